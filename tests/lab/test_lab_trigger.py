"""What a triggered acquisition depends on, as a bench has it: the generator's Sync connector into the
scope's EXT input, and the scope's sweep mode.

* Keysight 33500B Series Operating and Service Guide, OUTPut:SYNC, OUTPut:SYNC:SOURce,
  OUTPut[1|2]:SYNC:POLarity: the connector is off, or follows one channel; its pulse rises at phase
  zero of each cycle (inverted: half a cycle later).
* InfiniiVision 3000T Programmer's Guide, :TRIGger:SWEep {AUTO|NORMal}: AUTO acquires even when no
  trigger comes; NORMal waits for one.
"""
from __future__ import annotations

import time

import h5py
import numpy as np
import pytest
from labhelpers import drive_sine, fit_sine, instruments_toml, lab, raw, read_word, settle  # noqa: F401  (fixtures)

from clihelpers import stepped_inchip_toml
from labkit.lab import VirtualLab
from labkit.lab.scpi import ScpiError


def _arm_and_wait(sc, wait_s: float) -> bool:
    """:SINGle, then whether the record completed within ``wait_s`` (operation register bit 3 clear)."""
    sc.write(":SING")
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        if not int(sc.query(":OPER:COND?")) & 8:
            return True
        time.sleep(0.01)
    return False


def _ext_scope(sc, sweep: str) -> None:
    sc.write(":CHAN1:DISP 1;:CHAN1:SCAL 0.5;:TIM:RANG 5e-3;:TRIG:EDGE:SOUR EXT;:TRIG:EDGE:LEV 1")
    sc.write(f":TRIG:SWE {sweep}")
    assert sc.query(":SYST:ERR?") == '+0,"No error"'


def test_no_sync_no_trigger_in_normal_and_untriggered_records_in_auto(lab, raw):
    fg, sc = raw("funcgen"), raw("scope")
    drive_sine(fg, 1000.0, 2.0)
    fg.write("OUTP:SYNC OFF")
    settle(lab)
    _ext_scope(sc, "NORM")
    assert not _arm_and_wait(sc, 0.4)          # NORMal: waits for a trigger that never comes
    _ext_scope(sc, "AUTO")
    phases = []
    for _ in range(4):                          # AUTO: records anyway, at whatever phase
        assert _arm_and_wait(sc, 2.0)
        t, v = read_word(sc, 1)
        phases.append(np.angle(fit_sine(t, v, 1000.0)))
    assert np.ptp(np.unwrap(phases)) > 0.3      # untriggered: the phase wanders record to record


@pytest.mark.parametrize("setting, phase_deg", [
    ("OUTP:SYNC ON", 0.0),                                   # phase zero at the trigger
    ("OUTP:SYNC ON;:OUTP1:SYNC:POL INV", 180.0),             # inverted pulse: rises half a cycle later
    ("OUTP:SYNC ON;:OUTP:SYNC:SOUR CH2", None),              # follows channel 2 (off): no trigger
    ("OUTP:SYNC ON;:OUTP1:SYNC:MODE MARK", None),            # marker mode: not the cycle's phase zero
])
def test_sync_settings_decide_the_trigger(lab, raw, setting, phase_deg):
    fg, sc = raw("funcgen"), raw("scope")
    drive_sine(fg, 1000.0, 2.0)
    fg.write(setting)
    assert fg.query("SYST:ERR?") == '+0,"No error"'
    settle(lab)
    _ext_scope(sc, "NORM")
    done = _arm_and_wait(sc, 0.5)
    if phase_deg is None:
        assert not done
        return
    assert done
    sc.write(":TIM:REF LEFT")   # (the record is already taken; only the transfer reads it)
    t, v = read_word(sc, 1)
    # v = A sin(w t + phi) with t = 0 at the trigger: phi is the drive's phase at the sync edge
    c = fit_sine(t, v, 1000.0)
    assert abs(c) == pytest.approx(1.0, rel=0.01)
    assert np.degrees(np.angle(c * np.exp(-1j * np.radians(phase_deg)))) == pytest.approx(0.0, abs=0.5)


def _inchip_config(tmp_path, res, *, timeout_s=5) -> str:
    cfg = tmp_path / "inchip.toml"
    cfg.write_text(stepped_inchip_toml(instruments_toml(res, scope_timeout_s=timeout_s, funcgen_timeout_s=timeout_s),
                                       [800.0, 3400.0]))
    return str(cfg)


