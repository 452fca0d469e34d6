"""The sensor loop's fourth moments with faults and a sampled V (estimator.tails) against a
brute force that shares none of its moment algebra: every path of a small loop (one state,
three ticks) enumerated over the three-point Gauss-Hermite nodes of every noise variable it
draws (the plant's increments, the sensor's noise, the sensor-noise and actuator-noise
faults) and over every pattern of missed ticks, each path run as the firmware and the
harness run it (update, late latch, command held on a miss, predictor over the miss). The
path's state is multilinear in those variables, its cost quadratic, so the fourth moments and
the cost's variance are polynomials of degree at most four in each, which the rule
integrates exactly: the two must agree to rounding. The same comparison rejects the loop
with any one fault left out, with V held at its first sample, and with the Gaussian fourth
moment of the faults' noise replaced by the square of its variance (second moments intact).
"""
import copy
import dataclasses
import itertools

import numpy as np
import pytest

from stospline.design.moments import augmented_drift, running_cost_matrix
from stospline.estimator import tails as est_tails
from stospline.estimator.oracle import evaluate_estimator
from stospline.estimator.tails import estimator_tails_unsupported, evaluate_estimator_tails
from stospline.expm import expm
from stospline.pipeline import design_problem
from stospline.problem.faults import parse_faults
from stospline.problem.reader import parse_problem

DOC = {  # a scalar plant with state-multiplicative noise; two stages, three ticks
    "name": "scalar_sensor_faults", "x0": [1.0], "tick_hz": 2,
    "dynamics": {"A": [[-0.3]], "B": [[1.0]], "f": [0.2],
                 "noise": [{"state": 0, "G": [[0.5]]}]},
    "cost": {"Q": [[0.4]], "R": [[1.0]]},
    "knots": [{"t": 1.0, "penalty": {"C": [[1.0]], "target": [0.5], "weight": 2.0},
               "constraint": {"C": [[1.0]], "value": [0.5]}},
              {"t": 1.5, "penalty": {"C": [[1.0]], "target": [0.0], "weight": 1.0},
               "constraint": {"C": [[1.0]], "value": [0.0]}}],
    "measurement": {"C": [[1.0]], "V": {"t": [0, 1.5], "values": [[[0.3]], [[0.01]]]}},
}
FAULTS = {"sensor_noise": [0.4], "actuator_noise": [0.6], "plant_A_scale": 1.5,
          "plant_B_scale": 0.7, "plant_noise_scale": 1.3, "miss_probability": 0.3}
SUBSTEPS = 1
RTOL = 1e-9
PTS, WTS = np.sqrt(3.0) * np.array([-1.0, 0.0, 1.0]), np.array([1.0, 4.0, 1.0]) / 6.0


@pytest.fixture(scope="module")
def case():
    problem = parse_problem(copy.deepcopy(DOC))
    d = design_problem(problem)
    nominal = evaluate_estimator(problem, d.table, propagator="euler", substeps=SUBSTEPS)
    return problem, d.table, nominal.gain, nominal.predict


def _faults(problem, drop=None):
    return parse_faults({k: v for k, v in FAULTS.items() if k != drop}, problem.n, problem.m)


def _tails(problem, table, gains, pred, faults, meas=None):
    if meas is not None:
        problem = dataclasses.replace(problem, measurement=meas)
    loop = evaluate_estimator(problem, table, gains=gains, predictor=pred, faults=faults,
                              propagator="euler", substeps=SUBSTEPS)
    return evaluate_estimator_tails(problem, table, loop, predictor=pred, substeps=SUBSTEPS,
                                    faults=faults)


