#!/usr/bin/env python3
"""Plant plausible bugs in the firmware, one at a time, and show that the tests catch each.

For every fault below the script copies the C sources (``CMakeLists.txt``, ``cmake/``,
``firmware/``, ``tests/c/``, ``tests/consumer/``, ``gains/``, ``tools/bench/``) into a
temporary directory, applies the one edit there, rebuilds that copy, and runs

* the C tests of the copy: ``ctest`` without the clang, ARM, MISRA and consumer tests (controller,
  controller_fixed_2_1_2, robot_table, robot_table_fixed, the fixed-point (Q15/Q31) tests and
  their ASan + UBSan builds), and
* a fast subset of the Python tests that drive the C code through the cffi harness
  (``tests/python/firmware/test_c_step_equals_law.py``, ``sim/test_monte_carlo_vs_oracle.py``,
  ``firmware/test_table_limits.py``, ``firmware/test_fixed_point.py``),
  pointed at the faulty copy with ``STOSPLINE_FIRMWARE`` and a private ``STOSPLINE_BUILD``.

The working tree is never modified: the edits happen in the copy only, pytest runs with
``-p no:cacheprovider`` and ``PYTHONDONTWRITEBYTECODE=1``, and the script checks at the end
that the hashes of ``firmware/`` and ``tests/c/`` are what they were at the start. A run
without any fault comes first and must pass. Exit status 0 only if every fault is caught.

    .venv/bin/python tools/plant_faults.py            # all faults (about 10 minutes)
    .venv/bin/python tools/plant_faults.py --list
    .venv/bin/python tools/plant_faults.py --only F3 F5 --no-python
"""
from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# A fault names a file, or the firmware source directory: then the one file under it that holds
# the text to replace (the controller is split into files of one job each).
CTL = "firmware/src"
CRC = "firmware/src"
PY_TESTS = ["tests/python/firmware/test_c_step_equals_law.py",
            "tests/python/sim/test_monte_carlo_vs_oracle.py",
            "tests/python/firmware/test_table_limits.py", "tests/python/firmware/test_fixed_point.py",
            "tests/python/firmware/test_band_relatch.py", "tests/python/table/test_qspline_c.py",
            "tests/python/firmware/test_qspline_controller.py"]
CTEST_EXCLUDE = r"^(clang_|arm_|misra|consumer_)"


@dataclass(frozen=True)
class Fault:
    key: str
    title: str
    path: str
    old: str
    new: str


