"""Every read has one deadline for the whole reply, not one per byte.

pyvisa-py restarts its timeout whenever bytes arrive, so a scope trickling its waveform block a byte
every 0.5 s held labkit for minutes with a 1 s timeout. The lab's ``trickle`` fault sends a reply
that way; labkit must give up within its timeout (plus 1 s of slack for the test's machine).
"""
from __future__ import annotations

import time

import pytest
from labhelpers import instruments_toml, lab  # noqa: F401  (fixture)

from clihelpers import run_cli, stepped_inchip_toml
from labkit.drivers.funcgen import Keysight33500B
from labkit.drivers.scope import InfiniiVision
from labkit.errors import InstrumentError
from labkit.lab import VirtualLab


@pytest.mark.parametrize("match, call", [
    ("*IDN?", lambda sc: sc.query("*IDN?")),                         # a line
    ("DATA?", lambda sc: sc.read_waveform(1, "WORD")),               # a block
])
def test_a_trickled_reply_times_out_within_the_timeout(lab, match, call):
    with InfiniiVision.open(lab.resources["scope"], timeout_s=1.0, points=1000) as sc:
        sc.setup_channel(1, 0.5)
        sc.single()
        sc.wait_done(5)
        lab.inject_fault("scope", "trickle", match=match, interval_s=0.3)
        t0 = time.monotonic()
        with pytest.raises(InstrumentError, match="no reply within 1 s"):
            call(sc)
        took = time.monotonic() - t0
    assert 0.9 < took < 1.5, took


def test_an_endless_error_queue_is_one_short_line(lab):
    """A generator whose queue never empties (every read answers an error): one line, repeats
    counted, the read limit said; not 32 entries of text."""
    with Keysight33500B.open(lab.resources["funcgen"], timeout_s=2) as fg:
        lab.funcgen.next_error = lambda: '-113,"Undefined header"'      # the queue never empties
        with pytest.raises(InstrumentError) as exc:
            fg.set_frequency(1000.0)
    text = str(exc.value)
    assert "\n" not in text and len(text) < 400, text
    assert '-113,"Undefined header" x32' in text and "queue not empty after 32 reads" in text


def test_a_run_whose_scope_trickles_gives_up_within_its_timeout_exit_3_drive_off(tmp_path):
    with VirtualLab(seed=6) as lab:
        res = lab.resources
        instruments = instruments_toml(res, scope_timeout_s=1.5)
        cfg = tmp_path / "inchip.toml"
        cfg.write_text(stepped_inchip_toml(instruments, [800.0, 3400.0]))
        lab.inject_fault("scope", "trickle", match="DATA?", interval_s=0.5)
        proc = run_cli("sweep", "inchip", str(cfg), "--out", str(tmp_path / "run.h5"), check=None, timeout=120)
        assert proc.returncode == 3, proc.stderr
        assert "no reply within 1.5 s" in proc.stderr and "Traceback" not in proc.stderr
        started = next(t for t, inst, d, text in lab.log if d == "fault" and text.startswith("trickle"))
        offs = [t for t, inst, ch, on in lab.output_timeline if inst == "funcgen" and ch == 1 and not on]
        assert lab.output_state("funcgen", 1) is False
        assert offs[-1] - started < 1.5 + 1.0, (started, offs)


def test_a_trickled_serial_reply_times_out_within_the_timeout(lab):
    """The vibrometer controller on the lab's pseudo-terminal sends its reply a byte every 0.7 s
    (pyserial's read_until would wait 1 s per byte and return the whole line after 1.4 s): labkit's
    serial read gives up at its 1 s timeout."""
    from labkit.drivers.vibrometer import OFV5000

    with OFV5000.open(lab.resources["vibrometer"], timeout_s=1.0) as vib:
        assert vib.over_range() is False
        lab.inject_fault("vibrometer", "trickle", match="OverRange", interval_s=0.7)
        t0 = time.monotonic()
        with pytest.raises(InstrumentError, match="timeout after 1 s"):
            vib.over_range()
        took = time.monotonic() - t0
    assert 0.9 < took < 1.3, took


def test_a_run_whose_vibrometer_trickles_gives_up_within_its_timeout_exit_3_drive_off(tmp_path):
    """The same on the serial link in a run: the over-range query after the first acquisition
    trickles; the run ends within the vibrometer's timeout (+1 s) with exit 3, one line, drive off."""
    with VirtualLab(seed=9) as lab:
        instruments = instruments_toml(lab.resources).replace(
            'model = "OFV-5000"\n', 'model = "OFV-5000"\ntimeout_s = 1.5\n')
        cfg = tmp_path / "inchip.toml"
        cfg.write_text(stepped_inchip_toml(instruments, [800.0, 3400.0]))
        lab.inject_fault("vibrometer", "trickle", match="OverRange", interval_s=1.0)   # "0\n": 2 s
        proc = run_cli("sweep", "inchip", str(cfg), "--out", str(tmp_path / "run.h5"), check=None, timeout=120)
        assert proc.returncode == 3, proc.stderr
        assert "vibrometer" in proc.stderr and "timeout" in proc.stderr and "Traceback" not in proc.stderr
        started = next(t for t, inst, d, text in lab.log if d == "fault" and text.startswith("trickle"))
        offs = [t for t, inst, ch, on in lab.output_timeline if inst == "funcgen" and ch == 1 and not on]
        assert lab.output_state("funcgen", 1) is False
        assert 0 < offs[-1] - started < 1.5 + 1.0, (started, offs)