class _Paths:
    """A weighted population of paths, each with its named arrays (one row per path); `draw`
    splits every path at the three Gauss-Hermite nodes of a new N(0, scale^2) variable."""

    def __init__(self, **arrays):
        self.a = {}
        self.set(**arrays)
        self.w = np.ones(1)

    def draw(self, scale: float) -> None:
        N = len(self.w)
        self.a = {k: np.repeat(v, 3, axis=0) for k, v in self.a.items()}
        self.w = np.repeat(self.w, 3) * np.tile(WTS, N)
        self.a.setdefault("noise", np.zeros((3 * N, 0)))
        self.a["noise"] = np.hstack([self.a["noise"], np.tile(PTS, N)[:, None] * scale])

    def draws(self, scales) -> np.ndarray:
        """New variables of these scales (one column each)."""
        self.a["noise"] = np.zeros((len(self.w), 0))
        for s in scales:
            self.draw(s)
        return self.a.pop("noise")

    def __getattr__(self, key):
        return self.__dict__["a"][key]

    def set(self, **arrays):
        self.a.update({k: np.atleast_2d(np.asarray(v, float)) for k, v in arrays.items()})


def _brute(problem, table, gains, pred, faults):
    """(E J, E J^2, per knot E x, E x^2, E x^3, E x^4) over every path, as `_Paths` splits
    them, and every pattern of missed ticks."""
    meas = problem.measurement
    plant = faults.plant_of(problem)
    n, m, nl = table.dims
    h = 1.0 / table.tick_hz
    dt = h / SUBSTEPS
    miss = faults.miss_probability
    sig_x = faults.sensor_noise if faults.sensor_noise.size else np.zeros(n)
    sig_u = faults.actuator_noise if faults.actuator_noise.size else np.zeros(m)
    EJ = EJ2 = 0.0
    raw = np.zeros((table.n_stages, 4, n))
    for pattern in itertools.product([True, False], repeat=table.n_ticks):
        weight = np.prod([1.0 - miss if ran else miss for ran in pattern])
        if weight == 0.0:
            continue
        P = _Paths(x=problem.x0, xh=problem.x0, v=np.zeros(nl), ul=table.u_hold, J=[0.0])
        for k in range(table.n_stages):
            st = plant.stages[k]
            Ad = expm(augmented_drift(st, m + 1) * dt)[:n]        # on [x; u; 1]
            Lb = running_cost_matrix(st, n, m, n + m + 1, n)
            Gt = st.noise_tensor                                  # (n + m, n, mz)
            latched = not (k == 0 or table.stage_n_latch[k] > 0)
            for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
                if pattern[j]:
                    if meas.samples_at(j):
                        sqV = np.linalg.cholesky(meas.V_at(table.t0 + j * h))
                        e = P.draws([1.0] * meas.p + list(sig_x))
                        y = (P.x + e[:, meas.p:]) @ meas.C.T + e[:, :meas.p] @ sqV.T
                        P.set(xh=P.xh + (y - P.xh @ meas.C.T) @ np.asarray(gains[j]).T)
                    if not latched:
                        P.set(v=P.xh @ table.Lambda[k].astype(float).T
                              + table.lambda0[k].astype(float))
                        latched = True
                    P.set(u=-(P.xh @ table.K[j].astype(float).T
                              + P.v @ table.L[j].astype(float).T + table.k0[j].astype(float)))
                else:
                    P.set(u=P.ul)
                eta = P.draws(sig_u)
                P.set(ua=P.u + eta)
                for _ in range(SUBSTEPS):
                    q = np.hstack([P.x, P.ua, np.ones((len(P.w), 1))])
                    P.set(J=P.J + dt * np.einsum("pi,ij,pj->p", q, Lb, q)[:, None])
                    xi = P.draws([np.sqrt(dt)] * Gt.shape[2])
                    q = np.hstack([P.x, P.ua, np.ones((len(P.w), 1))])
                    P.set(x=q @ Ad.T + np.einsum("pa,aik,pk->pi", q[:, :n + m], Gt, xi))
                pj = np.asarray(pred[j], float)       # the predictor, with the command written
                P.set(xh=P.xh @ pj[:, :n].T + P.u @ pj[:, n:n + m].T + pj[:, -1], ul=P.u)
            kn = problem.knots[k]
            if kn.penalty is not None:
                res = P.x @ kn.penalty.C.T - kn.penalty.target
                P.set(J=P.J + kn.penalty.weight * np.einsum("pi,pi->p", res, res)[:, None])
            for a in range(4):
                raw[k, a] += weight * (P.w @ P.x ** (a + 1))
        EJ += weight * (P.w @ P.J[:, 0])
        EJ2 += weight * (P.w @ P.J[:, 0] ** 2)
    return EJ, EJ2, raw