FAULTS = [
    Fault("F1", "fast finiteness check only catches NaN (Inf passes)", CTL,
          "if (!((sum - sum) == 0.0f)) {", "if (!(sum == sum)) {"),
    Fault("F2", "NaN check of the state looks at x[0] only (a bad x[1] reported as overflow)",
          CTL, "return (stsp_all_finite(x, stsp_nx(h)) == 0) ? STSP_ERR_NONFINITE_STATE",
          "(void)h;\n    return (stsp_all_finite(x, 1u) == 0) ? STSP_ERR_NONFINITE_STATE"),
    Fault("F3", "off-by-one tick range: the tick after the last is accepted", CTL,
          "if (tick >= h->n_ticks) {", "if (tick > h->n_ticks) {"),
    Fault("F4", "wrong latch time: stage search switches one tick late", CTL,
          "(h->stage_start[s + 1u] <= tick)", "(h->stage_start[s + 1u] < tick)"),
    Fault("F5", "sign flip in a gain: L v added instead of subtracted (every arithmetic)", CTL,
          "acc = stsp_row_mac(acc, L[j], v[j]);",
          "acc = stsp_row_mac(acc, L[j], (stsp_scalar_t)-v[j]);"),
    Fault("F6", "missing saturation at the upper limit", CTL,
          "            u[i] = h->u_max[i];\n", "            /* clamp dropped */\n"),
    Fault("F7", "latch offset lambda0 dropped", CTL,
          "stsp_f32_t acc = lambda0;", "stsp_f32_t acc = 0.0f * lambda0;"),
    Fault("F8", "a repeated first tick of a stage latches again", CTL,
          "if ((c->latched == 0u) || ((stage != c->stage) && (n_stage > 0u))) {",
          "if ((c->latched == 0u) || ((tick == h->stage_start[stage]) && (n_stage > 0u))) {"),
    Fault("F9", "the tick is consumed before the overflow check (instance changed on error)",
          CTL,
          "    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {\n"
          "        return stsp_step_nonfinite(ctrl, x, u);",
          "    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {\n"
          "        ctrl->next_tick = tick + 1u;\n        return stsp_step_nonfinite(ctrl, x, u);"),
    Fault("F10", "command not set to u_hold on an error of an ordinary tick", CTL,
          "    const stsp_status_t st = stsp_nonfinite_status(&ctrl->checked, x);\n"
          "    stsp_hold(ctrl, u);\n",
          "    const stsp_status_t st = stsp_nonfinite_status(&ctrl->checked, x);\n"
          "    (void)u;\n"),
    Fault("F11", "CRC does not cover u_max", CRC,
          "    crc = stsp_crc32_scalars(crc, table->u_max, nu);\n", ""),
    Fault("F12", "off-by-one tick order: a repeated tick is refused as going backwards", CTL,
          "if ((tick + 1u) < c->next_tick) {", "if (tick < c->next_tick) {"),
    Fault("F13", "feed-forward k0 of the next tick (off-by-one row)", CTL,
          "const stsp_scalar_t *k0 = &h->k0[tick * nu];",
          "const stsp_scalar_t *k0 = &h->k0[((tick + 1u) % h->n_ticks) * nu];"),
    # Band tables: the t0 latch re-solves the band dual (float32).
    Fault("F20", "band table: the t0 latch ignores the band dual (affine map only)", CTL,
          "    if ((plan->relatch != 0u) && (stage == 0u) && (h->band_qp != NULL)) {",
          "    if ((plan->relatch != 0u) && (stage == 1u) && (h->band_qp != NULL)) {"),
    Fault("F21", "band table: a failed solve latches zeros instead of the affine map",
          CTL, "        status = STSP_WARN_BAND_FALLBACK; /* the affine map below, from the "
               "design's x0 */\n    }",
          "        status = STSP_WARN_BAND_FALLBACK; /* the affine map below, from the "
          "design's x0 */\n        stsp_zero(v_new, n_latch);\n        return status;\n    }"),
    Fault("F22", "band table: CRC does not cover the band bounds", CTL,
          "        crc = stsp_crc32_f64s(crc, b->hi, q);\n", ""),
    # Fixed-point (Q15/Q31) code paths.
    Fault("F14", "Q15 rounding: the half-LSB bias dropped (rounds down)", CTL,
          "    return 1073758208u;", "    return 1073741824u;"),
    Fault("F15", "Q: law row-sum check off by one (a row summing to 2^F is accepted)", CTL,
          "            sum += stsp_q_abs_sum(&t->L[r * n_latch], n_latch);\n        }\n"
          "        if (sum > row_max) {",
          "            sum += stsp_q_abs_sum(&t->L[r * n_latch], n_latch);\n        }\n"
          "        if (sum > (row_max + 1u)) {"),
    Fault("F16", "Q: CRC does not cover v_exp", CTL,
          "        crc = stsp_crc32_i8s(crc, table->v_exp, n_latch);\n", ""),
    Fault("F17", "Q: latch rows not checked at init", CTL,
          "stsp_q_abs_sum(&t->Lambda[r * nx], nx)) >\n            row_max) {",
          "stsp_q_abs_sum(&t->Lambda[r * nx], nx)) >\n            (row_max + row_max)) {"),
    Fault("F18", "Q: state conversion truncates instead of rounding half up",
          "firmware/src/stsp_qconv.c", "const stsp_f32_t r = s + 0.5f;", "const stsp_f32_t r = s;"),
    Fault("F19", "Q: a law row starts without the accumulator's bias (rounding, offset lost)",
          CTL, "stsp_q_mac(stsp_q_start(), (a), (b))", "stsp_q_mac(0u, (a), (b))"),
    # A table changed after init (stsp_verify) and x/u sharing a buffer.
    Fault("F23", "verify skips the header check (a changed header is not reported)", CTL,
          "    if (stsp_header_changed(&ctrl->checked, ctrl->table) != 0) {",
          "    if (stsp_header_changed(&ctrl->checked, ctrl->table) > 1) {"),
    Fault("F24", "stage end not capped at n_ticks (stage_start changed after init)", CTL,
          "    return (end < h->n_ticks) ? end : h->n_ticks;",
          "    return end;"),
    Fault("F25", "ordinary tick writes u before classifying a non-finite command", CTL,
          "#endif\n#ifndef STSP_ARITH_FIXED_POINT\n    /* A NaN/Inf command: which error",
          "#endif\n    stsp_copy(u, y, stsp_nu(&ctrl->checked));\n"
          "#ifndef STSP_ARITH_FIXED_POINT\n    /* A NaN/Inf command: which error"),
    Fault("F26", "the command is written for the header's nu, not the validated one", CTL,
          "    stsp_copy_command(u, y, stsp_nu(&ctrl->checked));\n    if (out != 0u) {",
          "    stsp_copy_command(u, y, ctrl->table->nu);\n    if (out != 0u) {"),
    Fault("F27", "a refused step writes zeros, not the safe command u_hold", CTL,
          "    stsp_copy(u, ctrl->hold, stsp_nu(&ctrl->checked));",
          "    stsp_zero(u, stsp_nu(&ctrl->checked));"),
    Fault("F28", "CRC does not cover u_hold", CRC,
          "    crc = stsp_crc32_scalars(crc, table->u_hold, nu);\n", ""),
    Fault("F29", "init does not check u_hold against the limits (float32)", CTL,
          "(stsp_isfinite_f32(hold) == 0) || !(lo <= hold) || !(hi >= hold)",
          "(stsp_isfinite_f32(hold) == 0)"),
    Fault("F30", "Q: init does not check u_hold against the limits", CTL,
          "if ((t->u_min[r] > t->u_hold[r]) || (t->u_max[r] < t->u_hold[r])) {",
          "if (t->u_min[r] > t->u_max[r]) {"),
    Fault("F31", "a refused step reads u_hold from the table, not the copy made at init", CTL,
          "    stsp_copy(u, ctrl->hold, stsp_nu(&ctrl->checked));",
          "    stsp_copy(u, ctrl->checked.u_hold, stsp_nu(&ctrl->checked));"),
    Fault("F32", "init accepts a band table in a program without the band solver", CTL,
          "    if (b->solve_f32 == NULL) {", "    if (b->solve_f32 != b->solve_f32) {"),
    Fault("F33", "band order check compares magnitudes only (lo = -1 > hi = 0.5)", CTL,
          "    return ((bits >> 63) != 0u) ? -magnitude : magnitude;",
          "    return magnitude;"),
    Fault("F34", "spline basis: a wrong left term in the last round", CTL,
          "    n[3] = left1 * temp;", "    n[3] = left2 * temp;"),
    Fault("F35", "spline ordinary tick does not check the state (a sparse row hides a NaN)", CTL,
          "        total += x[i];", "        (void)x;"),
    Fault("F36", "spline operand index not bounded (col changed after init)", CTL,
          "    return (col < nx) ? col : (nx - 1u);", "    (void)nx;\n    return col;"),
    Fault("F37", "spline stage layout not bounded by the coefficient count (changed after init)",
          CTL, "        if ((e1 - e0) > ((sp->n_coef - c0) / (n_spans + 3u))) {",
          "        if ((e1 - e0) > sp->n_coef) {"),
    Fault("F38", "stsp_verify misses a changed spline coefficient address", CTL,
          "            (p->coef_start != q->coef_start) || (p->coef != q->coef) || (p->ops != q->ops)) {",
          "            (p->coef_start != q->coef_start) || (p->ops != q->ops)) {"),
    Fault("F39", "span search stops at a knot (tau == U[sigma + 4] stays in the left span)", CTL,
          "    while (((sigma + 1u) < n_spans) && !(tau < U[sigma + 4u])) {",
          "    while (((sigma + 1u) < n_spans) && (tau > U[sigma + 4u])) {"),
    Fault("F40", "the first tick of the next span evaluates the old span's knots", CTL,
          "    knot = &p->knot[1];", "    knot = p->knot;"),
    Fault("F41", "the fold at the first tick of the next span uses k0 and L of the old span", CTL,
          "    stsp_spline_fold(h, p, coef, ctrl->v, fold);",
          "    stsp_spline_fold(h, p, p->coef, ctrl->v, fold);"),
    Fault("F42", "init accepts a spline table in a program without the spline code", CTL,
          "        if (stsp_spline_code_ok(t->sp.ops) == 0) {",
          "        if (stsp_spline_code_ok(t->sp.ops) < 0) {"),
    # The generic float32 law (two rows at a time; the host runs the C branch of the M4F asm).
    Fault("F43", "generic float32 law: the second row of a pair uses the first row's gains", CTL,
          "            r1 = stsp_mls(r1, kp[nx + c], x[c]);",
          "            r1 = stsp_mls(r1, kp[c], x[c]);"),
    Fault("F44", "generic float32 law: an odd last row starts from +k0 (k0 added, not subtracted)",
          CTL, "        stsp_f32_t acc = -bp[0];", "        stsp_f32_t acc = bp[0];"),
    # The rows the generic float32 build keeps for tick next_tick (stsp_ctrl_t.rows).
    Fault("F55", "generic float32: a cold tick leaves the kept rows where they were (not the "
          "rows of tick + 1 its law moved on to)", CTL,
          "    ctrl->rows = next;\n", "\n"),
    Fault("F56", "generic float32: an odd last row does not move K on (the next ordinary tick "
          "reads this tick's last K row)", CTL,
          "        kp = &kp[nx];\n", "\n"),
    Fault("F57", "generic float32: an ordinary tick with a non-finite command keeps the moved "
          "rows (the refused step changes the instance)", CTL,
          "    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {\n"
          "        return stsp_step_nonfinite(ctrl, x, u);\n"
          "    }\n"
          "#endif\n"
          "#if STSP_ROW_CACHE\n"
          "    ctrl->rows = rows;\n"
          "#endif\n",
          "#if STSP_ROW_CACHE\n"
          "    ctrl->rows = rows;\n"
          "#endif\n"
          "    if ((out != 0u) && (stsp_command_finite(&ctrl->checked, y) == 0)) {\n"
          "        return stsp_step_nonfinite(ctrl, x, u);\n"
          "    }\n"
          "#endif\n"),
    # The fixed-point spline evaluation (stsp_qspline.c).
    Fault("F45", "fixed-point spline gain floored instead of rounded half up", CTL,
          "    const uint64_t up = halves + 1u;", "    const uint64_t up = halves;"),
    Fault("F46", "fixed-point spline basis P1 with 2D + d instead of 2D - d", CTL,
          "    p[1] = (4u * D3) - (3u * d * d * (D + e));",
          "    p[1] = (4u * D3) - (3u * d * d * (D + d));"),
    Fault("F47", "fixed-point spline layout check accepts a column equal to nx + 1 + n_latch",
          CTL, "            if ((sp->col[e] >= nz) ||", "            if ((sp->col[e] > nz) ||"),
    Fault("F48", "fixed-point spline layout check accepts a coefficient scale of 31", CTL,
          "(sp->shift[e] > STSP_QSPLINE_MAX_SHIFT)) {",
          "(sp->shift[e] > (STSP_QSPLINE_MAX_SHIFT + 1u))) {"),
    Fault("F49", "fixed-point spline gains read the previous span's coefficients", CTL,
          "    const stsp_scalar_t *c = &sp->coef[sp->coef_start[s] + sigma];",
          "    const stsp_scalar_t *c =\n"
          "        &sp->coef[(sp->coef_start[s] + sigma) - ((sigma > 0u) ? 1u : 0u)];"),
    # The fixed-point spline controller (stsp_spline.c, Q15/Q31 builds).
    Fault("F50", "fixed-point spline row bound not checked at each stage's last tick", CTL,
          "        for (tau = 0u; tau < ticks; ++tau) {",
          "        for (tau = 0u; (tau + 1u) < ticks; ++tau) {"),
    Fault("F51", "fixed-point spline law takes the first L gain for k0", CTL,
          "            k0 = (j == nx) ? g : k0;", "            k0 = (j > nx) ? g : k0;"),
    Fault("F52", "fixed-point spline step leaves stage_end set (next tick on the per-tick path)",
          CTL, "    ctrl->stage_end = 0u;\n    return status;",
          "    return status;"),
    Fault("F53", "fixed-point spline CRC leaves out the coefficient scales", CTL,
          "        c = stsp_crc32_u32(c, (uint32_t)sp->shift[i]);\n", ""),
    Fault("F54", "stsp_verify misses a fixed-point spline's moved shift array", CTL,
          "            (p->col != q->col) || (p->shift != q->shift) ||"
          " (p->coef_start != q->coef_start) ||",
          "            (p->col != q->col) || (p->coef_start != q->coef_start) ||"),
    # The fixed-point spline tick on a table changed after init (stsp_qspline_layout and
    # stsp_qspline_law, stsp_spline.c): the bounds by the validated lengths.
    Fault("F68", "fixed-point spline tick keeps a changed row end beyond the validated n_entries",
          CTL, "        if ((end < prev) || (end > sp->n_entries)) {",
          "        if (end < prev) {"),
    Fault("F69", "fixed-point spline tick reads a span beyond a changed entry stride", CTL,
          "        if ((st >= 4u) && (sigma <= (st - 4u))) {", "        if (st >= 4u) {"),
    Fault("F70", "fixed-point spline tick takes a changed operand index beyond z as the last one",
          CTL, "acc = stsp_q_mac(acc, g, z[(j < nz) ? j : nx]);",
          "acc = stsp_q_mac(acc, g, z[(j < nz) ? j : (nz - 1u)]);"),
    Fault("F71", "fixed-point spline gain shifts by a changed scale outside 1..30 unmasked "
          "(undefined shifts)", CTL,
          "    const uint32_t down = (sh - 1u) & 63u;", "    const uint32_t down = sh - 1u;"),
    # The fixed-point spline ordinary tick (stsp_spline_step, stsp_spline.c).
    Fault("F72", "fixed-point spline ordinary tick taken at the first tick of the next stage "
          "(no relatch, the old stage's gains)", CTL,
          "        (tick >= stsp_stage_end(h, stage))) {\n        return stsp_qspline_step_cold(",
          "        (tick > stsp_stage_end(h, stage))) {\n        return stsp_qspline_step_cold("),
    # The band solver's non-symmetric path (a spline band table's W', stsp_bandqp.c).
    Fault("F58", "band solver, non-symmetric W: no partial pivoting (the diagonal pivot kept)",
          CTL, "                piv = i;\n", "                piv = k;\n"),
    Fault("F59", "band solver: a non-symmetric W taken for symmetric (Cholesky of its lower "
          "triangle)", CTL, "            if (!(W[(i * q) + j] == W[(j * q) + i])) {\n                sym = 0u;",
          "            if (!(W[(i * q) + j] == W[(j * q) + i])) {\n                sym = 1u;"),
    Fault("F60", "band solver, non-symmetric W: an overflowed solution accepted", CTL,
          "            if ((r[row] - r[row]) != 0.0) {", "            if ((r[row] - r[row]) > 1.0) {"),
    # The controller on a sensor (stsp_estimator.c; tests/c/test_estimator.c).
    Fault("F73", "estimator: a NaN or infinite reading not refused (the update runs on it)", CTL,
          "        } else if (stsp_est_reading_ok(e, y) == 0) {",
          "        } else if (stsp_est_reading_ok(e, y) < 0) {"),
    Fault("F74", "estimator: the next sample's gain (index slip)", CTL,
          "            stsp_est_update(e, tick / e->every, y, xh, &clamped);",
          "            stsp_est_update(e, (tick / e->every) + 1u, y, xh, &clamped);"),
    Fault("F75", "estimator: the prediction made with the safe command, not the one written",
          CTL, "    stsp_est_predict(est, stage_start, stage, tick, xh, cmd, &clamped);",
          "    stsp_est_predict(est, stage_start, stage, tick, xh, est->ctrl.hold, &clamped);"),
    Fault("F76", "estimator: the CRC leaves out the gains", CTL,
          "        crc = stsp_crc32_scalars(crc, est->gain, stsp_est_samples(est) * nx * est->ny);\n",
          ""),
    Fault("F77", "estimator: a skip does not predict over the missed ticks", CTL,
          "    for (j = est->next_tick; j < tick; ++j) {", "    for (j = tick; j < tick; ++j) {"),
    Fault("F78", "estimator: a refused reading still updates the estimate", CTL,
          "            return stsp_est_hold(est, u, STSP_ERR_NONFINITE_MEASUREMENT);",
          "            stsp_est_update(e, tick / e->every, y, est->xhat, &clamped);\n"
          "            return stsp_est_hold(est, u, STSP_ERR_NONFINITE_MEASUREMENT);"),
    # The estimator's gain spline (stsp_estimator.c, float32; tests/c/test_estimator_spline.c).
    Fault("F96", "estimator (spline gains): the sample's abscissa not relative to its stage",
          CTL, "(tick / e->every) -\n                        stsp_est_first_sample(e, est->ctrl.checked.stage_start[s])",
          "(tick / e->every) -\n                        0u"),
    # The estimator in fixed point (stsp_estimator.c; tests/c/test_estimator.c built for Q15).
    Fault("F90", "estimator (Q15/Q31): a row's rounding bias dropped (rounds down)", CTL,
          "    return (UINT64_C(1) << 62) + (UINT64_C(1) << (k - 1u));",
          "    return (UINT64_C(1) << 62) + ((UINT64_C(1) << (k - 1u)) * 0u);"),
    Fault("F91", "estimator (Q15/Q31): a saturation not reported past the next row", CTL,
          "    return (stsp_scalar_t)out;\n}", "    *clamped = 0u;\n    return (stsp_scalar_t)out;\n}"),
    Fault("F92", "estimator (Q15/Q31): the row bound leaves out the prediction's pass-through",
          CTL, "            const uint64_t pass = UINT64_C(1) << e->shift[ny + nx + i];",
          "            const uint64_t pass = 0u;"),
    Fault("F93", "estimator (Q15/Q31): the CRC leaves out the row shifts", CTL,
          "    crc = stsp_crc32_bytes(crc, est->shift, (uint32_t)est->ny + (2u * nx));\n", ""),
    Fault("F94", "estimator (Q15/Q31): verify does not compare the innovation exponents' address",
          CTL, "(a->e_exp != b->e_exp) || ", ""),
    Fault("F95", "estimator (Q15/Q31): the reading's coefficient without y_exp - e_exp", CTL,
          "    const int32_t up = (int32_t)k + ((int32_t)e->y_exp[i] - (int32_t)e->e_exp[i]);",
          "    const int32_t up = (int32_t)k;"),
    # Runtime parameters (stsp_params.c; tests/c/test_params.c).
    Fault("F79", "params: a NaN theta accepted (the range check written as two rejections)",
          CTL, "        if (!((theta[i] >= p->lower[i]) && (theta[i] <= p->upper[i]))) {",
          "        if ((theta[i] < p->lower[i]) || (theta[i] > p->upper[i])) {"),
    Fault("F80", "params: the latch without the parameters' offsets", CTL,
          "                                                          pc->d, n);",
          "                                                          pc->d, 0u * n);"),
    Fault("F81", "params: the CRC leaves out the feed-forward columns", CTL,
          "    crc = stsp_crc32_scalars(crc, params->S_k0, stsp_param_k0_len(params));",
          "    crc = stsp_crc32_scalars(crc, params->S_k0, 0u * stsp_param_k0_len(params));"),
    Fault("F82", "params: the sensitivity rows not moved on per input (index slip)", CTL,
          "&pc->checked.S_k0[s0 + (i * n)]", "&pc->checked.S_k0[s0]"),
    Fault("F83", "params: the problem hash not compared", CTL,
          "    if (memcmp(pc->checked.problem_sha256, table->problem_sha256, 32u) != 0) {",
          "    if (memcmp(pc->checked.problem_sha256, table->problem_sha256, 0u) != 0) {"),
    # Runtime parameters in fixed point (stsp_params.c; tests/c/test_params.c in Q15/Q31).
    Fault("F84", "params (Q15/Q31): a negative d_q floored, not rounded", CTL,
          "    const double r = y + 0.5;", "    const double r = (y < 0.0) ? y : y + 0.5;"),
    Fault("F85", "params (Q15/Q31): the row bound leaves out the feed-forward columns", CTL,
          " +\n                          stsp_q_abs_sum(&p->S_k0[r * n], n);", ";"),
    Fault("F86", "params (Q15/Q31): the range's ends not checked against the Q range", CTL,
          "            (stsp_param_dq(p, i, p->lower[i], &q) == 0) ||\n"
          "            (stsp_param_dq(p, i, p->upper[i], &q) == 0)) {",
          "            (stsp_param_dq(p, i, p->nominal[i], &q) == 0)) {"),
    # Spline columns (stsp_params.h format 2; stsp_spline.c's param_law, tests/c/
    # test_params_spline.c and its reference hashes).
    Fault("F87", "params (spline): the columns' coefficients from the stage's first span", CTL,
          "(((i * n_params) + q) * p->stride) + p->span)]", "(((i * n_params) + q) * p->stride))]"),
    Fault("F88", "params (spline): the CRC of format 2 leaves out n_spline_coef", CTL,
          "        crc = stsp_crc32_u32(crc, params->n_spline_coef);\n", ""),
    Fault("F89", "params (spline): every input's gains of x from the stage's first entry", CTL,
          "for (e = (i > 0u) ? p->row_end[i - 1u] : 0u; e < p->k_end[i]; ++e) {",
          "for (e = 0u; e < p->k_end[i]; ++e) {"),
    # Spline columns in fixed point (format 2 in Q15/Q31; stsp_spline.c's
    # stsp_qspline_param_law, stsp_qspline.c's stsp_qspline_cols_check, tests/c/
    # test_params_spline.c and its reference hashes).
    Fault("F97", "params (Q spline): the columns' coefficients from the stage's first span", CTL,
          "stsp_qspline_narrow(&block[1u + sigma], p, (3u * k) + sh)",
          "stsp_qspline_narrow(&block[1u], p, (3u * k) + sh)"),
    Fault("F98", "params (Q spline): the row bound at init leaves out the columns", CTL,
          "(3u * k) + stsp_qspline_col_shift(block));\n"
          "                    sum += (uint64_t)((g < 0) ? -g : g);",
          "(3u * k) + stsp_qspline_col_shift(block));\n"
          "                    sum += 0u * (uint64_t)((g < 0) ? -g : g);"),
    Fault("F99", "params (Q spline): the law's accumulator without the columns' terms", CTL,
          "        acc0[i] = acc;\n", "        acc0[i] = stsp_q_start();\n"),
    # The parametric spline tick's span cache (stsp_spline.c, stsp_params.c;
    # tests/c/test_params_spline.c, test_span_cache_any_order).
    Fault("F100", "params (spline): the span cache kept across a parameter change", CTL,
          "    pc->ctrl.span.next = 0u;\n", "    (void)pc;\n"),
    Fault("F101", "params (spline): a span record after the tick taken as its span", CTL,
          "(p->first == first) && (p->knot[2] <= tau))", "(p->first == first) && (tau >= 0.0f))"),
]


