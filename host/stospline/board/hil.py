"""Serial hardware-in-the-loop: the host simulates the plant, the board runs the controller.

One frame per tick over a serial line (QEMU's serial on a local socket, or a board's UART):
the host sends the state the controller measures (STATE), the board answers with the command
it applies (COMMAND). The plant is the Monte Carlo harness's (`sim.montecarlo`): the same
integrator in C, the same random numbers for the same seed (block 0 of the seed, paths in the
same order), so a path through the board must equal the host-compiled controller's path bit
for bit; `run_hil` checks that it does, tick by tick.
"""
from __future__ import annotations

import os
import select
import socket
import struct
import subprocess
import time
from dataclasses import dataclass, field

import numpy as np

from stospline.board import frames as fr

__all__ = ["table_of", "HilResult", "run_hil", "open_port", "start_qemu", "QEMU_MACHINES"]

QEMU_MACHINES = {"netduinoplus2": "netduinoplus2"}


def table_of(d, arith: str):
    """The table of arithmetic `arith` the board runs (and the host compares with)."""
    if arith == "float32":
        return d.table
    from stospline.pipeline import fixed_point_spline, fixed_point_table
    if d.table.spline is not None:
        return fixed_point_spline(d, arith)[0]
    return fixed_point_table(d, arith)
