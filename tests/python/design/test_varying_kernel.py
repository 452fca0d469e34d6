"""The C loops of time-varying stages (design/varying_kernel.c): the designer's backward
recursion and the oracle's forward one, both on the data interpolated through two Gauss points
per tick and solved by Taylor series, against references that share none of their code — the
numpy designer with a Magnus exponential per tick, the oracle integrating every tick with
DOP853 — and the vectorised sampling of the data they read."""
import copy

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from stospline.design import varying
from stospline.design.zoh import design_zoh
from stospline.problem import parse_problem
from stospline.problem.faults import Faults
from stospline.problem.series import Series
from stospline.oracle.evaluate import evaluate_table
from stospline.table.format import table_of

from test_time_varying_data import tv_doc


def _with_drift(doc):
    """tv_doc with a time-varying affine drift as well (the constant column of the maps)."""
    doc = copy.deepcopy(doc)
    doc["dynamics"]["f"] = {"t": [0, 1, 2], "values": [[0.0, 0.5], [0.2, -0.3], [0.0, 0.1]]}
    return doc


def _reference_oracle(problem, table, monkeypatch, path=True):
    with monkeypatch.context() as mp:
        mp.setenv("STOSPLINE_ORACLE_KERNEL", "numpy")
        return evaluate_table(problem, table, path=path)


@pytest.mark.parametrize("mode", ["stagewise", "joint"])
def test_c_loops_agree_with_the_references(mode, monkeypatch):
    problem = parse_problem(_with_drift(tv_doc()))
    d = design_zoh(problem, mode=mode)
    ref_design = design_zoh(problem, mode=mode, kernel="numpy")
    table = table_of(d, quantize=False)
    c = evaluate_table(problem, table, path=True)
    ref = _reference_oracle(problem, table, monkeypatch)
    # Two fourth-order tick maps (Gauss-point interpolation, Magnus) at 20 Hz.
    assert abs(d.J0 - ref_design.J0) <= 1e-7 * d.J0
    for a, b in zip(d.stages, ref_design.stages):
        np.testing.assert_allclose(a.K, b.K, atol=1e-6 * np.abs(b.K).max())
    # The C oracle and DOP853 on every tick, same table: cost, knots and the whole path.
    assert abs(c.J - ref.J) <= 1e-7 * ref.J
    np.testing.assert_allclose(c.path_mean, ref.path_mean, atol=1e-7)
    np.testing.assert_allclose(c.path_var, ref.path_var, atol=1e-7 * ref.path_var.max())
    np.testing.assert_allclose(c.path_u_mean, ref.path_u_mean, atol=1e-7)
    np.testing.assert_allclose(c.path_u_var, ref.path_u_var, atol=1e-7 * ref.path_u_var.max())
    for k, kn in enumerate(problem.knots):
        np.testing.assert_allclose(c.knot_constraint[k], kn.constraint.value, atol=1e-7)
    # Designer and C oracle read the same interpolated data: equal to rounding.
    assert abs(c.J - d.J0) <= 1e-12 * d.J0


def _dense_noise_doc(varying_noise: bool, seed: int = 3):
    """n = 3, m = 2, time-varying drift, a dense n x 3 noise matrix on every state and every
    input (constant, or varying in time), seeded."""
    rng = np.random.default_rng(seed)
    n, m, mz = 3, 2, 3
    ts = [0.0, 0.7, 1.4, 2.0]

    def G():
        if not varying_noise:
            return rng.normal(scale=0.2, size=(n, mz)).tolist()
        return {"t": ts, "values": rng.normal(scale=0.2, size=(len(ts), n, mz)).tolist()}

    A = [(rng.normal(scale=0.5, size=(n, n)) - np.eye(n)).tolist() for _ in ts]
    noise = ([{"state": i, "G": G()} for i in range(n)]
             + [{"input": j, "G": G()} for j in range(m)])
    return {"name": "dense", "x0": rng.normal(size=n).tolist(), "tick_hz": 40,
            "dynamics": {"A": {"t": ts, "values": A}, "B": rng.normal(size=(n, m)).tolist(),
                         "noise": noise},
            "cost": {"R": np.eye(m).tolist(), "Q": (0.5 * np.eye(n)).tolist()},
            "knots": [{"t": 1.0, "constraint": {"C": [[1, 0, 0]], "value": [0.5]}},
                      {"t": 2.0, "penalty": {"C": np.eye(n).tolist(), "target": [0.0] * n,
                                             "weight": 2.0}}]}


