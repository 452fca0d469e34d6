"""Running a table: the firmware compiled for the host and driven through cffi (`controller`,
with the plant in ``plant.c`` and the normal generator in ``normals.c``), Monte Carlo over it
(`montecarlo`, with the plant's substeps chosen in `plant_scheme`), the fault sweep
(`fault_sweep`), corridor-exit statistics (`exit_stats`) and the closed loop of a fixed-point
controller against the double-precision law (`fixed_point_error`)."""
