"""``stospline corridor-design``: the cheapest grid design whose paths stay in the corridor with
probability 1 - epsilon (`stospline.corridor_search`), on the robot at 50 Hz with few paths.

Checked: the chosen design's certified bound is at most epsilon, and recounting its
certification run from the written problem file gives the same exits; no grid point cheaper
than the chosen one passes screening (against a brute-force screening of the whole grid), and
fewer points are screened than the grid has; the designed problem file reads back and its
tables name its SHA-256; two runs write the same bytes; bad values exit 2 with one line
naming the field or option and nothing on disk.
"""
import hashlib
import json

import pytest

from conftest import EXAMPLES
from stospline import corridor_search as cs
from stospline.cli import main
from stospline.problem import load_problem

EPS, SEARCH, CERTIFY = 0.03, 2000, 4000
STRIP, RATE = "0,2,5", "0,1"


def robot_text(epsilon=EPS, extra_corridor=False) -> str:
    text = (EXAMPLES / "robot_corridor.toml").read_text()
    text = text.replace("tick_hz = 1000", "tick_hz = 50").replace(
        'name = "robot_corridor"', 'name = "robot_risk"')
    if epsilon is not None:
        text += f"epsilon = {epsilon}\n"
    if extra_corridor:
        text += ("\n[[corridors]]\nt = [0.0, 6.0]\nC = [[1, 0, 0, 0]]\n"
                 "polygons = [{ A = [[1]], b = [1] }]\nepsilon = 0.5\n")
    return text


def run(tmp_path, *args, text=None, out="out"):
    src = tmp_path / "risk.toml"
    src.write_text(robot_text() if text is None else text)
    argv = ["corridor-design", str(src), "--search", str(SEARCH), "--certify", str(CERTIFY),
            "--strip", STRIP, "--rate", RATE, "--workers", "2", "--quiet", *args]
    if out is not None:
        argv += ["--out", str(tmp_path / out)]
    return main(argv), tmp_path / out if out else None


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cd")
    rc, out = run(tmp)
    assert rc == 0
    return tmp, out, json.loads((out / "robot_risk_corridor.json").read_text())


def test_writes_the_set_and_the_certified_bound_meets_epsilon(designed):
    _, out, cert = designed
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"robot_risk{s}" for s in (".toml", ".c", ".h", ".json", "_corridor.json"))
    ch = cert["chosen"]
    assert cert["meets_epsilon"] and cert["epsilon"] == EPS
    assert ch["certification"]["paths"] == CERTIFY and ch["screening"]["paths"] == SEARCH
    assert ch["certification"]["seed"] != ch["screening"]["seed"]
    assert ch["certification"]["upper99"] <= EPS and ch["screening"]["upper99"] <= EPS
    assert ch["extra_percent"] > 0 and ch["J"] > cert["J0"]
    # The designed file reads back; its tables name it; its weights are stage data.
    toml = out / "robot_risk.toml"
    p = load_problem(toml)
    assert p.source_sha256 == hashlib.sha256(toml.read_bytes()).hexdigest() == \
        ch["problem_sha256"] == json.loads((out / "robot_risk.json").read_text())["problem_sha256"]
    assert p.corridors[0].epsilon == EPS and len(p.stages) == 2
    assert p.stages[0].Q[2, 2] == ch["w"] and p.stages[0].Q[1, 1] == ch["wv"]
    # Its own certification run, recounted from the written file: the same exits.
    cand = cs.Candidate(ch["w"], ch["wv"], toml.read_text(), ch["J"], 1.0, 1.0, True)
    again = cs.count_exits(p, 0, cand, paths=CERTIFY, seed=ch["certification"]["seed"],
                           workers=1)
    assert again.exits == ch["certification"]["exits"]
    assert again.upper <= EPS


def test_cheapest_first_no_cheaper_point_passes_screening(designed):
    """Brute force: screen the whole grid with the same paths and seed. Every point cheaper
    than the chosen one fails; the search screened only the points up to it."""
    tmp, _, cert = designed
    p, index = cs.target_corridor(load_problem(tmp / "risk.toml"))
    grid = cs.evaluate_grid(p, index, strip=(0.0, 2.0, 5.0), rate=(0.0, 1.0))
    costs = [c.J for c in grid.candidates]
    assert costs == sorted(costs)
    ch = cert["chosen"]
    passed = []
    for c in grid.candidates:
        e = cs.count_exits(p, index, c, paths=SEARCH, seed=ch["screening"]["seed"])
        row = next(r for r in cert["grid"] if (r["w"], r["wv"]) == (c.w, c.wv))
        assert row["J"] == c.J
        if row["screening"] is not None:           # screened by the search: the same count
            assert row["screening"]["exits"] == e.exits
        if e.upper <= EPS:
            passed.append(c)
    assert (passed[0].w, passed[0].wv) == (ch["w"], ch["wv"])     # the first certified
    assert all(c.J > passed[0].J or c is passed[0] for c in passed)
    screened = sum(r["screening"] is not None for r in cert["grid"])
    assert cert["screened"] == screened == 1 + grid.candidates.index(passed[0])
    assert screened < len(grid.candidates)


