"""Running a table: the compiled C controller through cffi (`controller`, plant in `plant.c`),
Monte Carlo (`montecarlo`) and the exact moment oracle of the law as implemented (`oracle`)."""
