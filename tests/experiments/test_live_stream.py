"""The live stream's content for each kind of run (in-process runs on the virtual lab), the page
replaying a finished shaker run in headless Chromium, and ``labkit watch`` on a finished, a
vanished and a missing stream.

The stream is checked against the run file the same run wrote (the file is what the rest of
labkit trusts): every point's frequency, FRF or transmissibility, tray amplitude and drive are
the file's, and the events are the file's ``/events`` in order.
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from labcfg import inchip_toml, shaker_toml
from livehelpers import Browser

from clihelpers import REPO, last_json, run_cli
from labkit.errors import LimitError
from labkit.experiments import live
from labkit.experiments.session import run_session
from labkit.lab import VirtualLab


def _records(run):
    return [rec for _off, rec in live.follow(live.live_path(run), wait=False)]


def _file_events(f) -> list[str]:
    return list(f["events/text"].asstr()[...])


def test_stepped_stream_matches_the_run_file(tmp_path):
    cfg = inchip_toml(tmp_path / "c.toml", [500.0, 1000.0, 2000.0], locations=("body", "knee"),
                      settle_s=0.03, dwell_cycles=20)
    out = tmp_path / "r.h5"
    run_session("inchip", cfg, out, lab=True, quiet=True)
    recs = _records(out)
    assert recs[0]["t"] == "start" and recs[0]["points_planned"] == 6 and recs[0]["pid"] == os.getpid()
    assert recs[-1] == recs[-1] | {"t": "end", "status": "complete", "exit": 0}
    pts = [r for r in recs if r["t"] == "point"]
    assert [p["k"] for p in pts] == [1, 2, 3, 4, 5, 6] and {p["n"] for p in pts} == {6}
    with h5py.File(out, "r") as f:
        assert [r["text"] for r in recs if r["t"] == "event"] == _file_events(f)
        for loc in ("body", "knee"):
            g = f[f"locations/{loc}"]
            mine = [p for p in pts if p["location"] == loc]
            assert [p["freq_hz"] for p in mine] == list(g["freq_hz"][...])
            assert [complex(*p["frf"]) for p in mine] == list(g["frf"][...])
            assert [p["quality"] for p in mine] == list(g["quality"][...])
            assert [p["drive_vpp"] for p in mine] == pytest.approx(list(2 * np.abs(g["drive_v"][...])))
    for p in pts:
        assert p["drive_set_vpp"] == 4.0 and abs(p["drive_vpp"] / 4.0 - 1) < 0.05
        # the drive channel is scaled to 1.25 x the drive: its peak is 80 % of the half screen
        assert p["pct_fs"]["drive"] == pytest.approx(80.0, abs=2.0)
        assert p["over"] == {"drive": False, "velocity": False}
        assert p["under"]["velocity"] == (p["pct_fs"]["velocity"] < live.UNDER_PCT)
        assert p["remaining_s"] >= 0 and p["elapsed_s"] > 0
    drive = [r["drive"] for r in recs if "drive" in r]
    assert drive[0] is True and drive[-1] is False and drive.count(False) >= 2     # off before the move
    assert all(live.format_record(r) for r in recs if r["t"] != "hb")


def test_over_range_points_are_flagged_and_an_interlock_end_exits_2(tmp_path):
    # 1 mm/s/V: the knee's 3.4 kHz resonance (~12 mm/s) exceeds the vibrometer's 10 V analog range
    freqs = [1000.0, 3400.0, 4500.0]
    cfg = inchip_toml(tmp_path / "il.toml", freqs, locations=("knee",), scale_mm_s_per_v=1.0,
                      settle_s=0.02, dwell_cycles=10)
    run_session("inchip", cfg, tmp_path / "il.h5", lab=True, quiet=True)
    pts = [r for r in _records(tmp_path / "il.h5") if r["t"] == "point"]
    assert [p["status"] for p in pts] == ["ok", "interlock", "ok"]
    assert pts[1]["over"]["velocity"] and "over-range" in pts[1]["reason"] and "frf" not in pts[1]
    assert not pts[0]["over"]["velocity"] and not pts[2]["over"]["velocity"]
    assert "interlock: vibrometer over-range" in live.format_record(pts[1])
    end_cfg = inchip_toml(tmp_path / "end.toml", freqs, locations=("knee",), scale_mm_s_per_v=1.0,
                          settle_s=0.02, dwell_cycles=10, on_interlock="end")
    with pytest.raises(LimitError):
        run_session("inchip", end_cfg, tmp_path / "end.h5", lab=True, quiet=True)
    end = _records(tmp_path / "end.h5")[-1]
    assert end["t"] == "end" and end["exit"] == 2 and end["status"].startswith("aborted: interlock")


def test_shaker_stream_and_the_page_replaying_it(tmp_path):
    from playwright.sync_api import sync_playwright

    from labkit.experiments.liveview import LiveView

    cfg = shaker_toml(tmp_path / "s.toml", [200.0, 300.0], [8.0, 12.0], settle_s=0.03, dwell_cycles=10)
    out = tmp_path / "s.h5"
    with VirtualLab(seed=2) as lab:
        run_session("shaker", cfg, out, lab=lab, quiet=True)
    pts = [r for r in _records(out) if r["t"] == "point"]
    with h5py.File(out, "r") as f:
        p = f["points"]
        assert [x["tray_amp_um"] for x in pts] == list(p["tray_amp_um"][...])
        assert [x["tray_amp_request_um"] for x in pts] == list(p["tray_amp_request_um"][...]) == [8, 12, 8, 12]
        assert [x["drive_vpp"] for x in pts] == list(p["drive_vpp"][...])
        assert [complex(*x["transmissibility"]) for x in pts] == list(p["transmissibility"][...])
    for x in pts:       # the drive the scope saw is the one applied (the scope's rms, a sine's 2 sqrt 2)
        assert x["drive_measured_vpp"] == pytest.approx(x["drive_vpp"], rel=0.05)
    with LiveView(out) as view, sync_playwright() as pw:
        browser = Browser(pw)
        try:
            page = browser.page(view.url, height=1100)
            page.wait_for_function("() => document.getElementById('state').textContent.includes('exit 0')")
            assert page.is_visible("#shaker") and "transmissibility" in page.inner_text("#h-mag")
            page.wait_for_function("() => document.querySelectorAll('#tray circle.pt').length === 8")
            assert page.locator("#drivev circle.pt").count() == 4 and page.locator("#mag circle.pt").count() == 4
            assert page.inner_text("#k") == "4" and page.inner_text("#drive") == "DRIVE OFF"
            assert page.is_disabled("#stop-point")            # nothing to stop: the run has ended
            assert "tray" in page.inner_text("#last-point") and "(measured " in page.inner_text("#last-point")
            assert "No video in this run" in page.inner_text("#speed-note")
            page.goto(view.url.replace("token=", "token=x"))   # a wrong token gets no page
            assert "wrong token" in page.inner_text("body")
            assert [c for c in browser.console if "403" not in c] == [], browser.console
        finally:
            browser.close()


def test_the_page_shows_each_video_s_tracked_speed(tmp_path):
    """A shaker run with video (the demo's robot, which walks at 240-280 Hz): the view tracks each
    point's video as it appears and the page plots the speed with its confidence interval; the
    numbers are those ``labkit track`` gives for the same videos."""
    from playwright.sync_api import sync_playwright

    from labkit.analysis.tracking import track_file
    from labkit.demo.configs import write_shaker_config
    from labkit.demo.run import demo_robots
    from labkit.experiments.liveview import LiveView

    cfg = write_shaker_config(tmp_path / "v.toml", [240.0, 280.0], 25.0, video_s=0.5, settle_s=0.05,
                              dwell_cycles=10)
    out = tmp_path / "v.h5"
    with VirtualLab(robot=demo_robots()[0], seed=1) as lab:
        run_session("shaker", cfg, out, lab=lab, quiet=True)
    videos = [r["video"] for r in _records(out) if r["t"] == "point"]
    assert len(videos) == 2 and all(videos)
    want = [track_file(tmp_path / v, quiet=True).summary for v in videos]
    with LiveView(out) as view, sync_playwright() as pw:
        browser = Browser(pw)
        try:
            page = browser.page(view.url, height=1300)
            page.wait_for_function("() => document.querySelectorAll('#speed circle.pt').length === 2",
                                   timeout=60000)
            assert page.locator("#speed line.ci").count() == 2
            assert "2 of 2 tracked" in page.inner_text("#speed-note")
            got = page.evaluate("window.__labkit.speeds")
            assert browser.console == [], browser.console
        finally:
            browser.close()
    for g, w, v in zip(got, want, videos):
        assert g["video"] == v and g["speed_mm_s"] == w["mean_speed_mm_s"] > 0
        assert g["ci_mm_s"] == list(w["speed_ci_mm_s"]) and g["ci_mm_s"][0] < g["speed_mm_s"] < g["ci_mm_s"][1]


def test_chirp_points_carry_every_line(tmp_path):
    cfg = inchip_toml(tmp_path / "chirp.toml", [400.0, 2000.0], locations=("body",))
    text = cfg.read_text().replace("list_hz = [400.0, 2000.0]",
                                   'start_hz = 400.0\nstop_hz = 2000.0\ncount = 2\nspacing = "lin"')
    cfg.write_text(text.replace('kind = "stepped"\nsettle_s = 0.04\ndwell_cycles = 20\nkeep_raw = false',
                                'kind = "chirp"\nlength_s = 0.4\naverages = 2\nkeep_raw = false'))
    out = tmp_path / "chirp.h5"
    run_session("inchip", cfg, out, lab=True, quiet=True)
    (pt,) = [r for r in _records(out) if r["t"] == "point"]
    with h5py.File(out, "r") as f:
        g = f["locations/body"]
        assert pt["freq_hz"] == list(g["freq_hz"][...])
        h = np.array(pt["frf"][0], float) + 1j * np.array(pt["frf"][1], float)
        assert np.array_equal(h, g["frf"][...])
        assert pt["quality"] == list(g["coherence"][...])
    assert "chirp 400-2000 Hz" in live.format_record(pt)


def test_watch_replays_a_finished_run_and_fails_cleanly_without_a_stream(tmp_path):
    cfg = inchip_toml(tmp_path / "c.toml", [800.0, 1600.0], locations=("knee",), settle_s=0.03)
    out = tmp_path / "r.h5"
    run_session("inchip", cfg, out, lab=True, quiet=True)
    proc = run_cli("watch", str(out), "--json")
    summary = last_json(proc)
    assert summary["points"] == 2 and summary["status"] == "complete" and summary["exit"] == 0
    rows = run_cli("watch", str(out)).stdout.splitlines()
    assert sum("/2 " in r for r in rows) == 2 and rows[-1].endswith("end: complete (exit 0)")
    assert any("drive on" in r for r in rows)
    bad = run_cli("watch", str(tmp_path / "none.h5"), check=2)
    assert bad.stderr.count("\n") == 1 and "no live stream beside it" in bad.stderr and "Traceback" not in bad.stderr
    assert run_cli("view", str(tmp_path / "none.h5"), check=2).stderr.count("\n") == 1
    # labkit view serves until Ctrl-C, which ends it normally (exit 0, its summary)
    view = subprocess.Popen([sys.executable, "-m", "labkit", "view", str(out), "--json"], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = json.loads(view.stdout.readline())["url"]
        assert url.startswith("http://127.0.0.1:") and "token=" in url
        view.send_signal(signal.SIGINT)
        v_out, v_err = view.communicate(timeout=30)
    finally:
        view.kill()
    assert view.returncode == 0 and json.loads(v_out.splitlines()[-1])["url"] == url, v_err


def test_watch_says_when_the_run_has_gone(tmp_path):
    """A stream without an end record whose writer is gone (a SIGKILLed run): watch says the
    drive may be on, with the way back, and returns (nothing holds the run file's lock)."""
    run = tmp_path / "k.h5"
    stream = live.LiveStream(run)
    stream.start(kind="run_inchip", points_planned=3, points_done=0, est_s=1.0, locations=["knee"],
                 config="bench.toml")
    stream.event("drive on")
    stream.close()                                    # no end record: as after SIGKILL
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "labkit", "watch", str(run)], cwd=REPO, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "has gone without an end record" in proc.stdout and "labkit off bench.toml" in proc.stdout
    assert time.monotonic() - t0 >= live.STALE_S        # it waited for the heartbeat first
    assert json.loads(json.dumps(_records(run)[0]))["config"] == "bench.toml"
    assert not math.isnan(_records(run)[0]["est_s"])
