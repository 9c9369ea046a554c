"""Motion limits: velocity, acceleration and jerk limits, retiming (:mod:`.limits`) and online
trajectory generation (:mod:`.otg`). The bottom layer, beside :mod:`pbdkit.prob`."""
