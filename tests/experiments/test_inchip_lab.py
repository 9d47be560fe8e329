"""In-chip sweeps against the virtual lab (real sockets and pty): FRF peaks, interlocks, a lost instrument."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from labcfg import inchip_toml, lab_timeline

from labkit.errors import InputError, InstrumentError, LimitError
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab


def _peak_hz(f: np.ndarray, mag: np.ndarray, lo: float, hi: float) -> float:
    """Peak of |H| inside [lo, hi]: a parabola through the top three points (in log f)."""
    sel = np.flatnonzero((f >= lo) & (f <= hi))
    k = sel[np.argmax(mag[sel])]
    assert sel[0] < k < sel[-1], f"no interior maximum in {lo:.0f}-{hi:.0f} Hz (max at {f[k]:.1f} Hz)"
    x = np.log(f[k - 1:k + 2])
    a, b, _ = np.polyfit(x, mag[k - 1:k + 2], 2)
    return float(np.exp(-b / (2 * a)))


@pytest.mark.slow
def test_inchip_frf_peaks_at_tethered_resonances(tmp_path):
    truth = VirtualLab(seed=0).truth["tethered_modes"]           # not started: just its parameters
    modes = {n: f for n, f in zip(truth["names"], truth["freq_hz"]) if n in ("tether", "knee")}
    # a coarse log grid plus a 0.5 % grid across +-1.5 % of each resonance
    freqs = set(np.round(np.geomspace(300, 5000, 6), 3))
    for f0 in modes.values():
        freqs |= set(np.round(f0 * (1 + 0.005 * np.arange(-3, 4)), 3))
    freqs = sorted(freqs)
    cfg = inchip_toml(tmp_path / "inchip.toml", freqs, settle_s=0.03, dwell_cycles=12)
    out = tmp_path / "run.h5"
    summary = run_session("inchip", cfg, out, lab=True, quiet=True)
    assert summary["status"] == "complete" and summary["points_ok"] == 3 * len(freqs)
    with h5py.File(out, "r") as f:
        assert f.attrs["kind"] == "run_inchip" and f.attrs["status"] == "complete"
        stored = json.loads(f["virtual_lab"].attrs["truth_json"])["tethered_modes"]
        assert stored["freq_hz"] == truth["freq_hz"]
        for loc in ("body", "hip", "knee"):
            g = f[f"locations/{loc}"]
            fr, h, q = g["freq_hz"][...], g["frf"][...], g["quality"][...]
            assert list(fr) == freqs and g["frf"].attrs["units"] == "(mm/s)/V"
            for name, f0 in modes.items():
                peak = _peak_hz(fr, np.abs(h), f0 * 0.984, f0 * 1.016)
                assert abs(peak / f0 - 1) < 0.01, (loc, name, peak, f0)
                near = np.abs(fr / f0 - 1) < 0.01
                assert q[near].min() > 0.99          # clean sines at the resonances
        # the drive was on during the sweep and off at the end (the lab's own record)
        t, on = lab_timeline(f)
        assert on.any() and not on[-1]


def test_over_range_interlock_skips_points_and_turns_drive_off(tmp_path):
    # 1 mm/s/V: the knee's 3.4 kHz resonance (~12 mm/s) exceeds the 10 V analog range
    freqs = [1000.0, 3400.0, 3420.0, 4500.0]
    cfg = inchip_toml(tmp_path / "il.toml", freqs, locations=("knee",), scale_mm_s_per_v=1.0,
                      settle_s=0.02, dwell_cycles=10)
    out = tmp_path / "il.h5"
    with VirtualLab(seed=1) as lab:
        summary = run_session("inchip", cfg, out, lab=lab, quiet=True)
        assert lab.output_state("funcgen", 1) is False
    assert summary["status"] == "complete"
    assert [il["index"] for il in summary["interlocks"]] == [1, 2]
    with h5py.File(out, "r") as f:
        st = list(f["points/status"].asstr()[...])
        assert st == ["ok", "interlock", "interlock", "ok"]
        assert "over-range" in f["points/reason"].asstr()[1]
        assert list(f["locations/knee/freq_hz"][...]) == [1000.0, 4500.0]
        events = list(f["events/text"].asstr()[...])
        assert sum("drive off (interlock: vibrometer over-range)" in e for e in events) == 2
        # the drive went off after each interlocked point: three on/off pairs on the lab's record
        _, on = lab_timeline(f)
        assert list(on) == [False, True, False, True, False, True, False]
    cfg_end = inchip_toml(tmp_path / "end.toml", freqs, locations=("knee",), scale_mm_s_per_v=1.0,
                          settle_s=0.02, dwell_cycles=10, on_interlock="end")
    with pytest.raises(LimitError, match="over-range at point 1; run ended"):
        run_session("inchip", cfg_end, tmp_path / "end.h5", lab=True, quiet=True)
    with h5py.File(tmp_path / "end.h5", "r") as f:
        assert f.attrs["status"].startswith("aborted: interlock")
        assert list(f["points/status"].asstr()[...]) == ["ok", "interlock"]
        _, on = lab_timeline(f)
        assert not on[-1]


@pytest.mark.parametrize("instrument, match", [("scope", "DATA?"), ("funcgen", "SYST:ERR?")])
def test_lost_instrument_leaves_output_off(tmp_path, instrument, match):
    cfg = inchip_toml(tmp_path / "c.toml", [800.0, 900.0, 1000.0, 1100.0, 1200.0], locations=("hip",),
                      settle_s=0.01, dwell_cycles=10, timeout_s=0.5)
    out = tmp_path / "lost.h5"
    with VirtualLab(seed=2) as lab:
        # the link drops in the middle of the third point (after the drive is on), and every new
        # link too: a lost instrument (a single drop is reconnected: test_reconnect.py)
        lab.inject_fault(instrument, "drop", after=5 if instrument == "scope" else 9, match=match, count=10**6)
        with pytest.raises(InstrumentError) as err:
            run_session("inchip", cfg, out, lab=lab, quiet=True)
        assert instrument in str(err.value)
        assert lab.output_state("funcgen", 1) is False and lab.output_state("funcgen", 2) is False
        on_times = [t for t, inst, ch, on in lab.output_timeline if inst == "funcgen" and on]
        assert on_times, "the drive was never on: the fault hit too early to test anything"
    with h5py.File(out, "r") as f:
        assert f.attrs["status"].startswith("aborted: InstrumentError")
        n = f["points/index"].shape[0]
        assert f["locations/hip/freq_hz"].shape[0] == n >= 1
        assert any("drive off" in e for e in f["events/text"].asstr()[...])


def test_chirp_h1_and_coherence(tmp_path, capsys):
    cfg = inchip_toml(tmp_path / "chirp.toml", [400.0, 2000.0], locations=("body",))
    text = cfg.read_text()
    text = text.replace("list_hz = [400.0, 2000.0]", 'start_hz = 400.0\nstop_hz = 2000.0\ncount = 2\nspacing = "lin"')
    text = text.replace('kind = "stepped"\nsettle_s = 0.04\ndwell_cycles = 20\nkeep_raw = false',
                        'kind = "chirp"\nlength_s = 0.4\naverages = 2\nkeep_raw = true')
    cfg.write_text(text)
    out = tmp_path / "chirp.h5"
    with VirtualLab(seed=5) as lab:
        summary = run_session("inchip", cfg, out, lab=lab, quiet=True)
        with h5py.File(out, "r") as f:
            assert f.attrs["method"] == "chirp"
            # a sweep keeps running between triggers: the run says so, in the file and on the console
            assert not f.attrs["drive_bounded"] and "chirp" in f.attrs["drive_bounded_note"]
            assert any(e.startswith("DRIVE NOT BOUNDED") for e in f["events/text"].asstr()[...])
            assert "warning: DRIVE NOT BOUNDED" in capsys.readouterr().err
            g = f["locations/body"]
            fr, h, coh = g["freq_hz"][...], g["frf"][...], g["coherence"][...]
            assert g["coherence"].attrs["units"] == "1" and fr[0] >= 400 and fr[-1] <= 2000
            assert np.median(np.diff(fr)) == pytest.approx(1 / 0.4)          # 1 / chirp length
            true = lab.frf("body", fr)
            tether_hz = lab.truth["tethered_modes"]["freq_hz"][1]
            band = np.abs(fr / tether_hz - 1) < 0.1
            assert np.median(np.abs(h[band] / true[band] - 1)) < 0.1
            assert abs(fr[np.argmax(np.abs(h))] / tether_hz - 1) < 0.01
            assert np.median(coh[band]) > 0.95
            raw = f["raw/p00000"]
            assert raw["drive_v"].attrs["units"] == "V" and raw["drive_v"].shape == raw["velocity_v"].shape
            assert raw["drive_v"].shape[0] >= 2 * 0.4 * 2000 * 10 * 0.99     # two records, 10 samples/cycle
    assert summary["status"] == "complete" and summary["locations"]["body"] == len(fr)


class _Person:
    """Answers the runner's prompts on 'stdin' by moving the lab's laser, as a person would."""

    def __init__(self, lab, spots):
        self.lab, self.spots, self.asked = lab, list(spots), 0

    def readline(self):
        if not self.spots:
            return ""                                    # walked away: EOF
        self.lab.set_spot(self.spots.pop(0))
        self.asked += 1
        return "\n"


def test_person_moves_the_laser_when_asked(tmp_path, capsys):
    cfg = inchip_toml(tmp_path / "p.toml", [830.0, 3400.0], locations=("body", "knee"), settle_s=0.03)
    with VirtualLab(seed=6) as lab:
        person = _Person(lab, ["body", "knee"])
        run_session("inchip", cfg, tmp_path / "p.h5", lab=lab, quiet=True, stdin=person)
        assert person.asked == 2
        with h5py.File(tmp_path / "p.h5", "r") as f:
            for loc in ("body", "knee"):
                h = f[f"locations/{loc}/frf"][...]
                assert np.allclose(h, lab.frf(loc, [830.0, 3400.0]), rtol=0.05)
        assert "Point the laser vibrometer at the KNEE" in capsys.readouterr().err
        # nobody answers the second prompt: the run stops with the drive off and says why
        with pytest.raises(InputError, match="no answer on standard input"):
            run_session("inchip", cfg, tmp_path / "q.h5", lab=lab, quiet=True, stdin=_Person(lab, ["body"]))
        assert lab.output_state("funcgen", 1) is False
    with h5py.File(tmp_path / "q.h5", "r") as f:
        assert f.attrs["status"].startswith("aborted: InputError")
        assert list(f["locations/body/freq_hz"][...]) == [830.0, 3400.0]


def test_a_final_status_that_cannot_be_written_is_not_reported_complete(tmp_path, monkeypatch):
    """Disk full at the very end (simulated at the file's edge): the drive still goes off, the
    points stay on disk, and the run is an error, not "complete"."""
    from labkit.experiments import runfile

    def disk_full(self, status):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runfile.RunFile, "finish", disk_full)
    cfg = inchip_toml(tmp_path / "c.toml", [830.0, 900.0], locations=("body",), settle_s=0.03)
    out = tmp_path / "run.h5"
    with VirtualLab(seed=1) as lab:
        with pytest.raises(InputError, match="final status"):
            run_session("inchip", cfg, out, lab=lab, quiet=True)
        assert lab.output_state("funcgen", 1) is False
    with h5py.File(out, "r") as f:
        assert f["locations/body/freq_hz"].shape[0] == 2