def tree_hash(paths: list[str]) -> str:
    h = hashlib.sha256()
    for top in paths:
        for p in sorted((ROOT / top).rglob("*")):
            if p.is_file():
                h.update(str(p.relative_to(ROOT)).encode())
                h.update(p.read_bytes())
    return h.hexdigest()


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


class Sandbox:
    """A copy of the C sources with its own CMake build and cffi build cache."""

    def __init__(self, base: Path):
        self.src = base / "src"
        self.build = base / "build"
        self.cffi = base / "cffi"
        self.src.mkdir()
        shutil.copy2(ROOT / "CMakeLists.txt", self.src)
        shutil.copy2(ROOT / "VERSION", self.src)   # the project's version (CMakeLists.txt)
        # Everything the top-level CMakeLists.txt reads (the host benchmark is a target too).
        for d in ("firmware", "tests/c", "tests/consumer", "gains", "cmake", "tools/bench",
                  "host/stospline/board/files"):
            shutil.copytree(ROOT / d, self.src / d)
        self.pristine = {}

    def configure(self) -> None:
        r = run(["cmake", "-S", str(self.src), "-B", str(self.build), "-G", "Ninja",
                 "-DCMAKE_BUILD_TYPE=Release"])
        if r.returncode:
            raise SystemExit(f"plant_faults: configure failed\n{r.stdout}\n{r.stderr}")

    def locate(self, fault: Fault) -> str:
        """The file the fault edits: `fault.path`, or under a directory the one holding `old`."""
        where = self.src / fault.path
        if where.is_file():
            return fault.path
        holders = [p for p in sorted(where.glob("*.[ch]")) if fault.old in p.read_text()]
        if len(holders) != 1:
            raise SystemExit(f"plant_faults: {fault.key}: the text to replace is in "
                             f"{len(holders)} files under {fault.path} (expected one)")
        return str(holders[0].relative_to(self.src))

    def apply(self, fault: Fault) -> None:
        rel = self.locate(fault)
        path = self.src / rel
        text = self.pristine.setdefault(rel, path.read_text())
        if text.count(fault.old) != 1:
            raise SystemExit(f"plant_faults: {fault.key}: the text to replace occurs "
                             f"{text.count(fault.old)} times in {rel} (expected once)")
        path.write_text(text.replace(fault.old, fault.new))

    def restore(self) -> None:
        for rel, text in self.pristine.items():
            (self.src / rel).write_text(text)

    def ctest(self) -> tuple[str, list[str]]:
        """('ok' | 'build failed' | 'failed', [summary of the failures])."""
        r = run(["cmake", "--build", str(self.build)])
        if r.returncode:
            return "build failed", ["(build: " + first_error(r.stdout + r.stderr) + ")"]
        r = run(["ctest", "--test-dir", str(self.build), "-E", CTEST_EXCLUDE,
                 "--output-on-failure", "--timeout", "120"])
        if r.returncode == 0:
            return "ok", []
        failed = re.findall(r"^\s*\d+ - (\S+) \(", r.stdout, re.M)
        total = re.search(r"tests failed out of (\d+)", r.stdout)
        cases = sorted(set(re.findall(r"\[  FAILED  \] (test_\w+)", r.stdout)))
        if "runtime error" in r.stdout or "AddressSanitizer" in r.stdout:
            cases.append("(sanitizer report)")
        summary = [f"{len(failed)}/{total.group(1) if total else '?'} ctest tests "
                   f"({', '.join(failed)})", "cases: " + (", ".join(cases) or "-")]
        return "failed", summary

    def pytest(self, fail_fast: bool) -> tuple[str, list[str]]:
        env = dict(os.environ, STOSPLINE_FIRMWARE=str(self.src / "firmware"),
                   STOSPLINE_BUILD=str(self.cffi), PYTHONDONTWRITEBYTECODE="1")
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf",
               *(["-x"] if fail_fast else []), *PY_TESTS]
        r = run(cmd, cwd=ROOT, env=env)
        failed = re.findall(r"^FAILED (.+?)(?: - .*)?$", r.stdout, re.M)
        errors = re.findall(r"^ERROR (.+?)(?: - .*)?$", r.stdout, re.M)
        if r.returncode == 0:
            return "ok", []
        return "failed", [f.replace("tests/python/", "") for f in failed + errors] or \
            [f"(pytest exit {r.returncode})"]


