"""The state estimator of a loop whose sensor is a `problem.measurement.Measurement`: the
linear minimum mean-square error filter's gains, computed offline with the exact moments of
the loop it closes (docs/theory/estimator.md)."""