def test_two_runs_write_the_same_bytes(designed):
    tmp, out, _ = designed
    rc, out2 = run(tmp, out="again")
    assert rc == 0
    for f in out.iterdir():
        assert (out2 / f.name).read_bytes() == f.read_bytes(), f.name


@pytest.mark.parametrize("args, text, field", [
    ((), robot_text(epsilon=None), "corridors: no corridor has an epsilon"),
    ((), robot_text(extra_corridor=True), "corridors[1].epsilon: 2 corridors"),
    (("--epsilon", "0.05"), robot_text(extra_corridor=True), "--epsilon: sets the epsilon"),
    (("--epsilon", "1.5"), None, "--epsilon: must be a number in (0, 1)"),
    (("--search", "0"), None, "--search: must be an integer in 1.."),
    (("--certify", "-3"), None, "--certify: must be an integer in 1.."),
    (("--strip", "1,nan"), None, "--strip: must be distinct"),
    (("--certify-seed", "20261126"), None, "--certify-seed: must differ from --seed"),
    (("--table", "spline"), None, "--table: corridor-design writes per-tick tables"),
    (("--refine", "-1"), None, "--refine: must be an integer in 0..20"),
    (("--refine", "2.5"), None, "--refine: must be an integer in 0..20"),
    (("--refine", "1e9"), None, "--refine: must be an integer in 0..20"),
    (("--certify", "1000000", "--max-time", "5"), None,
     "--certify: the corridor-design would take"),
])
def test_bad_values_exit_2_naming_the_field_and_write_nothing(tmp_path, capsys, args, text,
                                                              field):
    try:
        rc, out = run(tmp_path, *args, text=text)
    except SystemExit as exc:          # argparse
        rc, out = exc.code, tmp_path / "out"
    err = capsys.readouterr().err
    assert rc == 2 and field in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_no_grid_point_meets_epsilon_exits_2_and_writes_nothing(tmp_path, capsys):
    """An epsilon the screening paths can certify (0.003 needs 1534 of them) that the one grid
    point misses: one line on stderr, nothing on stdout or on disk."""
    rc, out = run(tmp_path, "--strip", "0", "--rate", "0",
                  text=robot_text(epsilon=0.003))
    cap = capsys.readouterr()
    assert rc == 2 and "corridors[0].epsilon: no grid point meets 0.003" in cap.err, cap.err
    assert cap.err.count("\n") == 1 and cap.out == ""
    assert not out.exists()


def test_refine_bisects_to_a_cheaper_certified_design(designed, tmp_path):
    """--refine 3: three screened points on the segment from the last failing grid point to
    the first passing one. The chosen design is the cheapest of them that passes screening
    (certified on fresh paths), at most the grid's choice in cost; every refined point's
    screening is in the certificate, and recounting the chosen one's certification from the
    written file gives the same exits."""
    _, _, grid_cert = designed
    rc, out = run(tmp_path, "--refine", "3")
    assert rc == 0
    cert = json.loads((out / "robot_risk_corridor.json").read_text())
    ch, g = cert["chosen"], grid_cert["chosen"]
    assert len(cert["refined"]) == 3 and "bisection" in cert["method"]
    grid_rows = [r for r in cert["grid"] if r["screening"] is not None]
    fail, ok = grid_rows[-2], grid_rows[-1]
    assert (ok["w"], ok["wv"]) == (g["w"], g["wv"]) and fail["screening"]["upper99"] > EPS
    for r in cert["refined"]:            # on the segment, strictly inside
        th = ((r["w"] - fail["w"]) / (ok["w"] - fail["w"]) if ok["w"] != fail["w"]
              else (r["wv"] - fail["wv"]) / (ok["wv"] - fail["wv"]))
        assert 0 < th < 1
        assert r["wv"] == pytest.approx(fail["wv"] + th * (ok["wv"] - fail["wv"]))
    passing = [r for r in cert["refined"] + [ok] if r["screening"]["upper99"] <= EPS]
    cheapest = min(passing, key=lambda r: r["J"])
    assert (ch["w"], ch["wv"], ch["J"]) == (cheapest["w"], cheapest["wv"], cheapest["J"])
    assert ch["J"] <= g["J"] and ch["certification"]["upper99"] <= EPS
    p = load_problem(out / "robot_risk.toml")
    cand = cs.Candidate(ch["w"], ch["wv"], (out / "robot_risk.toml").read_text(), ch["J"],
                        1.0, 1.0, True)
    again = cs.count_exits(p, 0, cand, paths=CERTIFY, seed=ch["certification"]["seed"],
                           workers=1)
    assert again.exits == ch["certification"]["exits"]
