"""Amplitude units and the declared load, driver against simulated generator: the volts that reach the
high-impedance PZT (the lab's physics) are what the settings say they are.

A generator programs its amplitude for the load it is told (Keysight 33500B Operating and Service
Guide, OUTPut:LOAD: "the displayed amplitude ... assumes the load"); the open-circuit voltage behind
its 50 ohm source is then ``V (R + 50) / R``, and a high-impedance load sees all of it.
"""
from __future__ import annotations

import pytest

from labkit.drivers import registry
from labkit.lab import VirtualLab


@pytest.mark.parametrize("model", ["33522B", "DG1062Z", "33220A"])
@pytest.mark.parametrize("unit, load, pzt_vpp", [
    ("VPP", "INF", 2.0),          # declared high Z: the PZT sees the programmed 2 Vpp
    ("VRMS", "INF", 2.0),         # sent as 0.7071 Vrms: the same sine
    ("VPP", 50, 4.0),             # declared 50 ohm into a high-Z PZT: twice (the factory-default trap)
    ("DBM", 50, 4.0),             # 10 dBm into 50 ohm is 2 Vpp there, 4 Vpp open circuit
    ("VRMS", 600, 2.0 * 650 / 600),
])
def test_the_pzt_sees_what_unit_and_load_say(model, unit, load, pzt_vpp):
    with VirtualLab(seed=5, funcgen_model=model) as lab:
        cls = registry.driver_class(lab.models["funcgen"])
        with cls.open(lab.resources["funcgen"], timeout_s=5, amplitude_unit=unit, load_ohm=load) as fg:
            fg.set_load()
            fg.set_sine(1000.0, 2.0)
            assert fg.read_error_queue() == []
            assert 2 * lab.funcgen.drive(1).amp_v == pytest.approx(pzt_vpp, rel=1e-6)
            fg.set_amplitude(1.0)
            assert 2 * lab.funcgen.drive(1).amp_v == pytest.approx(pzt_vpp / 2, rel=1e-6)