@pytest.mark.parametrize("varying_noise", [True, False])
def test_dense_noise_paths_equal_the_pair_formulation(varying_noise, monkeypatch):
    """Every way the C loops apply a dense diffusion (Brownian columns, the packed operator,
    and the automatic choice) gives the nonzero-pair formulation's design and oracle to
    rounding."""
    problem = parse_problem(_dense_noise_doc(varying_noise))
    results = {}
    for path in ("pairs", "columns", "operator", "segments", "auto"):
        monkeypatch.setattr(varying, "NOISE_PATH", path)
        d = design_zoh(problem)
        table = table_of(d, quantize=False)
        results[path] = (d, evaluate_table(problem, table, path=True))
    ref, ref_oracle = results.pop("pairs")
    assert abs(ref_oracle.J - ref.J0) <= 1e-12 * ref.J0      # designer and oracle agree
    for path, (d, c) in results.items():
        assert abs(d.J0 - ref.J0) <= 1e-13 * ref.J0, path
        for a, b in zip(d.stages, ref.stages):
            np.testing.assert_allclose(a.K, b.K, rtol=0, atol=1e-12 * np.abs(b.K).max())
            np.testing.assert_allclose(a.k0, b.k0, rtol=0, atol=1e-12 * np.abs(b.k0).max())
        assert abs(c.J - ref_oracle.J) <= 1e-13 * ref_oracle.J, path
        np.testing.assert_allclose(c.path_var, ref_oracle.path_var, rtol=0,
                                   atol=1e-13 * ref_oracle.path_var.max())
    # ... and the numpy designer (Magnus exponential per tick) to its order-4 truncation.
    numpy_design = design_zoh(problem, kernel="numpy")
    assert abs(numpy_design.J0 - ref.J0) <= 1e-6 * ref.J0


def test_oracle_error_falls_as_h_to_the_fourth(monkeypatch):
    errors = []
    for hz in (20, 40):
        doc = _with_drift(tv_doc())
        doc["tick_hz"] = hz
        problem = parse_problem(doc)
        table = table_of(design_zoh(problem), quantize=False)
        c = evaluate_table(problem, table, path=False).J
        errors.append(abs(c - _reference_oracle(problem, table, monkeypatch, path=False).J))
    assert errors[1] < errors[0] / 10          # order 4: a factor ~16 (kinks: less)


def test_constant_data_given_as_samples_is_exact():
    """Samples that do not change: the Taylor loops must give the constant-stage results (an
    exact exponential per stage) to rounding."""
    doc = {"name": "flat", "x0": [1.0, -0.5], "tick_hz": 50,
           "dynamics": {"A": [[0, 1], [-2, -0.3]], "B": [[0], [1]],
                        "noise": [{"state": 1, "G": [[0.0], [0.3]]}]},
           "cost": {"R": [[0.5]], "Q": [[1, 0], [0, 0.1]]},
           "knots": [{"t": 1.0, "constraint": {"C": [[1, 0]], "value": [0.5]}},
                     {"t": 2.0, "penalty": {"C": [[0, 1]], "target": [0.2], "weight": 3.0}}]}
    flat = parse_problem(doc)
    sampled_doc = copy.deepcopy(doc)
    sampled_doc["dynamics"]["A"] = {"t": [0, 2], "values": [doc["dynamics"]["A"]] * 2}
    sampled = parse_problem(sampled_doc)
    assert sampled.stages[0].varying is not None
    a, b = design_zoh(flat), design_zoh(sampled)
    assert abs(a.J0 - b.J0) <= 1e-12 * a.J0
    for sa, sb in zip(a.stages, b.stages):
        np.testing.assert_allclose(sb.K, sa.K, rtol=0, atol=1e-11 * np.abs(sa.K).max())
        np.testing.assert_allclose(sb.k0, sa.k0, rtol=0, atol=1e-11 * np.abs(sa.k0).max())
    ja = evaluate_table(flat, table_of(a, quantize=False), path=False).J
    jb = evaluate_table(sampled, table_of(a, quantize=False), path=False).J
    assert abs(ja - jb) <= 1e-12 * ja


