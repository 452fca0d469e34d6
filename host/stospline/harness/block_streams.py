"""The random numbers of a loop that steps all its paths at once, laid out as the linear
harness (`stospline.harness.montecarlo`) draws them: the paths in blocks of `BLOCK_PATHS`,
block b's plant normals from the C generator on `block_seed` (``seed``, b) and its fault
numbers from that stream's fault child (`fault_seed`), each tick in the harness's order. Path p
of a run therefore sees the numbers the harness gives path p of a run with the same seed.

Beside them, the numbers that split each plant increment into two halves on the same
Brownian path (a Brownian bridge) come from another child of each block's stream
(`BRIDGE_STREAM`), so the coarse run's numbers are the harness's whether or not the fine run
is there.
"""
from __future__ import annotations

import math

import numpy as np

from stospline.harness.montecarlo import block_counts, block_seed, child_stream, fault_seed

__all__ = ["BlockStreams", "BRIDGE_STREAM"]

# The bridge's child of each block's stream (the faults take 2**32 - 2, the substep pilot's
# stream is child 2**32 - 1 of the seed).
BRIDGE_STREAM = 2**32 - 3


class BlockStreams:
    """Per tick: standard normal numbers `z` (paths, substeps, mz) of the coarse run,
    `z_fine` (paths, 2 substeps, mz) of the run at half steps, ``(z_fine[2s] + z_fine[2s+1])
    / sqrt 2 = z[s]``, and with `faults` the fault draws of every block (`FaultDraws`)."""

    def __init__(self, controller, seed, paths: int, substeps: int, mz: int, *,
                 faults: bool = False):
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        spans = [(start, start + count) for _, start, count in block_counts(paths)]
        streams = [block_seed(ss, b) for b in range(len(spans))]
        self.rows = [slice(a, b) for a, b in spans]
        self.z = np.empty((paths, substeps, mz))
        self.z_fine = np.empty((paths, 2 * substeps, mz))
        self._bridge = np.empty_like(self.z)
        self._fills = [controller.normals(s)(self.z[r]) for s, r in zip(streams, self.rows)]
        self._fills += [controller.normals(child_stream(s, BRIDGE_STREAM))(self._bridge[r])
                        for s, r in zip(streams, self.rows)]
        self._fault_rngs = ([np.random.default_rng(fault_seed(s)) for s in streams]
                            if faults else [])

    def draw(self, draws=None) -> None:
        """This tick's numbers: `z`, `z_fine` and, into `draws`, the faults'."""
        for fill in self._fills:
            fill()
        half = math.sqrt(0.5)
        np.multiply(self.z + self._bridge, half, out=self.z_fine[:, 0::2])
        np.multiply(self.z - self._bridge, half, out=self.z_fine[:, 1::2])
        for rng, rows in zip(self._fault_rngs, self.rows):
            draws.draw(rng, rows)
