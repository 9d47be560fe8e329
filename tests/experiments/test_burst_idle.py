"""Between the bursts of a bounded run the generator rests at 0 V: a crashed run leaves no DC on the PZT.

A sine burst of whole cycles ends at its start phase and the output holds that level until
the next trigger (Keysight 33220A/33500 guides, ``BURSt:PHASe``: "the voltage level
corresponding to the starting burst phase"); the runner picks the start phase whose level
is 0 V, ``offset + amp/2 * sin(phase) = 0``. Where no phase reaches 0 V (``|offset| > amp/2``)
it says so on standard error. The lab's generator models that level; the kill is a real
SIGKILL of a real ``labkit`` process.
"""
from __future__ import annotations

import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from labcfg import inchip_toml
from test_bench_safety import FREQS, POINT_S, act_mid_run, on_lab, sweep_cfg

from clihelpers import REPO
from labkit.drivers.funcgen import Keysight33500B, RigolDG1000Z
from labkit.drivers.testing import expected_protocol
from labkit.experiments.runner import burst_idle
from labkit.lab import VirtualLab

OK = b'+0,"No error"\n'
RIGOL_OK = b'0,"No error"\n'


def _w(*cmds: str):
    return [(c.encode() + b"\n", None) for c in cmds]


@pytest.mark.parametrize("amp, offset, phase, idle", [
    (4.0, 2.0, -90.0, 0.0),        # the in-chip drive: 0..4 V, idles at its minimum
    (4.0, -2.0, 90.0, 0.0),        # a negative offset: at its maximum
    (2.0, 0.0, 0.0, 0.0),          # no offset: the zero crossing (the generator's default)
    (4.0, 1.0, -30.0, 0.0),        # sin(-30 deg) = -1/2: 1 - 2 * 1/2 = 0
    (2.0, 1.5, -90.0, 0.5),        # |offset| > amp/2: the nearest the sine comes to 0 V
])
def test_the_start_phase_whose_level_is_zero(amp, offset, phase, idle):
    got_phase, got_idle = burst_idle(amp, offset)
    assert got_phase == pytest.approx(phase, abs=1e-9)
    assert got_idle == pytest.approx(idle, abs=1e-12)
    assert offset + amp / 2 * math.sin(math.radians(got_phase)) == pytest.approx(idle, abs=1e-12)


def test_the_start_phase_in_each_dialect():
    """Keysight: degrees set first (``UNIT:ANGL``), -360..360; the DG1000Z: 0..360 degrees."""
    sine = _w("OUTP1:LOAD INF", "SOUR1:FUNC SIN", "SOUR1:VOLT:UNIT VPP", "SOUR1:FREQ 1000", "SOUR1:VOLT 4",
              "SOUR1:VOLT:OFFS 2") + [(b"SYST:ERR?\n", OK)]
    burst = _w("SOUR1:BURS:MODE TRIG", "SOUR1:BURS:NCYC 7", "UNIT:ANGL DEG", "SOUR1:BURS:PHAS -90",
               "TRIG1:SOUR BUS", "SOUR1:BURS:STAT ON") + [(b"SYST:ERR?\n", OK)]
    with expected_protocol(Keysight33500B, sine + burst) as fg:
        fg.set_sine(1000, 4, 2)
        fg.burst(7, start_phase_deg=-90)
    rigol = [(c.replace(b"SOUR1", b":SOUR1").replace(b"OUTP1", b":OUTP1").replace(b"SYST", b":SYST"),
              RIGOL_OK if r == OK else r) for c, r in sine]
    rigol += _w(":SOUR1:BURS:MODE TRIG", ":SOUR1:BURS:NCYC 7", ":SOUR1:BURS:PHAS 270", ":SOUR1:BURS:TRIG:SOUR MAN",
                ":SOUR1:BURS ON") + [(b":SYST:ERR?\n", RIGOL_OK)]
    with expected_protocol(RigolDG1000Z, rigol) as fg:
        fg.set_sine(1000, 4, 2)
        fg.burst(7, start_phase_deg=-90)


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=7) as lab:
        yield lab


@pytest.mark.slow
def test_sigkill_mid_run_leaves_zero_volts_on_the_pzt(tmp_path, lab):
    """The in-chip drive (4 Vpp around 2 V): SIGKILL mid-run, nobody turns the output off; once
    the burst has ended by itself the generator's output is on and at 0 V (it was 2 V)."""
    cfg, out = sweep_cfg(tmp_path, lab), tmp_path / "run.h5"

    def kill_it(proc):
        proc.send_signal(signal.SIGKILL)
        return lab.now_s()

    proc, _, stderr, t_kill = act_mid_run(cfg, out, 3, kill_it)
    assert proc.returncode == -signal.SIGKILL
    assert "DC on the PZT" not in stderr           # nothing to warn about: the idle level is 0 V
    idle = lab.drive_idle_after_s(1)
    assert idle - t_kill <= POINT_S + 1.0
    time.sleep(max(0.0, idle - lab.now_s()) + 0.02)
    assert lab.output_state("funcgen", 1) is True    # still on: only the level is safe
    volts = []
    for _ in range(20):                               # over ~0.2 s of idling
        volts.append(lab.output_volts(1))
        time.sleep(0.01)
    assert np.max(np.abs(volts)) < 1e-9, volts
    done = subprocess.run([sys.executable, "-m", "labkit", "off", str(cfg)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


@pytest.mark.slow
def test_an_offset_no_phase_can_cancel_is_said_loudly(tmp_path, lab):
    """1 V offset under 1 Vpp: the sine never reaches 0 V, so 0.5 V DC stays between bursts and
    after a crash; the run says so on standard error even with --quiet, and the lab shows it."""
    cfg = on_lab(inchip_toml(tmp_path / "c.toml", FREQS[:2], locations=("hip",), settle_s=0.03,
                             dwell_cycles=20, amp_vpp=1.0, offset_v=1.0), lab)
    done = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out",
                           str(tmp_path / "r.h5"), "--quiet"], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "holds 0.5 V DC on the PZT" in done.stderr and "labkit off" in done.stderr
    # what the last burst left before the run's OFF: the level of its start phase
    with lab.funcgen.lock:
        d = lab.funcgen.drive(1)
    assert d.burst and not d.on
    assert np.degrees(d.burst_phase_rad) == pytest.approx(-90.0)
    assert d.offset_v + d.amp_v * np.sin(d.burst_phase_rad) == pytest.approx(0.5)