def test_sub_steps_keep_stiff_slow_ticks_exact(monkeypatch):
    """A fast pole at a slow tick rate (h |A| = 10): the loops split each tick into sub-steps
    and still match DOP853."""
    doc = tv_doc()
    doc["tick_hz"] = 10
    doc["dynamics"]["A"]["values"] = [[[0, 1], [-100, -20]], [[0, 1], [-80, -25]],
                                      [[0, 1], [-100, -20]]]
    problem = parse_problem(doc)
    table = table_of(design_zoh(problem), quantize=False)
    c = evaluate_table(problem, table, path=False)
    ref = _reference_oracle(problem, table, monkeypatch, path=False)
    assert abs(c.J - ref.J) <= 1e-6 * ref.J
    smp = varying.tick_samples(problem.stages[0], 0.0, 0.1, 3, varying._gauss(2)[0])
    assert smp.Ar.shape[0] == 3     # the data vary: one entry per tick


def test_sub_steps_keep_noise_dominated_slow_ticks_exact(monkeypatch):
    """Dense noise so strong at a slow tick rate that it, not the drift, sets the sub-steps
    and the series' length: the loops still match DOP853 on every tick."""
    doc = _dense_noise_doc(False)
    doc["tick_hz"] = 5
    doc["dynamics"]["A"]["values"] = [doc["dynamics"]["A"]["values"][0]] * 3 + [
        (np.asarray(doc["dynamics"]["A"]["values"][0]) + 0.01).tolist()]
    for entry in doc["dynamics"]["noise"]:
        entry["G"] = (6.0 * np.asarray(entry["G"])).tolist()
    problem = parse_problem(doc)
    table = table_of(design_zoh(problem), quantize=False)
    c = evaluate_table(problem, table, path=False)
    ref = _reference_oracle(problem, table, monkeypatch, path=False)
    assert abs(c.J - ref.J) <= 1e-10 * ref.J


times = st.lists(st.floats(-1.0, 4.0, allow_nan=False), min_size=1, max_size=30)


@settings(max_examples=60, deadline=None)
@given(knots=st.lists(st.floats(0.0, 3.0), min_size=1, max_size=6, unique=True),
       at=times, interpolation=st.sampled_from(["linear", "zoh"]), seed=st.integers(0, 99))
def test_series_many_equals_one_call_per_time(knots, at, interpolation, seed):
    t = np.array(sorted(knots))
    values = np.random.default_rng(seed).normal(size=(t.size, 2, 3))
    s = Series(t, values, interpolation, "x")
    got = s.many(np.array(at))
    for j, tj in enumerate(at):
        np.testing.assert_array_equal(got[j], s(tj))


@pytest.mark.parametrize("wrap", ["none", "without_noise", "mismatch"])
def test_stage_samples_equal_the_stage_at_each_time(wrap):
    stage = parse_problem(_with_drift(tv_doc())).stages[1]
    if wrap == "without_noise":
        stage = stage.without_noise()
    elif wrap == "mismatch":
        stage = Faults(plant_A_scale=1.1, plant_noise_scale=0.5)._stage(stage)
    ts = np.linspace(0.8, 2.3, 23)
    s = stage.samples(ts)
    for j, t in enumerate(ts):
        frozen = stage.at(t)
        for k in ("A", "B", "G", "Q", "R", "S", "q", "r", "rho", "f"):
            np.testing.assert_array_equal(s[k][j], np.asarray(getattr(frozen, k), float), k)


