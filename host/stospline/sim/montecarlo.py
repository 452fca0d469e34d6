"""Monte Carlo of the compiled C controller against a simulation of the SDE plant.

Between ticks the command is held and the plant advances by `substeps` exponential
Euler–Maruyama steps ``x+ = e^{A dt} x + Gamma u + sum_i x_i G_i dZ`` (exact for the mean,
O(dt) weak error in the second moments). The oracle evaluates the same scheme exactly
(`oracle.euler_tick`), so the simulation bias is a computed number, not a guess.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from stospline.expm import expm

from stospline import progress
from stospline.sim.controller import STATUS, CompiledController
from stospline.problem.model import Problem

if TYPE_CHECKING:
    from stospline.sim.plant_scheme import SubstepChoice

__all__ = ["MonteCarloResult", "simulate", "z_value", "Agreement", "compare_to_oracle",
           "JointVerdict", "joint_verdict", "DETERMINISTIC_RTOL"]


def z_value(confidence: float, comparisons: int = 1) -> float:
    """Two-sided normal quantile; Bonferroni-corrected for `comparisons` joint intervals."""
    from scipy.stats import norm   # lazy: importing scipy.stats takes longer than a design
    return float(norm.ppf(1 - (1 - confidence) / (2 * comparisons)))


@dataclass
class MonteCarloResult:
    cost: np.ndarray                 # (paths,) realised cost of every path
    knot_states: list[np.ndarray]    # per knot (paths, n)
    sample_t: np.ndarray             # tick times, (ticks + 1,)
    sample_x: np.ndarray             # one realisation (ticks + 1, n)
    sample_u: np.ndarray             # its commands (ticks, m)
    mean_x: np.ndarray               # Monte Carlo mean path (ticks + 1, n)
    worst_status: int
    # Ticks on which the C controller returned STSP_WARN_SATURATED, per path (paths,), and
    # the smallest and largest command it issued per input over all paths and ticks (m,).
    saturated_ticks: np.ndarray | None = None
    u_low: np.ndarray | None = None
    u_high: np.ndarray | None = None
    substeps: int = 0                # plant steps per tick of this run
    # How `substeps` was chosen (pipeline.simulate_problem with substeps="auto"), else None.
    substep_choice: "SubstepChoice | None" = None

    @property
    def paths(self) -> int:
        return self.cost.shape[0]

    @property
    def saturated_fraction(self) -> float:
        """Fraction of all (path, tick) steps on which the controller clamped a command."""
        ticks = self.sample_u.shape[0]
        if self.saturated_ticks is None or ticks == 0:
            return 0.0
        return float(self.saturated_ticks.sum()) / (self.paths * ticks)

    def cost_mean_ci(self, confidence: float = 0.95) -> tuple[float, float]:
        """Mean cost and the half-width of its normal-approximation confidence interval."""
        se = self.cost.std(ddof=1) / np.sqrt(self.paths)
        return float(self.cost.mean()), z_value(confidence) * float(se)

    def knot_mean_se(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        X = self.knot_states[k]
        return X.mean(axis=0), X.std(axis=0, ddof=1) / np.sqrt(X.shape[0])

    def knot_cov(self, k: int) -> np.ndarray:
        return np.cov(self.knot_states[k], rowvar=False)


def _zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = B.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = A, B
    E = expm(big * dt)
    return E[:n, :n], E[:n, n:]


def simulate(problem: Problem, controller: CompiledController, *, paths: int, seed: int,
             substeps: int = 4) -> MonteCarloResult:
    """Run `paths` realisations of the plant with the compiled controller in the loop.

    Parameters
    ----------
    problem : Problem
        The plant (dynamics, noise, cost) and x0; the controller's table is what is tested.
    controller : CompiledController
    paths : int
        Number of paths (>= 1; ValueError otherwise, before anything is allocated).
    seed : int or numpy.random.SeedSequence
        Seed of ``numpy.random.default_rng``.
    substeps : int
        Plant steps per controller tick (>= 1) (time-varying data are frozen at each step's
        midpoint, a second-order error in the step).
    """
    for name, value in (("paths", paths), ("substeps", substeps)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    table = controller.table
    rng = np.random.default_rng(seed)
    n, m = problem.n, problem.m
    h = 1.0 / table.tick_hz
    dt = h / substeps
    sq = np.sqrt(dt)
    X = np.ascontiguousarray(np.tile(problem.x0, (paths, 1)), dtype=float)
    cost = np.zeros(paths)
    step = controller.stepper(paths)
    knots, worst = [], 0
    saturated = np.zeros(paths, dtype=np.int64)
    u_low, u_high = np.full(m, np.inf), np.full(m, -np.inf)
    sample_x = [X[0].copy()]
    sample_u = []
    mean_x = [X.mean(axis=0)]
    bar = progress.start(f"simulate ({paths} paths)", table.n_ticks)
    for k in range(table.n_stages):
        st = problem.stages[k]
        Ad, Bd = _zoh(st.A, st.B, dt)
        mz = st.G.shape[2]
        for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            U, status = step(j, X)
            worst = min(worst, int(status.min()))
            saturated += status == STATUS["WARN_SATURATED"]
            np.minimum(u_low, U.min(axis=0), out=u_low)
            np.maximum(u_high, U.max(axis=0), out=u_high)
            dZ = rng.standard_normal((paths, substeps, mz)) * sq
            if st.varying is None:
                controller.plant_tick(st, Ad, Bd, dt, substeps, dZ, U, X, cost)
            else:
                # Time-varying data: each substep uses the data at its midpoint.
                for i in range(substeps):
                    sd = st.at(problem.t0 + j * h + (i + 0.5) * dt)
                    Adi, Bdi = _zoh(sd.A, sd.B, dt)
                    controller.plant_tick(sd, Adi, Bdi, dt, 1,
                                          np.ascontiguousarray(dZ[:, i:i + 1]), U, X, cost)
            sample_x.append(X[0].copy())
            sample_u.append(U[0].astype(float))
            mean_x.append(X.mean(axis=0))
            progress.advance()
        knot = problem.knots[k]
        if knot.penalty is not None:
            r = X @ knot.penalty.C.T - knot.penalty.target
            cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
        knots.append(X.copy())
    progress.finish(bar)
    t = problem.t0 + np.arange(table.n_ticks + 1) * h
    return MonteCarloResult(cost, knots, t, np.array(sample_x), np.array(sample_u),
                            np.array(mean_x), worst, saturated, u_low, u_high, substeps)


# A deterministic statistic (zero Monte Carlo spread) agrees when it is this close, relative.
DETERMINISTIC_RTOL = 1e-6


@dataclass(frozen=True)
class JointVerdict:
    """Monte Carlo statistics against exact values, all at once: each z-score within the
    two-sided normal bound `z_limit`, Bonferroni-corrected so that a correct controller passes
    every one of them together with probability `confidence`."""
    agree: bool
    confidence: float
    statistics: int
    z_limit: float
    max_abs_z: float
    max_abs_z_of: str | None
    outside: tuple[str, ...]     # the statistics that fail


def joint_verdict(stats, confidence: float = 0.99) -> JointVerdict:
    """`stats`: (name, z, Monte Carlo value, exact value) per statistic, z None where the
    Monte Carlo spread is zero (every path alike): that statistic must then equal the exact
    value to DETERMINISTIC_RTOL relative."""
    stats = list(stats)
    limit = z_value(confidence, len(stats))
    worst_name, worst, outside = None, 0.0, []
    for name, z, mc_value, exact in stats:
        if z is None:
            if abs(mc_value - exact) > DETERMINISTIC_RTOL * max(1.0, abs(exact)):
                outside.append(name)
            continue
        if worst_name is None or abs(z) > worst:
            worst_name, worst = name, abs(z)
        if not abs(z) <= limit:
            outside.append(name)
    return JointVerdict(not outside, confidence, len(stats), limit, worst, worst_name,
                        tuple(outside))


@dataclass
class Agreement:
    """Monte Carlo vs exact numbers: z-scores (0 where the spread is zero) and the joint
    verdict at a confidence level."""
    confidence: float
    z_limit: float
    cost_z: float
    knot_mean_z: list[np.ndarray]
    verdict: JointVerdict

    @property
    def max_abs_z(self) -> float:
        return self.verdict.max_abs_z

    @property
    def ok(self) -> bool:
        return self.verdict.agree


def compare_to_oracle(mc: MonteCarloResult, J: float, knot_means: list[np.ndarray], *,
                      confidence: float = 0.99) -> Agreement:
    """Compare the Monte Carlo cost and knot means with exact values (`joint_verdict`): the
    z-scores use the sample's own standard errors, Bonferroni-corrected so that the *joint*
    statement (cost and every knot-mean component) holds at `confidence` when the controller
    is right."""
    mean, _ = mc.cost_mean_ci()
    se = mc.cost.std(ddof=1) / np.sqrt(mc.paths)
    cost_z = float((mean - J) / se) if se > 0 else None
    stats = [("cost", cost_z, mean, J)]
    zs = []
    for k, exact in enumerate(knot_means):
        m, s = mc.knot_mean_se(k)
        z = [float((m[i] - exact[i]) / s[i]) if s[i] > 0 else None for i in range(len(m))]
        stats += [(f"knot {k} mean[{i}]", z[i], m[i], exact[i]) for i in range(len(m))]
        zs.append(np.array([0.0 if v is None else v for v in z]))
    v = joint_verdict(stats, confidence)
    return Agreement(confidence, v.z_limit, 0.0 if cost_z is None else cost_z, zs, v)
