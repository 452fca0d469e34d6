"""Design steps that need the oracle: the tick-grid QP's every-tick regions, checked and
tightened against the exact moments of the table as run (`every_tick`), and the certificate
of a spline table against the per-tick law (`spline_certificate`)."""