@pytest.mark.parametrize("substeps", [1, 3])
def test_plant_scheme_loop_equals_the_python_maps(substeps, monkeypatch):
    """The oracle's "euler" propagator (the Monte Carlo plant's own scheme, data at each step's
    midpoint) in C equals the composed numpy maps of `oracle._euler_varying_maps`."""
    problem = parse_problem(_with_drift(tv_doc()))
    table = table_of(design_zoh(problem))
    c = evaluate_table(problem, table, propagator="euler", substeps=substeps, path=True)
    with monkeypatch.context() as mp:
        mp.setenv("STOSPLINE_ORACLE_KERNEL", "numpy")
        ref = evaluate_table(problem, table, propagator="euler", substeps=substeps, path=True)
    assert abs(c.J - ref.J) <= 1e-13 * ref.J
    np.testing.assert_allclose(c.path_mean, ref.path_mean, rtol=0, atol=1e-13)
    np.testing.assert_allclose(c.path_var, ref.path_var, rtol=0, atol=1e-13)
    np.testing.assert_allclose(c.path_u_var, ref.path_u_var, rtol=0, atol=1e-12)
    for a, b in zip(c.knot_cov, ref.knot_cov):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13)


def test_overflowing_varying_data_is_named_not_a_traceback(tmp_path):
    """Samples whose products overflow: the C loops' series cannot converge; the design stops
    with exit status 2, one line naming the extreme input, and writes nothing."""
    import subprocess
    import sys
    from pathlib import Path
    doc = tmp_path / "huge.toml"
    doc.write_text('name = "huge"\nx0 = [1.0, 0.0]\ntick_hz = 10\n[dynamics]\n'
                   'A = { t = [0.0, 1.0], values = [[[0, 1], [-1e200, 0]], '
                   '[[0, 1], [-2e200, 0]]] }\nB = [[0], [1]]\n[cost]\nR = [[1.0]]\n'
                   '[[knots]]\nt = 1.0\nconstraint = { C = [[1, 0]], value = [0.5] }\n')
    cli = Path(sys.executable).with_name("stospline")
    out = tmp_path / "out"
    run = subprocess.run([str(cli), "design", str(doc), "--out", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "dynamics.A" in lines[0] and "overflow" in lines[0], run.stderr
    assert not out.exists()


def test_noise_knots_mark_where_the_noise_is_affine():
    """`noise_knots`: the merged sample times of linearly interpolated noise (none for held
    noise); `Stage.samples(noise=False)` samples the rest alike and no G or H."""
    doc = _dense_noise_doc(True)
    doc["dynamics"]["noise"][1]["G"]["t"] = [0.0, 0.5, 2.0, 2.5]
    stage = parse_problem(doc).stages[0]
    np.testing.assert_array_equal(stage.varying.noise_knots, [0.0, 0.5, 0.7, 1.4, 2.0, 2.5])
    ts = np.linspace(0.1, 0.9, 7)
    full, bare = stage.samples(ts), stage.samples(ts, noise=False)
    assert bare["G"] is None and bare["H"] is None
    for k in ("A", "B", "Q", "R", "S", "q", "r", "rho"):
        np.testing.assert_array_equal(bare[k], full[k], k)
    doc["dynamics"]["noise"][1]["G"]["interpolation"] = "zoh"
    assert parse_problem(doc).stages[0].varying.noise_knots is None
    assert parse_problem(_dense_noise_doc(False)).stages[0].varying.noise_knots is None


def test_segment_operators_are_the_operator_of_the_interpolated_noise():
    """Between two noise knots the three operators of a segment, weighted (1-w)^2, w(1-w), w^2,
    give the packed diffusion operator of G at that time, and the segment's ends
    interpolate G there."""
    problem = parse_problem(_dense_noise_doc(True))
    stage = problem.stages[0]
    times = np.linspace(0.05, 0.95, 10)
    segs = varying.segment_operators(stage, times, T=5)
    s = stage.samples(times)
    GH = np.concatenate([s["G"], s["H"]], axis=1)[:, segs.act]
    n, na = GH.shape[2], segs.act.size
    rows, cols = np.triu_indices(na), np.triu_indices(n)
    for j, t in enumerate(times):
        w, ops = segs.w[j], segs.ops[segs.idx[j]]
        formed = (1 - w) ** 2 * ops[0] + w * (1 - w) * ops[1] + w * w * ops[2]
        direct = varying._pair_operator(GH[j], GH[j], rows, cols)
        np.testing.assert_allclose(formed, direct, rtol=0, atol=1e-14 * np.abs(direct).max())
        np.testing.assert_allclose(segs.ops_t[segs.idx[j]], ops.swapaxes(1, 2))
        ends = segs.ends[segs.idx[j]]
        np.testing.assert_allclose((1 - w) * ends[0] + w * ends[1], GH[j], rtol=0, atol=1e-15)
    assert varying.segment_operators(stage, times, T=3) is None      # 2 segments > T/2


@pytest.mark.parametrize("bad", ["index", "place"])
def test_bad_segments_are_refused_by_the_c_loops(bad, monkeypatch):
    """A segment index out of range or a place outside [0, 1]: both loops return their
    dimensions status (-2), which `zoh_ticks` and `oracle_ticks` raise as a bug."""
    problem = parse_problem(_dense_noise_doc(True))
    table = table_of(design_zoh(problem), quantize=False)
    real = varying.segment_operators

    def broken(*args):
        segs = real(*args)
        idx, w = segs.idx.copy(), segs.w.copy()
        if bad == "index":
            idx[-1] = segs.ops.shape[0]
        else:
            w[0] = 1.5
        return varying.Segments(segs.act, segs.ends, segs.ops, segs.ops_t, idx, w)

    monkeypatch.setattr(varying, "segment_operators", broken)
    varying._CACHE.clear()
    with pytest.raises(RuntimeError, match="stsp_tv_zoh_ticks: status -2"):
        design_zoh(problem)
    with pytest.raises(RuntimeError, match="stsp_tv_oracle_ticks: status -2"):
        evaluate_table(problem, table, path=False)
    varying._CACHE.clear()


def test_avx2_clones_give_the_default_copys_bits(monkeypatch):
    """The C loops' AVX2 copies (picked at load time on a CPU that has AVX2) against the kernels
    built with the default copy only, as a CPU without AVX2 runs them: the same bits for the
    design and the oracle, on every noise path. (On a CPU without AVX2 both are the default.)"""
    from stospline.cache import KERNEL_CFLAGS, build_kernel_sources, load_module
    from stospline.design import kernels

    plain = load_module(build_kernel_sources("_stsp_kernels", kernels._SOURCES, kernels._CDEF,
                                             KERNEL_CFLAGS + ["-DSTSP_TV_NO_CLONES"]))
    problem = parse_problem(_dense_noise_doc(True))

    def bits(module, path):
        monkeypatch.setattr(kernels, "_load", lambda: module)
        monkeypatch.setattr(varying, "NOISE_PATH", path)
        varying._CACHE.clear()
        d = design_zoh(problem)
        c = evaluate_table(problem, table_of(d, quantize=False), path=True)
        return (b"".join(s.K.tobytes() + s.k0.tobytes() for s in d.stages)
                + np.float64(c.J).tobytes() + c.path_var.tobytes())

    clones = kernels.load_kernels()
    for path in ("columns", "operator", "segments"):
        assert bits(plain, path) == bits(clones, path), path
