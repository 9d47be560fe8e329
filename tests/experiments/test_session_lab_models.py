"""``--lab`` with a lab serving other models: the session opens the drivers of the lab's models.

A config written for the default bench (33500B, InfiniiVision, OFV-5000) run against a virtual
lab that simulates a Rigol DG1062Z, a DS1104Z and an OFV-3001 must talk to them with the Rigol
and OFV-3001 drivers (the models the lab names), not the config's: otherwise every command of
the wrong dialect is refused by the simulated instrument.
"""
from __future__ import annotations

import h5py
import numpy as np

from clihelpers import stepped_inchip_toml
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab

INSTRUMENTS = """[instruments.funcgen]
model = "33500B"
resource = "TCPIP0::192.0.2.1::5025::SOCKET"
channel = 1
timeout_s = 10

[instruments.scope]
model = "InfiniiVision"
resource = "TCPIP0::192.0.2.2::5025::SOCKET"
timeout_s = 10

[instruments.vibrometer]
model = "OFV-5000"
resource = "ASRL/dev/ttyUSB0::INSTR"
timeout_s = 10
"""


def test_lab_run_uses_the_drivers_of_the_labs_models(tmp_path):
    cfg = tmp_path / "inchip.toml"
    cfg.write_text(stepped_inchip_toml(INSTRUMENTS, [800.0, 3400.0]))
    out = tmp_path / "run.h5"
    with VirtualLab(seed=4, funcgen_model="DG1062Z", scope_model="DS1104Z", vibrometer_model="OFV-3001",
                    scope_memory_points=200_000) as lab:
        assert lab.models == {"funcgen": "DG1000Z", "scope": "DS1000Z", "vibrometer": "OFV-3001"}
        summary = run_session("inchip", cfg, out, lab=lab, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == 2, summary
    with h5py.File(out, "r") as f:
        drive_vpp = 2 * np.abs(f["locations/knee/drive_v"][...])
        text = " ".join(str(v) for v in f.attrs.values())
    np.testing.assert_allclose(drive_vpp, 4.0, rtol=0.01)
    assert "DG1062Z" in text or "DG1000Z" in text, "the run file does not name the Rigol generator"
