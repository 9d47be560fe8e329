"""Published specifications of the lab's instruments, in one place.

The drivers check drives against them (:class:`labkit.drivers.shaker.Shaker4809Envelope`)
and the simulator's paper scenarios model the shaker with them
(:class:`labkit.sim.paper.shaker.ShakerLaw`); neither layer may import the other, so the
numbers live here, below both.
"""
from __future__ import annotations

#: Brüel & Kjær 4809 vibration exciter (product data): frequency range, sine force peak,
#: displacement peak (8 mm peak to peak), velocity peak and the moving element's mass.
BK4809_FREQ_MIN_HZ = 10.0
BK4809_FREQ_MAX_HZ = 20e3
BK4809_FORCE_PEAK_N = 44.5
BK4809_STROKE_PEAK_MM = 4.0
BK4809_VELOCITY_PEAK_M_S = 1.65
BK4809_MOVING_MASS_KG = 0.060
