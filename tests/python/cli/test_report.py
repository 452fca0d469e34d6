"""`stospline report`: one self-contained HTML page, opened in headless Chromium (Debian's
`chromium`, installed by tools/setup.sh). The page marks its <body> once every image has
decoded and no script error occurred; the test reads that back from the rendered DOM, and
checks that the key numbers are on the page."""
import re
import shutil
import subprocess

import pytest

from conftest import EXAMPLES

from test_cli_end_to_end import ONE_STATE, run

ROBOT = EXAMPLES / "robot_corridor.toml"


def rendered_dom(page) -> str:
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.fail("chromium not found: tools/setup.sh installs it (Debian package chromium)")
    r = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu",
                        "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


@pytest.mark.parametrize("problem", ["robot", "one state"])
def test_report_page_renders_with_every_image_and_the_numbers(tmp_path, problem):
    if problem == "robot":
        source = ROBOT
    else:
        source = tmp_path / "growth.toml"
        source.write_text(ONE_STATE)
    page = tmp_path / "report.html"
    r = run("report", str(source), "--out", str(page), "--paths", "300", "--seed", "4")
    assert r.returncode == 0, r.stderr
    text = page.read_text(encoding="utf-8")
    assert "http://" not in text and "https://" not in text       # nothing to fetch
    dom = rendered_dom(page)
    body = re.search(r"<body([^>]*)>", dom).group(1)
    assert 'data-images="ok"' in body and 'data-errors="0"' in body, body
    assert dom.count("<img") == 3
    sim = json_summary(source)
    for key in ("mc-cost", "oracle-cost"):
        assert re.search(rf'id="{key}">([^<]+)<', dom), key
    assert f'{sim["cost"]["oracle_implemented"]:.6g}' in dom
    assert f'{sim["cost"]["mc_mean"]:.6g}' in dom
    assert ("the Monte Carlo run agrees with the oracle" in dom) == sim["verdict"]["agree"]
    if problem == "robot":       # its L-shaped [[corridors]]: exits, by time and by wall
        (c,) = sim["corridors"]
        assert 'id="corridor-0"' in dom
        assert f"<b>{c['mc']['exits']}</b> of 300 paths" in dom
        assert f"<b>{100 * c['mc']['upper99']:.4g}%</b>" in dom


