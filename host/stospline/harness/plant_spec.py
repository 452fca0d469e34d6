"""The plant's step compiled for one problem: its sparsity as compile-time structure.

`plant_source` writes C (``plant_spec.h``, included by ``plant.c`` when the module is built
with ``HARNESS_PLANT_SPEC``) whose step has the problem's dimensions, noise entries and zero
and unit coefficients built in: a zero coefficient's term is not computed, a unit one is not
multiplied. The remaining coefficients are read at run time (`plant_spec_load`, once per stage
and block, from the ``harness_plant_t`` the generic step takes), so one module serves every
step length (substeps) and stage. A stage whose data do not fit the compiled pattern runs the
generic step.

Same bits as the generic step (``plant.c``): the sums keep their order and their +0.0 start,
so a dropped term is a product with an exact zero, +-0.0, added to a sum that is never -0.0
(a sum from +0.0 becomes -0.0 only by adding -0.0 to -0.0), which leaves it as it is; and
``1.0 * w`` is w. (Not for states that reach inf or NaN: 0 * inf is NaN, a dropped term.)
"""
from __future__ import annotations

import numpy as np

from stospline.expm import expm

__all__ = ["plant_source"]

def zoh_step(stage, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(Ad, Bd, fd)`` of one plant step of length dt: ``x+ = Ad x + Bd u + fd`` in the mean
    (fd None without a drift)."""
    n, m = stage.B.shape
    big = np.zeros((n + m + 1, n + m + 1))
    big[:n, :n], big[:n, n:n + m] = stage.A, stage.B
    if stage.f is not None:
        big[:n, -1] = stage.f
    E = expm(big * dt)
    return E[:n, :n], E[:n, n:n + m], (None if stage.f is None else E[:n, -1])


# Kinds of a coefficient (plant.c's PLANT_SPEC_* constants).
_ZERO, _ONE, _VALUE, _PLUS_ZERO = 0, 1, 2, 3


def _blocks(stage, dt: float):
    """The stage's coefficients in the loader's order (plant.c, plant_spec_load), with the
    factors of 2 applied as the generic step applies them (exact)."""
    n, m = stage.B.shape
    Ad, Bd, fd = zoh_step(stage, dt)
    return [("R", np.asarray(stage.R, float).ravel()), ("r", 2.0 * np.asarray(stage.r, float)),
            ("Q", np.asarray(stage.Q, float).ravel()),
            ("S", 2.0 * np.asarray(stage.S, float).ravel()),
            ("q", 2.0 * np.asarray(stage.q, float)),
            ("Ad", Ad.ravel()), ("Bd", Bd.ravel()), ("fd", np.zeros(n) if fd is None else fd),
            ("g", stage.noise_tensor[tuple(np.argwhere(stage.noise_tensor != 0).T)])]


def _kinds(values: list[np.ndarray], init: bool) -> np.ndarray:
    """Per coefficient the kind common to every stage: zero, one, or a value read at run
    time. A sum's first term (`init`) may be dropped only when it is +0.0."""
    v = np.stack(values)
    kind = np.full(v.shape[1], _VALUE)
    if init:
        kind[np.all((v == 0) & ~np.signbit(v), axis=0)] = _PLUS_ZERO
    else:
        kind[np.all(v == 0, axis=0)] = _ZERO
        kind[np.all(v == 1, axis=0)] = _ONE
    return kind


def plant_source(problem, tick_hz: int) -> str | None:
    """C text of the step compiled for `problem`'s constant stages (None when every stage
    is time-varying, or their noise entries differ: the generic step serves them)."""
    stages = [s for s in problem.stages if s.varying is None]
    if not stages:
        return None
    index = [np.argwhere(s.noise_tensor != 0) for s in stages]
    if any(i.shape != index[0].shape or np.any(i != index[0]) for i in index):
        return None
    n, m = stages[0].B.shape
    mz = stages[0].G.shape[2]
    state_cost = [bool(np.any(s.Q) or np.any(s.S) or np.any(s.q)) for s in stages]
    if len(set(state_cost)) > 1:
        return None
    blocks = [_blocks(s, 1.0 / tick_hz) for s in stages]
    kinds = {name: _kinds([b[i][1] for b in blocks], name in ("r", "q"))
             for i, (name, _) in enumerate(blocks[0])}
    if not state_cost[0]:            # the loader skips Q, S, q (the step has no state cost)
        for name in ("Q", "S", "q"):
            kinds[name] = kinds[name][:0]
    slot: dict = {}                  # (block, entry) -> index into the loaded values
    for name, kind in kinds.items():
        for e, k in enumerate(kind):
            if k == _VALUE:
                slot[name, e] = len(slot)

    def term(name: str, e: int, var: str) -> str | None:
        """The product of coefficient e of `name` and `var`, None for a zero coefficient."""
        k = kinds[name][e]
        if k in (_ZERO, _PLUS_ZERO):
            return None
        return var if k == _ONE else f"v[{slot[name, e]}] * {var}"

    def total(start: str, terms) -> str:
        """The sum left to right from `start`, as the generic step adds (zeros dropped)."""
        expr = start
        for t in terms:
            if t is not None:
                expr = f"({expr} + {t})"
        return expr

    def init(name: str, e: int) -> str:
        return "0.0" if kinds[name][e] == _PLUS_ZERO else f"v[{slot[name, e]}]"

    lines = []
    uru = []
    for i in range(m):
        acc = total(init("r", i), (term("R", i * m + j, f"u[{j}]") for j in range(m)))
        if acc != "0.0":
            uru.append(f"({acc}) * u[{i}]")
    lines.append(f"    const double uru = {total('0.0', uru)};")
    lines.append("    double c = 0.0 + pp->dt * (double)pp->substeps * (uru + pp->rho);")
    lines += [f"    double xs{i} = x[{i}];" for i in range(n)]
    lines.append("    size_t s;")
    lines.append("    for (s = 0; s < pp->substeps; ++s) {")
    if len(index[0]):
        lines.append("        const double *dzs = dz + s * PLANT_SPEC_MZ;")
    else:                                  # a noise-free plant reads no increments
        lines.insert(0, "    (void)dz;")
    if state_cost[0]:
        lx = []
        for i in range(n):
            acc = total(init("q", i), [term("Q", i * n + j, f"xs{j}") for j in range(n)]
                        + [term("S", i * m + j, f"u[{j}]") for j in range(m)])
            if acc != "0.0":
                lx.append(f"({acc}) * xs{i}")
        lines.append(f"        c += pp->dt * {total('0.0', lx)};")
    for i in range(n):
        acc = total("0.0", [term("Ad", i * n + j, f"xs{j}") for j in range(n)]
                    + [term("Bd", i * m + j, f"u[{j}]") for j in range(m)]
                    + [None if kinds["fd"][i] == _ZERO else
                       ("1.0" if kinds["fd"][i] == _ONE else f"v[{slot['fd', i]}]")])
        lines.append(f"        double xn{i} = {acc};")
    for e, (a, comp, k) in enumerate(index[0]):
        w = f"xs{a}" if a < n else f"u[{a - n}]"
        g = w if kinds["g"][e] == _ONE else f"{w} * v[{slot['g', e]}]"
        lines.append(f"        xn{comp} += {g} * (dzs[{k}] * pp->dz_scale);")
    lines += [f"        xs{i} = xn{i};" for i in range(n)]
    lines.append("    }")
    lines += [f"    x[{i}] = xs{i};" for i in range(n)]
    lines.append("    return c;")

    def c_array(ctype: str, name: str, values) -> str:
        body = ", ".join(str(int(v)) for v in values) or "0"
        return f"static const {ctype} {name}[] = {{{body}}};"

    kind_all = np.concatenate([kinds[name] for name in kinds])
    cor_data, cor_steps = _corridor_source(problem.corridors, n)
    return "\n".join([
        "/* Generated by stospline.harness.plant_spec: the plant step of one problem.",
        " * plant.c includes it twice: its constants, then (PLANT_SPEC_STEP) its step. */",
        "#ifndef PLANT_SPEC_STEP",
        f"#define PLANT_SPEC_MZ {mz}u",
        f"#define PLANT_SPEC_G {len(index[0])}u",
        f"#define PLANT_SPEC_VALUES {max(1, len(slot))}u",
        f"#define PLANT_SPEC_STATE_COST {int(state_cost[0])}",
        c_array("unsigned char", "plant_spec_kind", kind_all),
        c_array("size_t", "plant_spec_g_index", index[0].ravel()),
        *cor_data,
        "#else",
        "#if defined(__GNUC__)",
        "__attribute__((always_inline))",
        "#endif",
        "static inline double plant_spec_path(const plant_prep_t *pp, const double *u,",
        "                                     const double *dz, double *x)",
        "{",
        "    const double *v = pp->v;",
        *lines,
        "}",
        *cor_steps,
        "#endif",
        ""])


def _hex(v: float) -> str:
    return float(v).hex()


def _corridor_source(corridors, n: int) -> tuple[list[str], list[str]]:
    """The corridors' data (to check the run's against) and `corridor_spec_inside`: whether
    x is inside corridor k by corridor_inside's rule (controller_c.py) with the walls as
    constants, zero coefficients dropped and unit ones not multiplied. The outputs y are the
    same bits (a sum from +0.0); a wall's a y - b may differ in the sign of a zero, which no
    comparison sees, so every path is inside or outside as with the generic test."""
    kept = [c for c in corridors
            if np.all(np.isfinite(c.C)) and all(np.all(np.isfinite(a)) for a in c.unit_walls())]
    if len(kept) != len(corridors) or not corridors or len(corridors) > 32:
        return ["#define CORRIDOR_SPEC_COUNT 0u"], []
    data = [f"#define CORRIDOR_SPEC_COUNT {len(corridors)}u"]
    steps = ["/* Whether x is inside compiled corridor k (k < CORRIDOR_SPEC_COUNT). */",
             "#if defined(__GNUC__)", "__attribute__((always_inline))", "#endif",
             "static inline int corridor_spec_inside(size_t k, const double *x)", "{",
             "    int inside = 0;", "    switch (k) {"]

    def product(a: float, var: str) -> str | None:
        if a == 0:
            return None
        return var if a == 1 else (f"-{var}" if a == -1 else f"{_hex(a)} * {var}")

    for k, c in enumerate(corridors):
        A, b = c.unit_walls()
        C = np.asarray(c.C, dtype=float)
        p = C.shape[0]
        rows = np.asarray(c.row_start, dtype=int)
        data += [f"static const double corridor_spec_C{k}[] = "
                 f"{{{', '.join(_hex(v) for v in C.ravel())}}};",
                 f"static const double corridor_spec_A{k}[] = "
                 f"{{{', '.join(_hex(v) for v in A.ravel())}}};",
                 f"static const double corridor_spec_b{k}[] = "
                 f"{{{', '.join(_hex(v) for v in b)}}};",
                 f"static const size_t corridor_spec_rows{k}[] = "
                 f"{{{', '.join(str(v) for v in rows)}}};"]
        steps.append(f"    case {k}: {{")
        for i in range(p):
            y = None            # only compared: the sign of a zero does not matter
            for j in range(n):
                t = product(C[i, j], f"x[{j}]")
                if t is not None:
                    y = t if y is None else f"({y} + {t})"
            steps.append(f"        const double y{i} = {y or '0.0'};")
        for poly in range(len(rows) - 1):
            steps.append(f"        {{")
            for r in range(rows[poly], rows[poly + 1]):
                e = f"{_hex(-b[r])}" if b[r] != 0 else None    # (-b + a0 y0) + a1 y1 ...
                for i in range(p):
                    t = product(A[r, i], f"y{i}")
                    if t is not None:
                        e = t if e is None else f"({e} + {t})"
                e = e or "0.0"
                if r == rows[poly]:
                    steps.append(f"            double worst = {e};")
                else:
                    steps.append(f"            const double e{r} = {e};")
                    steps.append(f"            worst = (e{r} > worst) ? e{r} : worst;")
            steps.append("            inside |= !(worst > 0.0);")
            steps.append("        }")
        steps.append("        break;")
        steps.append("    }")
    data.append("static const harness_corridor_t corridor_spec[] = {")
    for k, c in enumerate(corridors):
        data.append(f"    {{0u, 0u, {c.C.shape[0]}u, {len(c.row_start) - 1}u, corridor_spec_C{k}, "
                    f"corridor_spec_rows{k}, corridor_spec_A{k}, corridor_spec_b{k}, NULL, NULL}},")
    data.append("};")
    steps += ["    default:", "        break;", "    }", "    return inside;", "}"]
    return data, steps
