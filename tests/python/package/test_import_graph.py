"""The package's imports flow one way: problem -> {design, table} -> oracle -> {refine,
estimator} -> harness -> report -> the application modules (cli, pipeline, ...). Design and
table are siblings: a design hands its
per-tick gains over an interface (`stospline.table.format.TickGains`), so neither imports the
other. Cross-cutting modules at the top level (errors and
the infrastructure: atomic writes, caches, strict JSON, firmware limits, ...) import none of
the layers. Every import counts, including those inside functions (a lazy import is still a
dependency); imports under ``if TYPE_CHECKING:`` do not run and do not count."""
import ast
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

import stospline

PACKAGE = Path(stospline.__file__).parent
RANK = {"problem": 0, "design": 1, "table": 1, "oracle": 2, "refine": 3, "estimator": 3,
        "harness": 4, "report": 5, "application": 6}
APPLICATION = {"cli", "pipeline", "design_method", "budget", "gains", "corridor_search",
               "nonlinear", "board", "__init__", "__main__"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(["stospline", *parts])


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))
            if "_firmware" not in p.parts}


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or \
        (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def imported(path: Path, name: str, known: set[str], *, type_only: bool = False) -> set[str]:
    """Package modules `path` imports (absolute or relative, at any depth of the code);
    `type_only`: those under ``if TYPE_CHECKING:`` too."""
    tree = ast.parse(path.read_text(), str(path))
    skip = set() if type_only else {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                                    and _is_type_checking(node) for n in ast.walk(node)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("stospline")}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            if not base.startswith("stospline"):
                continue
            for a in node.names:     # `from stospline.design import zoh` imports a module
                sub = f"{base}.{a.name}"
                out.add(sub if sub in known else base)
    return {m for m in out if m in known and m != name}


def graph(*, type_only: bool = False) -> dict[str, set[str]]:
    mods = modules()
    return {name: imported(path, name, set(mods), type_only=type_only)
            for name, path in mods.items()}


def layer(name: str) -> str | None:
    """The layer a module belongs to (a key of RANK), or None for errors/infrastructure."""
    parts = name.split(".")
    if len(parts) > 1 and parts[1] in RANK:
        return parts[1]
    return "application" if len(parts) == 1 or parts[1] in APPLICATION else None


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component with more than one module (iterative Tarjan)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in g:
        if root in index:
            continue
        work = [(root, iter(sorted(g[root])))]
        index[root] = low[root] = counter[0]; counter[0] += 1
        stack.append(root); on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]; counter[0] += 1
                    stack.append(w); on.add(w)
                    work.append((w, iter(sorted(g[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop(); on.discard(w); comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def violations(g: dict[str, set[str]]) -> list[str]:
    bad = []
    for a, deps in g.items():
        la = layer(a)
        for b in sorted(deps):
            lb = layer(b)
            if b == "stospline" and la != "application":   # the root loads names lazily
                bad.append(f"{a} imports the package root")
            elif la is None and lb is not None:
                bad.append(f"{a} (infrastructure) imports the layer module {b}")
            elif la is not None and lb is not None and (
                    RANK[lb] > RANK[la] or (RANK[lb] == RANK[la] and lb != la)):
                bad.append(f"{a} ({la}) imports {b} ({lb})")
    if any(g["stospline.errors"]):
        bad.append(f"stospline.errors imports {sorted(g['stospline.errors'])}")
    return bad


def test_the_package_has_no_import_cycle():
    assert cycles(graph()) == []


def test_no_cycle_even_through_type_only_imports():
    """A module that needs another only for its annotations still knows of it: a cycle there
    is a design knot (the shared piece belongs in the lower module)."""
    assert cycles(graph(type_only=True)) == []


def test_imports_flow_one_way():
    assert violations(graph()) == []


def test_the_table_imports_no_designer():
    g = graph()
    for name, deps in g.items():
        if name.startswith("stospline.table"):
            assert not {d for d in deps if d.startswith("stospline.design")}, name


def test_the_checks_catch_a_planted_cycle_and_an_upward_import():
    g = {k: set(v) for k, v in graph().items()}
    g["stospline.problem.model"].add("stospline.design.latch")
    g["stospline.design.latch"].add("stospline.problem.model")
    assert ["stospline.design.latch", "stospline.problem.model"] in cycles(g)
    assert "stospline.problem.model (problem) imports stospline.design.latch (design)" \
        in violations(g)
    g = {k: set(v) for k, v in graph().items()}
    g["stospline.table.format"].add("stospline.design.continuous")
    g["stospline.design.zoh"].add("stospline.table.format")
    assert violations(g) == [
        "stospline.design.zoh (design) imports stospline.table.format (table)",
        "stospline.table.format (table) imports stospline.design.continuous (design)"]


def _import_alone(name: str) -> tuple[str, int, str]:
    r = subprocess.run([sys.executable, "-c", f"import {name}"], capture_output=True, text=True)
    return name, r.returncode, r.stderr[-400:]


def test_every_module_imports_alone_in_a_fresh_interpreter():
    """A module that only works after another was imported hides a dependency (or a cycle
    that the import order happens to resolve)."""
    with ThreadPoolExecutor(4) as pool:
        failed = [r for r in pool.map(_import_alone, sorted(modules())) if r[1] != 0]
    assert len(modules()) > 40
    assert failed == []


@pytest.mark.parametrize("name", ["stospline.table.format", "stospline.problem"])
def test_the_lower_layers_do_not_load_the_higher_ones(name):
    """Importing the table format (or the problem) loads no designer, oracle, harness or report."""
    code = (f"import sys, {name}; print(sorted(m for m in sys.modules "
            f"if m.startswith(('stospline.design', 'stospline.oracle', 'stospline.refine', "
            f"'stospline.harness', 'stospline.report'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "[]"
