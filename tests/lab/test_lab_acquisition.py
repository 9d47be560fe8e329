"""The scope's acquisition type and averaging as configured (``[scope] acquisition``, ``averages``):
validated before anything is sent, set and read back on both scope families, recorded in the run
file, and modelled by the lab: averaging N triggered records lowers the uncorrelated noise by
about sqrt(N) (IV :ACQuire:TYPE, :ACQuire:COUNt; DS :ACQuire:TYPE, :ACQuire:AVERages).
"""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from labhelpers import instruments_toml

from clihelpers import run_cli, stepped_inchip_toml
from labkit.errors import ConfigError
from labkit.experiments.config import load_inchip
from labkit.lab import VirtualLab

FREQ_HZ = 800.0


def _config(tmp_path, res, scope_lines: str, *, scope_model: str = "InfiniiVision", name: str = "c.toml",
            keep_raw: bool = True) -> str:
    text = stepped_inchip_toml(instruments_toml(res, scope_model=scope_model), [FREQ_HZ])
    text = text.replace("velocity_channel = 2\n", "velocity_channel = 2\n" + scope_lines)
    if keep_raw:
        text = text.replace("dwell_cycles = 12\n", "dwell_cycles = 12\nkeep_raw = true\n")
    path = tmp_path / name
    path.write_text(text)
    return str(path)


FAKE = {"funcgen": "TCPIP0::127.0.0.1::1::SOCKET", "scope": "TCPIP0::127.0.0.1::2::SOCKET",
        "vibrometer": "ASRL/dev/null::INSTR", "control": "TCPIP0::127.0.0.1::3::SOCKET"}


@pytest.mark.parametrize("lines, model, match", [
    ('acquisition = "average"\n', "InfiniiVision", r"averages.*1 with acquisition = 'average'"),
    ("averages = 4\n", "InfiniiVision", r"averages.*4 with acquisition = 'normal'"),
    ('acquisition = "average"\naverages = 12\n', "DS1000Z", r"power of two 2\.\.1024 \(DS1000Z\)"),
    ('acquisition = "average"\naverages = 2048\n', "DS1000Z", r"averages.*out of range"),
    ('acquisition = "average"\naverages = 70000\n', "InfiniiVision", r"averages.*out of range"),
    ('acquisition = "peak"\n', "InfiniiVision", r"acquisition.*'normal', 'average'"),
])
def test_bad_acquisition_settings_are_config_errors(tmp_path, lines, model, match):
    with pytest.raises(ConfigError, match=match):
        load_inchip(_config(tmp_path, FAKE, lines, scope_model=model))


def test_scope_averaging_with_a_chirp_is_refused(tmp_path):
    path = _config(tmp_path, FAKE, 'acquisition = "average"\naverages = 4\n')
    text = open(path).read().replace('kind = "stepped"\nsettle_s = 0.03\ndwell_cycles = 12\n',
                                     'kind = "chirp"\nlength_s = 0.2\n')
    text = text.replace("list_hz = [800.0]", "start_hz = 500.0\nstop_hz = 900.0\ncount = 50")
    open(path, "w").write(text)
    with pytest.raises(ConfigError, match=r"acquisition.*method.averages"):
        load_inchip(path)


def test_a_bad_averages_line_sends_nothing(tmp_path):
    """Exit 2, one line naming the file and the key, and the lab received nothing."""
    with VirtualLab(seed=11, scope_model="DS1104Z") as lab:
        path = _config(tmp_path, lab.resources, 'acquisition = "average"\naverages = 12\n', scope_model="DS1000Z")
        proc = run_cli("sweep", "inchip", path, "--out", str(tmp_path / "r.h5"), check=2, timeout=120)
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "c.toml" in lines[0] and "averages" in lines[0], lines
        assert not [e for e in lab.log if e[1] in ("funcgen", "scope") and e[2] == "rx"]


def _noise(rec: np.ndarray, t: np.ndarray) -> float:
    """The record's residual after a least-squares fit of the drive frequency and two harmonics."""
    cols = [np.ones_like(t)]
    for k in (1, 2, 3):
        w = 2 * np.pi * k * FREQ_HZ
        cols += [np.sin(w * t), np.cos(w * t)]
    m = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(m, rec, rcond=None)
    return float(np.std(rec - m @ coef))


