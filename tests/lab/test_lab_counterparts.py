"""Every driver in ``labkit.drivers`` against its simulated counterpart, over the real transports.

For each generator / scope / vibrometer model the lab can simulate, the
driver of that family (picked by :attr:`VirtualLab.models`, as a config
would name it) shakes hands (identity -> model and channel count), drives a
sine, digitises it, reads the velocity range, switches off, and leaves no
error in any queue. The measured drive is checked against the programmed
sine by a least-squares fit.
"""
from __future__ import annotations

import numpy as np
import pytest
from labhelpers import fit_sine

from labkit.drivers.registry import open_instrument
from labkit.lab import VirtualLab


@pytest.mark.parametrize("funcgen, scope, vibrometer, channels", [
    ("33511B", "DSOX2024A", "OFV-3001", 1),
    ("DG1062Z", "DS1104Z", "OFV-5000", 2),
    ("33220A", "DS1054Z", "OFV-3001", 1),
])
def test_driver_meets_its_simulated_counterpart(funcgen, scope, vibrometer, channels):
    with VirtualLab(seed=3, funcgen_model=funcgen, scope_model=scope, vibrometer_model=vibrometer) as lab:
        models = lab.models
        with open_instrument(models["funcgen"], lab.resources["funcgen"], max_amp_vpp=2, timeout_s=5) as fg, \
                open_instrument(models["scope"], lab.resources["scope"], timeout_s=5) as sc, \
                open_instrument(models["vibrometer"], lab.resources["vibrometer"], timeout_s=2) as vib:
            assert fg.instrument_model == funcgen and fg.channels == tuple(range(1, channels + 1))
            assert sc.instrument_model == scope and sc.n_channels == 4
            assert fg.errors_at_connect == [] and sc.errors_at_connect == []
            fg.set_sine(1000.0, 1.0)
            fg.output(True)
            assert lab.output_state("funcgen", 1)
            sc.setup_channel(1, 0.2)
            sc.set_timebase(4e-3)
            sc.set_trigger("CHAN1", 0.0, "POS")
            sc.single()
            sc.wait_done(10.0)
            wf = sc.read_waveform(1, "BYTE")
            c = fit_sine(wf.t_s, wf.volts, 1000.0)
            # 1 Vpp into the high-impedance PZT: 0.5 V peak (8-bit codes: one code is 8 to 16 mV)
            assert abs(c) == pytest.approx(0.5, abs=0.02)
            assert wf.t_s[-1] - wf.t_s[0] == pytest.approx(4e-3, rel=0.01)
            vib.scale_mm_s_per_v = 125.0
            assert vib.scale_mm_s_per_v == 125.0 and vib.over_range() is False
            fg.safe_off()
            assert not lab.output_state("funcgen", 1)
            assert fg.read_error_queue() == [] and sc.read_error_queue() == []
        assert np.isfinite(lab.drive_idle_after_s(1))
