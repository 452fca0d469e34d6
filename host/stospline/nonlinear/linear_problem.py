"""The problem file of a linearisation: the user's file with ``[plant]`` replaced by the
linear model sampled along the path (`[[stages]]` dynamics as samples, linear in between,
docs/guide/problem-file.md "Time-varying data: samples"), which every designer and the
oracle accept as they are. A field whose samples over a stage agree to rounding is written as
one constant (a zero drift not at all), so that a model linear in x and u gives the linear
problem file it is, time-invariant data and all."""
from __future__ import annotations

import numpy as np

from stospline.design.linearise import Linearisation
from stospline.errors import ProblemError

__all__ = ["linear_doc", "ADDITIVE_TOLERANCE"]

# The diffusion's part independent of x and u, relative to its size, above which the model
# is refused: the problem's noise is Σ x_i G_i + Σ u_j H_j, with no additive term.
ADDITIVE_TOLERANCE = 1e-7
# Samples that differ by at most this many eps of the field's largest entry are one
# constant: the wide differences of a linear model (`stospline.design.linearise`) give its
# coefficients to a few eps.
_CONSTANT_EPS = 16


def _check_additive(lin: Linearisation, t: np.ndarray) -> None:
    scale = 1 + np.max(np.abs(lin.G), axis=(1, 2, 3)) + np.max(np.abs(lin.H), axis=(1, 2, 3))
    size = np.max(np.abs(lin.g0), axis=(1, 2)) / scale
    k = int(np.argmax(size))
    if size[k] > max(ADDITIVE_TOLERANCE, 100 * lin.error):
        raise ProblemError("plant.source", f"the diffusion has a part independent of x and u "
                           f"(|g0| = {size[k]:.3g} at t = {t[k]:g}); the linear model's "
                           f"noise is Σ x_i G_i + Σ u_j H_j only: write the additive noise as "
                           f"a state held constant at 1, or make it proportional to x or u")


def linear_doc(doc: dict, lin: Linearisation, t: np.ndarray, stages: list[slice]) -> dict:
    """`doc` (the decoded problem file) with the linear model `lin` at the times `t` as the
    dynamics of every user stage, ``stages[k]`` the points of stage k (from its start to its
    end, both included); ``[plant]`` dropped."""
    _check_additive(lin, t)
    n, m = lin.B.shape[1:]
    state_noise = [i for i in range(n) if np.any(lin.G[:, i])]
    input_noise = [j for j in range(m) if np.any(lin.H[:, j])]
    user = doc.get("stages", [{}] * len(stages))
    out_stages = []
    for k, sl in enumerate(stages):
        def samples(values):
            v = values[sl]
            scale = np.max(np.abs(v), initial=0.0)
            if np.all(np.abs(v - v[0]) <= _CONSTANT_EPS * np.finfo(float).eps * scale):
                return v[0]
            return {"t": t[sl], "values": v, "interpolation": "linear"}
        dyn = {"A": samples(lin.A), "B": samples(lin.B)}
        if np.any(lin.c[sl]):
            dyn["f"] = samples(lin.c)
        noise = [{"state": i, "G": samples(lin.G[:, i])} for i in state_noise]
        noise += [{"input": j, "G": samples(lin.H[:, j])} for j in input_noise]
        if noise:
            dyn["noise"] = noise
        out_stages.append({**user[k], "dynamics": dyn})
    out = {key: v for key, v in doc.items() if key != "plant"}
    out["dynamics"] = {"A": lin.A[0], "B": lin.B[0]}
    out["stages"] = out_stages
    return out