def _differences(tails, brute) -> dict:
    """Relative differences of the cost's mean and variance and the knot moments."""
    EJ, EJ2, raw = brute
    out = {"J": abs(tails.J - EJ) / abs(EJ),
           "cost_var": abs(tails.cost_var - (EJ2 - EJ ** 2)) / (EJ2 - EJ ** 2)}
    for k, (m1, m2, m3, m4) in enumerate(raw):
        var = m2 - m1 ** 2
        mu4 = m4 - 4 * m3 * m1 + 6 * m2 * m1 ** 2 - 3 * m1 ** 4
        out[f"knot {k} mean"] = np.max(np.abs(tails.knot_mean[k] - m1)) / np.sqrt(var.max())
        out[f"knot {k} var"] = np.max(np.abs(np.diag(tails.knot_cov[k]) - var) / var)
        out[f"knot {k} mu4"] = np.max(np.abs(tails.knot_mu4[k] - mu4) / mu4)
    return out


@pytest.fixture(scope="module")
def brute(case):
    problem, table, gains, pred = case
    return _brute(problem, table, gains, pred, _faults(problem))


def test_fourth_moments_with_faults_and_sampled_V_equal_the_path_quadrature(case, brute):
    problem, table, gains, pred = case
    faults = _faults(problem)
    assert estimator_tails_unsupported(problem, table, faults) is None
    diff = _differences(_tails(problem, table, gains, pred, faults), brute)
    assert max(diff.values()) < RTOL, diff


@pytest.mark.parametrize("drop", list(FAULTS) + ["sampled V"])
def test_the_loop_without_one_fault_is_rejected(case, brute, drop):
    """Left out of the fourth-moment loop (its own second moments consistent), each fault,
    and V's sampling, moves the cost's variance or a knot's fourth moment away from the
    brute force's by far more than the tolerance."""
    problem, table, gains, pred = case
    meas = None
    faults = _faults(problem, drop)
    if drop == "sampled V":
        meas = dataclasses.replace(problem.measurement, V_series=None)
    diff = _differences(_tails(problem, table, gains, pred, faults, meas), brute)
    fourth = max(v for key, v in diff.items() if key == "cost_var" or key.endswith("mu4"))
    assert fourth > 1e3 * RTOL, (drop, diff)


def test_a_wrong_fourth_moment_of_the_fault_noise_is_rejected(case, brute, monkeypatch):
    """Plant a bug the second-moment check cannot see: the appended Gaussian noise's fourth
    moment taken as the square of its variance (E r^4 = R^2, not 3 R^2)."""
    problem, table, gains, pred = case
    real = est_tails._with_noise

    def wrong(T4, P, Rq):
        W, Pr, zi, ri = real(T4, P, Rq)
        W[np.ix_(ri, ri, ri, ri)] /= 3.0
        return W, Pr, zi, ri

    monkeypatch.setattr(est_tails, "_with_noise", wrong)
    diff = _differences(_tails(problem, table, gains, pred, _faults(problem)), brute)
    assert diff["J"] < RTOL and diff["knot 0 var"] < RTOL     # second moments intact
    assert diff["cost_var"] > 1e3 * RTOL or max(
        v for key, v in diff.items() if key.endswith("mu4")) > 1e3 * RTOL, diff


def test_refused_loops_say_why(case):
    problem, table, _, _ = case
    assert "delay_ticks" in estimator_tails_unsupported(
        problem, table, parse_faults({"delay_ticks": 1}, 1, 1))
    assert "sensor_quantum" in estimator_tails_unsupported(
        problem, table, parse_faults({"sensor_quantum": [0.1]}, 1, 1))
