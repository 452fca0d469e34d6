"""The compiled firmware evaluates exactly the table's law; Python and C agree on the CRC."""
import numpy as np

from stospline.table.format import table_crc32


def test_crc_python_equals_c(robot, robot_controller):
    assert robot_controller.lib.stsp_table_crc32(robot_controller.c_table) == table_crc32(robot.table)
    assert robot_controller.c_table.crc32 == table_crc32(robot.table)


def test_c_step_equals_reference_law(robot, robot_controller, rng=np.random.default_rng(7)):
    """Random states through the compiled controller vs the law in double precision:
    agreement to float32 accumulation error."""
    t = robot.table
    step = robot_controller.stepper(64)
    X = rng.normal(size=(64, 4)) * 3
    latched, prev = {}, -1
    for j in [0, 1, 1500, 2999, 3000, 3001, 5999]:
        k = t.stage_of_tick(j)
        Xj = X + 0.01 * j
        X32 = Xj.astype(np.float32).astype(float)
        U, status = step(j, Xj)
        if k not in latched:
            latched[k] = X32 @ t.Lambda[k].T.astype(float) + t.lambda0[k].astype(float)
        ref = -(X32 @ t.K[j].T.astype(float) + t.k0[j] + latched[k] @ t.L[j].T.astype(float))
        assert np.all(status == (0 if j == prev + 1 else 1))   # skipping ahead: a warning
        prev = j
        np.testing.assert_allclose(U, ref, rtol=2e-6, atol=2e-5 * np.abs(ref).max())