def json_summary(source):
    import json
    r = run("simulate", str(source), "--paths", "300", "--seed", "4", "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_report_needs_an_html_file(tmp_path):
    out = tmp_path / "report.txt"
    r = run("report", str(ROBOT), "--out", str(out))
    assert r.returncode == 2 and "--out" in r.stderr and ".html" in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_page_check_sees_a_broken_image(tmp_path):
    """The marks the browser test reads are not constant: a page whose first figure does not
    decode says so."""
    page = tmp_path / "report.html"
    r = run("report", str(ROBOT), "--out", str(page), "--paths", "100")
    assert r.returncode == 0, r.stderr
    text = page.read_text(encoding="utf-8")
    broken = tmp_path / "broken.html"
    broken.write_text(text.replace("data:image/png;base64,", "data:image/png;base64,AAAA", 1),
                      encoding="utf-8")
    body = re.search(r"<body([^>]*)>", rendered_dom(broken)).group(1)
    assert 'data-images="missing"' in body, body


def test_report_has_the_fault_table_and_the_run_faults(tmp_path):
    """With a fault in the run, the page states it with the fault oracle's cost (the number
    `simulate --json` reports for the same run), and the fault table has its twelve rows,
    the linear faults with an oracle cost and the others with '-'."""
    page = tmp_path / "report.html"
    args = ["--paths", "300", "--seed", "4", "--fault", "delay_ticks=1"]
    r = run("report", str(ROBOT), "--out", str(page), "--fault-paths", "100", *args)
    assert r.returncode == 0, r.stderr
    dom = rendered_dom(page)
    assert 'data-images="ok"' in dom
    import json
    sim = json.loads(run("simulate", str(ROBOT), "--json", *args).stdout)
    assert sim["faults"]["levels"] == {"delay_ticks": 1} and sim["faults"]["exact_oracle"]
    assert f'{sim["faults"]["oracle_cost"]:.6g}' in re.search(r'id="faults">(.*?)</p>',
                                                              dom).group(1)
    table = re.search(r'<table id="fault-table">(.*?)</table>', dom, flags=re.S).group(1)
    rows = re.findall(r"<tr>(.*?)</tr>", table, flags=re.S)[1:]
    assert len(rows) == 12
    no_oracle = [r for r in rows if re.search(r"quantization|missed ticks", r)]
    assert len(no_oracle) == 4
    assert all(re.findall(r"<td>([^<]*)</td>", r)[0] == "-" for r in no_oracle)
    assert all(re.findall(r"<td>([^<]*)</td>", r)[0] != "-"
               for r in rows if r not in no_oracle)


def test_report_without_the_fault_table(tmp_path):
    page = tmp_path / "report.html"
    r = run("report", str(ROBOT), "--out", str(page), "--paths", "100", "--fault-paths", "0")
    assert r.returncode == 0, r.stderr
    assert "fault-table" not in page.read_text(encoding="utf-8")


def test_report_says_why_there_is_no_fault_table(tmp_path):
    """Time-varying data: the fault harness cannot run them, and the page says so instead of
    leaving the section out silently."""
    page = tmp_path / "report.html"
    r = run("report", str(EXAMPLES / "investment.toml"), "--out", str(page), "--paths", "100")
    assert r.returncode == 0, r.stderr
    text = page.read_text(encoding="utf-8")
    assert 'id="no-fault-table"' in text and "time-invariant" in text
    assert '<table id="fault-table"' not in text


def test_report_shows_the_regions_at_every_tick(tmp_path):
    """robot_monotone: a figure of each region row against time (band, oracle and Monte Carlo,
    the ticks held at a bound) and the oracle's every-tick check as a table, the same numbers
    as `design --json`'s every_tick entry."""
    import json
    source = EXAMPLES / "robot_monotone.toml"
    page = tmp_path / "report.html"
    r = run("report", str(source), "--out", str(page), "--paths", "300", "--seed", "4")
    assert r.returncode == 0, r.stderr
    dom = rendered_dom(page)
    body = re.search(r"<body([^>]*)>", dom).group(1)
    assert 'data-images="ok"' in body and 'data-errors="0"' in body, body
    assert dom.count("<img") == 4 and 'alt="regions"' in dom
    d = run("design", str(source), "--json")
    assert d.returncode == 0, d.stderr
    et = json.loads(d.stdout)["every_tick"]
    (reg,) = et["regions"]
    assert 'id="regions"' in dom and "one sparse QP on the tick grid" in dom
    assert f"{et['working_set_rows']} rows held at a bound" in dom
    # The page's row: region, ticks, then the three worst excursions (the summary rounds them
    # to its JSON resolution).
    cells = re.search(r"<tr><td>0</td><td>600</td><td>([^<]+)</td><td>([^<]+)</td>"
                      r"<td>([^<]+)</td><td>no</td></tr>", dom)
    assert cells, dom[dom.index('id="regions"'):][:800]
    for got, key in zip(cells.groups(), ("worst_at_ticks_design", "worst_at_ticks_implemented",
                                         "worst_over_interval")):
        assert float(got) == pytest.approx(reg[key], abs=1e-10)


HOSTILE = '<script>alert("x")</script> & co'


def test_text_from_the_problem_and_the_run_is_escaped():
    """The page template autoescapes: a name, a verdict's reason and a no-fault-table reason
    holding markup come out as text (unescaping gives them back), and the page's one script
    is its own."""
    import dataclasses
    import html
    import tomllib
    from stospline.pipeline import design_problem, simulate_problem, simulation_summary
    from stospline.problem import parse_problem
    from stospline.report.html import report_html
    d = design_problem(parse_problem(tomllib.loads(ONE_STATE)))
    mc = simulate_problem(d, paths=20, seed=4, record=5)
    summary = simulation_summary(d, mc, seed=4)
    summary["verdict"]["reason"] = HOSTILE
    # A name a problem file refuses (not a C identifier): set after the run, as a label.
    d = dataclasses.replace(d, problem=dataclasses.replace(d.problem, name=HOSTILE))
    page = report_html(d, mc, summary, None, HOSTILE)
    assert page.count("<script>") == 1 and "</script> &" not in page
    for pattern in (r"<title>stospline report: (.*?)</title>", r"<h1>(.*?)</h1>",
                    r'id="verdict">.* jointly; (.*)\)\.</p>',
                    r'id="no-fault-table">No fault table: (.*)\.</p>'):
        shown = re.search(pattern, page).group(1)
        assert shown != HOSTILE and html.unescape(shown) == HOSTILE, pattern


def test_report_of_a_problem_with_parameters_draws_the_planned_paths_over_the_box(tmp_path):
    """robot_goal (two parameters): the page has the family of planned mean paths at the
    nominal and the box's 4 vertices, and passes the browser check."""
    page = tmp_path / "report.html"
    r = run("report", str(EXAMPLES / "robot_goal.toml"), "--out", str(page), "--paths", "200",
            "--seed", "4")
    assert r.returncode == 0, r.stderr
    dom = rendered_dom(page)
    body = re.search(r"<body([^>]*)>", dom).group(1)
    assert 'data-images="ok"' in body and 'data-errors="0"' in body, body
    assert dom.count("<img") == 4
    assert 'alt="planned paths over the parameter box"' in dom
    assert re.search(r'id="parameters">[^<]*its 4 vertices of the box of goal_x, goal_y', dom)


def test_the_family_is_the_oracle_at_each_parameter_vector():
    """The affine mean paths the report draws are the oracle's at each vertex."""
    import numpy as np
    from stospline import load_problem
    from stospline.oracle.over_box import family, mean_paths
    from stospline.oracle.parametric import design_parametric, evaluate_at
    p = load_problem(EXAMPLES / "robot_goal.toml")
    pt = design_parametric(p).table
    thetas, what = family(p.parameters)
    assert what == "its 4 vertices" and thetas.shape == (4, 2)
    paths = mean_paths(p, pt, thetas)
    for theta, path in zip(thetas, paths):
        exact = evaluate_at(p, pt, theta, path=True).path_mean
        assert np.abs(path - exact).max() <= 1e-9 * max(1.0, np.abs(exact).max())
    many, what = family(p.parameters, most=3)
    assert what.startswith("3 draws") and many.shape == (3, 2)
    lo, hi = (np.array([getattr(q, k) for q in p.parameters]) for k in ("lower", "upper"))
    assert np.all(many >= lo) and np.all(many <= hi)