def _sabotage(lab, raw) -> None:
    """What an earlier session left on the bench: sync off, inverted, on channel 2; scope in AUTO."""
    fg, sc = raw("funcgen"), raw("scope")
    fg.write("OUTP:SYNC OFF;:OUTP:SYNC:SOUR CH2;:OUTP1:SYNC:POL INV")
    sc.write(":TRIG:SWE AUTO")
    assert fg.query("OUTP:SYNC?") == "0" and sc.query(":TRIG:SWE?") == "AUTO"


def test_a_run_on_a_bench_left_in_auto_with_sync_off_sets_both_and_is_triggered(lab, raw, tmp_path):
    """labkit's run configures sync and NORMal sweep itself (and reads them back): every point's
    velocity phase relative to the drive is the lab's true FRF phase."""
    from labkit.experiments.session import run_session

    _sabotage(lab, raw)
    out = tmp_path / "run.h5"
    summary = run_session("inchip", _inchip_config(tmp_path, lab.resources), out, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == 2, summary
    rx = [text for _, inst, d, text in lab.log if d == "rx"]
    assert "OUTP:SYNC ON" in rx and ":TRIG:SWE NORM" in rx
    assert lab.funcgen.sync_channel() == 1 and lab.scope.get("trig_sweep") == "NORM"
    with h5py.File(out, "r") as f:
        freqs = f["locations/knee/freq_hz"][...]
        frf = f["locations/knee/frf"][...]
    truth = np.array([complex(lab.frf("knee", float(fr))) for fr in freqs])
    assert np.abs(np.angle(frf / truth)).max() < 0.02
    assert np.abs(np.abs(frf) / np.abs(truth) - 1).max() < 0.02


def test_a_generator_whose_sync_will_not_turn_on_fails_the_run_clearly(tmp_path):
    """The Sync connector is broken (it ignores OUTPut:SYNC ON): the run stops before any point with
    one line naming the query and its reply, exit 3, the drive off; nothing untriggered is recorded."""
    from clihelpers import run_cli

    with VirtualLab(seed=4) as lab:
        cmd = next(c for c in lab.funcgen.commands if c.pattern == "OUTPut#:SYNC[:STATe]")

        def broken(c):
            if not lab.funcgen.sync[1]:
                return None
            raise ScpiError(-300)

        lab.funcgen.sync[1] = False
        cmd.set = broken
        out = tmp_path / "run.h5"
        proc = run_cli("sweep", "inchip", _inchip_config(tmp_path, lab.resources), "--out", str(out), timeout=120,
                       check=None)
        assert proc.returncode == 3, proc.stderr
        err = proc.stderr.strip().splitlines()
        assert any("sync not set" in line and "OUTP:SYNC?" in line for line in err), proc.stderr
        assert "Traceback" not in proc.stderr
        assert lab.output_state("funcgen", 1) is False
        assert not any(inst == "scope" and text.startswith(":WAV:DATA") for _, inst, d, text in lab.log)


def test_the_decoder_delay_is_read_recorded_and_taken_out_of_every_phase(lab, tmp_path):
    """The lab's decoder output lags the velocity by 7.6 us (9.3 degrees at 3.4 kHz). The run reads the
    delay, records it with the decoder's range, filter and tracking, and corrects every point: its
    phases match the structure's own FRF within 0.02 rad; undoing the correction misses by 2 pi f tau."""
    import json

    from labkit.experiments.session import run_session

    out = tmp_path / "run.h5"
    summary = run_session("inchip", _inchip_config(tmp_path, lab.resources), out, quiet=True)
    assert summary["status"] == "complete", summary
    with h5py.File(out, "r") as f:
        freqs = f["locations/knee/freq_hz"][...]
        frf = f["locations/knee/frf"][...]
        vib = json.loads(f["instruments/vibrometer"].attrs["snapshot_json"])
    st = vib["state"]
    assert st["signal_delay_s"] == pytest.approx(7.6e-6)
    assert (st["scale_mm_s_per_v"], st["filter"], st["tracking"]) == (25.0, "Off", "Off")
    truth = np.array([complex(lab.frf("knee", float(fr))) for fr in freqs])
    assert np.abs(np.angle(frf / truth)).max() < 0.02
    lag = 2 * np.pi * freqs * 7.6e-6
    assert np.angle(frf * np.exp(-1j * lag) / truth) == pytest.approx(-lag, abs=0.02)
    assert lag.max() > 0.16                      # 9.3 degrees at 3.4 kHz: far above the tolerance


def test_averaging_takes_one_triggered_record_per_average_and_lowers_the_noise(lab, raw):
    """IV :ACQuire:TYPE AVERage, :ACQuire:COUNt: the record is the mean of COUNt triggered records;
    the drive (synced) stays, uncorrelated noise (channel 4: nothing but the input's noise) falls by
    sqrt(COUNt)."""
    fg, sc = raw("funcgen"), raw("scope")
    drive_sine(fg, 1000.0, 2.0)
    settle(lab)
    sc.write(":CHAN1:DISP 1;:CHAN4:DISP 1;:CHAN4:SCAL 0.001;:TIM:RANG 2e-3;:TRIG:EDGE:SOUR EXT;:TRIG:SWE NORM")
    stds = {}
    for count in (1, 16):
        sc.write(":ACQ:TYPE NORM" if count == 1 else f":ACQ:TYPE AVER;:ACQ:COUN {count}")
        assert _arm_and_wait(sc, 5.0)
        _, noise = read_word(sc, 4)
        t, v = read_word(sc, 1)
        stds[count] = float(np.std(noise))
        assert abs(fit_sine(t, v, 1000.0)) == pytest.approx(1.0, rel=0.01)
    assert stds[1] / stds[16] == pytest.approx(4.0, rel=0.25)
    assert sc.query(":WAV:PRE?").split(",")[3] == "+16"


def _ext_refused(lab: VirtualLab, tmp_path, scope_model: str):
    """An in-chip config on the lab's DS1104Z (named ``scope_model`` in the config) asking for EXT:
    the run exits 2 with one line naming scope.trigger_source. Returns the config's path and text."""
    from clihelpers import run_cli

    instruments = instruments_toml(lab.resources, scope_model=scope_model).replace('"33500B"', '"DG1000Z"')
    text = stepped_inchip_toml(instruments, [800.0]).replace(
        "velocity_channel = 2\n", 'velocity_channel = 2\ntrigger_source = "EXT"\n')
    cfg = tmp_path / "inchip.toml"
    cfg.write_text(text)
    proc = run_cli("sweep", "inchip", str(cfg), "--out", str(tmp_path / "run.h5"), check=2, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "scope.trigger_source" in lines[0] and "DS1104Z has no external trigger" in lines[0]
    return cfg, text


def test_ext_on_a_config_naming_a_four_channel_ds1000z_sends_nothing(tmp_path):
    """A config whose scope model is the DS1104Z itself and asks for EXT: exit 2 at the config's check,
    one line naming scope.trigger_source, and not one byte reached any instrument."""

    with VirtualLab(seed=16, funcgen_model="DG1062Z", scope_model="DS1104Z") as lab:
        _ext_refused(lab, tmp_path, "DS1104Z")
        assert not [x for x in lab.log if x[2] == "rx"], lab.log[:5]
        assert not (tmp_path / "run.h5").exists()


def test_ext_on_a_four_channel_ds1000z_is_refused_before_any_scope_setting(tmp_path):
    """The DS1104Z has no EXT input (DS :TRIGger:EDGe:SOURce: CHANnel1-4, AC): a config asking for EXT
    ends with one line naming scope.trigger_source, exit 2 (a run and labkit check alike); the scope
    was asked its identity (and its error queue) only, and the generator's output never went on."""
    from clihelpers import run_cli

    with VirtualLab(seed=15, funcgen_model="DG1062Z", scope_model="DS1104Z") as lab:
        cfg, text = _ext_refused(lab, tmp_path, "DS1000Z")
        sent = [text for _, inst, d, text in lab.log if inst == "scope" and d == "rx"]
        assert sent and all(t in ("*IDN?", ":SYST:ERR?", "*CLS") for t in sent), sent
        assert not any(on for _, inst, _, on in lab.output_timeline if inst == "funcgen")
        # labkit check says the same; without the line it triggers on the drive (channel 1) and passes
        proc = run_cli("check", str(cfg), check=2, timeout=120)
        assert "scope.trigger_source" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
        cfg.write_text(text.replace('trigger_source = "EXT"\n', ""))
        proc = run_cli("check", str(cfg), check=0, timeout=120)
        assert "scope trigger CHAN1, sweep NORM (read back)" in proc.stdout
        assert "all checks passed" in proc.stdout
