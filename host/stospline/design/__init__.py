"""Designers: from a `stospline.problem.Problem` to a law ``u = -K(t) x - k0(t) - L(t) v`` with
latched multipliers ``v``: the latch set-up (`latch`), the continuous-time design
(`continuous`), the exact zero-order-hold design at the tick rate (`zoh`, with its C kernel
in `kernels`), band constraints (`bands`) and the moment equations they share (`moments`).
Every design hands its per-tick gains to `stospline.table` through ``tick_gains``; nothing
here builds a table."""