def _run(tmp_path, lab, name: str, lines: str, scope_model: str = "InfiniiVision") -> dict:
    from labkit.experiments.session import run_session

    out = tmp_path / f"{name}.h5"
    summary = run_session("inchip", _config(tmp_path, lab.resources, lines, scope_model=scope_model,
                                            name=f"{name}.toml"), out, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == 1, summary
    with h5py.File(out, "r") as f:
        drive = f["raw/p00000/drive_v"][...].astype(float)
        t = f["raw/p00000/t_s"][...].astype(float)
        scope = json.loads(f["instruments/scope"].attrs["snapshot_json"])
        frf = complex(f["locations/knee/frf"][0])
        config_text = f.attrs.get("config_text", "")
    return {"noise": _noise(drive, t), "state": scope["state"], "frf": frf, "config": config_text}


@pytest.mark.parametrize("scope_model, driver", [("DSOX3024T", "InfiniiVision"), ("DS1104Z", "DS1000Z")])
def test_averaging_is_set_read_back_and_recorded_on_both_families(tmp_path, scope_model, driver):
    """A run with ``acquisition = "average"``, ``averages = 16``: the scope averages 16 triggered
    records (its settings, read back, in the run file's scope snapshot); the FRF is the lab's; a run
    without the keys sets the scope back to NORMal (a scope left averaging would blend points)."""
    lines = "velocity_volts_per_div = 0.02\n"        # the 8-bit DS1000Z resolves the 0.1 Vpp velocity
    with VirtualLab(seed=12, scope_model=scope_model) as lab:
        lab.set_spot("knee")
        avg = _run(tmp_path, lab, "avg", lines + 'acquisition = "average"\naverages = 16\n', driver)
        assert lab.scope.get("acq_type") == "AVER" and lab.scope.get("acq_count") == 16
        normal = _run(tmp_path, lab, "normal", lines, driver)
        assert lab.scope.get("acq_type") == "NORM"
        truth = complex(lab.frf("knee", FREQ_HZ))
    assert (normal["state"]["acquisition"], normal["state"]["averages"]) == ("NORM", 1)
    assert (avg["state"]["acquisition"], avg["state"]["averages"]) == ("AVER", 16)
    for r in (normal, avg):
        assert abs(r["frf"] / truth) == pytest.approx(1.0, rel=0.03)
        assert abs(np.angle(r["frf"] / truth)) < 0.03


def test_averaging_n_records_lowers_the_run_noise_by_sqrt_n(tmp_path):
    """The same one-point run, normal and averaging 16 records: the noise of the recorded drive
    (its residual after the sine and two harmonics: the scope's input noise, 0.5 mV rms in the lab,
    over a WORD step of 0.1 mV) falls by sqrt(16) = 4 within 25 %. (The velocity's residual also
    holds the robot's other modes, rung by each burst's start: the same in every record, so
    averaging keeps it.)"""
    with VirtualLab(seed=13) as lab:
        lab.set_spot("knee")
        normal = _run(tmp_path, lab, "normal", "")
        avg = _run(tmp_path, lab, "avg", 'acquisition = "average"\naverages = 16\n')
    assert normal["noise"] / avg["noise"] == pytest.approx(4.0, rel=0.25)


def test_ds1000z_averages_lower_the_noise_by_sqrt_n():
    """labkit's DS1000Z driver on the lab's DS1104Z (no EXT: triggered on the drive, channel 1):
    :ACQuire:AVERages 16 lowers the noise of channel 4 (the input's noise alone, 1 mV/div, 8-bit
    steps of 0.04 mV) by sqrt(16) within 25 %; the averaged drive's amplitude is unchanged."""
    from labhelpers import Raw, drive_sine, fit_sine, settle

    from labkit.drivers.scope import RigolDS1000Z

    with VirtualLab(seed=14, scope_model="DS1104Z") as lab:
        fg = Raw(lab.resources["funcgen"], 10)
        drive_sine(fg, 1000.0, 2.0)
        settle(lab)
        with RigolDS1000Z.open(lab.resources["scope"], timeout_s=10) as sc:
            sc.setup_channel(1, 0.5)
            sc.setup_channel(4, 0.001)
            sc.set_timebase(2e-3)
            sc.set_trigger(sc.trigger_source_for(None, 1), 0.0)
            stds, amps = {}, {}
            for n in (1, 16):
                sc.set_averaging(n)
                sc.single()
                sc.wait_done(10)
                stds[n] = float(np.std(sc.read_waveform(4, "BYTE").volts))
                d = sc.read_waveform(1, "BYTE")
                amps[n] = abs(fit_sine(d.t_s, d.volts, 1000.0))
        fg.close()
    assert sc.state["trigger"]["source"] == "CHAN1"
    assert stds[1] / stds[16] == pytest.approx(4.0, rel=0.25)
    assert amps[16] == pytest.approx(amps[1], rel=0.01) and amps[1] == pytest.approx(1.0, rel=0.02)
