"""Boards: a firmware project generated from a problem's tables (`project`), the serial frame
protocol (`frames`) and the serial hardware-in-the-loop run (`hil`)."""
