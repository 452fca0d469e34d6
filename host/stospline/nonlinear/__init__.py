"""Nonlinear plants (``[plant]``): design on the linearisation along the mean path
(`stospline.nonlinear.iterate`)."""