def first_error(text: str) -> str:
    m = re.search(r"error: (.*)", text)
    return m.group(1)[:80] if m else "see log"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", metavar="KEY", help="faults to plant (default: all)")
    ap.add_argument("--list", action="store_true", help="list the faults and exit")
    ap.add_argument("--no-python", action="store_true", help="C tests only")
    ap.add_argument("--fail-fast", action="store_true",
                    help="stop pytest at the first failure (faster; names fewer tests)")
    args = ap.parse_args()
    faults = [f for f in FAULTS if not args.only or f.key in args.only]
    if args.list:
        for f in FAULTS:
            print(f"{f.key:4s} {f.title}  ({f.path})")
        return 0

    watched = ["firmware", "tests/c"]
    before = tree_hash(watched)
    rows = []
    with tempfile.TemporaryDirectory(prefix="stsp_faults_") as tmp:
        box = Sandbox(Path(tmp))
        box.configure()
        t0 = time.time()
        c_status, c_failed = box.ctest()
        p_status, p_failed = ("skipped", []) if args.no_python else box.pytest(False)
        print(f"baseline (no fault): ctest {c_status}, pytest {p_status} "
              f"({time.time() - t0:.0f} s)", flush=True)
        if c_status != "ok" or p_status not in ("ok", "skipped"):
            print("plant_faults: the unmodified sources fail: " + "; ".join(c_failed + p_failed))
            return 2
        for f in faults:
            t0 = time.time()
            box.apply(f)
            try:
                c_status, c_failed = box.ctest()
                if args.no_python:
                    p_status, p_failed = "skipped", []
                else:
                    p_status, p_failed = box.pytest(args.fail_fast)
            finally:
                box.restore()
            caught = c_status != "ok" or p_status == "failed"
            rows.append((f, caught, c_status, c_failed, p_status, p_failed))
            print(f"{f.key:4s} {'CAUGHT' if caught else 'MISSED'}  {f.title}  "
                  f"({time.time() - t0:.0f} s)", flush=True)
            print(f"       ctest:  {c_status}: {'; '.join(c_failed) or '-'}", flush=True)
            print(f"       pytest: {p_status}: {', '.join(p_failed) or '-'}", flush=True)
    after = tree_hash(watched)
    missed = [f.key for f, caught, *_ in rows if not caught]
    print(f"\n{len(rows) - len(missed)} of {len(rows)} planted faults caught"
          + (f"; MISSED: {', '.join(missed)}" if missed else ""))
    print(f"working tree untouched (firmware/, tests/c/ hashes equal): {before == after}")
    if before != after:
        print("plant_faults: firmware/ or tests/c/ changed during the run (another process?)")
    return 0 if not missed and before == after else 1


if __name__ == "__main__":
    sys.exit(main())
