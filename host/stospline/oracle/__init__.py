"""The exact moment oracle: first and second moments of the closed loop with a table exactly as
the firmware runs it (`evaluate`: knot moments, cost, the state range of fixed-point scales),
the per-tick maps they propagate through (`tick_moments`), the same with the modelled faults
(`faults`), bounds on leaving a corridor (`exit_bound`), the band dual's latch target
(`band_latch`) and the distance of a path outside time-boxed regions (`region_distance`).
Imports problem, design and table; no compiled controller and no random numbers."""
