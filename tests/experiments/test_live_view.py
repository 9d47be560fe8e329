"""The live view of a run, end to end: a real ``labkit sweep`` process against a served virtual
lab (``labkit lab serve``), ``labkit view`` and ``labkit watch`` on its run file, and a real
headless Chromium (Debian's ``/usr/bin/chromium``, driven by Playwright from PyPI; no browser
is downloaded).

What the page must do (and this checks): points appear as they arrive (within a second of
the run writing them, measured on the page), the FRF is drawn per location, the run's
heartbeat going stale shows "run not responding" with the ``labkit off`` way back (the run
is frozen with SIGSTOP), Stop "after this point" ends the run with exit 130 through its own
shutdown ("drive off" in its events, the file resumable), the console logs nothing, and
the page opened after the run ended replays it whole. Without a browser: the server refuses
a request without the page's token, from another Origin, or for another Host, and Stop
"now" is SIGINT (the lab's own record shows the drive going off).

The screenshot of the live page (``docs/figures/live-view.png``) is taken from this test's
run: it is written to the test's folder, and into ``docs/figures`` when the environment
variable ``LABKIT_DOCS_FIGURES`` is set.
"""
from __future__ import annotations

import http.client
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from livehelpers import Browser

from clihelpers import REPO, last_json
from labkit.experiments import live
from labkit.experiments.session import LAB_MODELS

FREQS = [float(f) for f in np.round(np.geomspace(300, 3000, 18), 2)]
LOCS = ("body", "knee")


def _popen(*args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "labkit", *args], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


@pytest.fixture
def served_lab():
    """``labkit lab serve`` in its own process; yields its resources."""
    proc = _popen("lab", "serve", "--json", "--seed", "3")
    try:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        yield json.loads(line)
    finally:
        _stop(proc)


def _config(path: Path, resources: dict[str, str], *, settle_s: float) -> Path:
    inst = "".join(f'[instruments.{role}]\nmodel = "{LAB_MODELS[role]}"\nresource = "{resources[role]}"\n\n'
                   for role in ("funcgen", "scope", "vibrometer", "control"))
    locs = ", ".join(f'"{x}"' for x in LOCS)
    path.write_text(f"""[run]
locations = [{locs}]

{inst}[drive]
amp_vpp = 4.0
offset_v = 2.0

[frequencies]
list_hz = [{", ".join(repr(f) for f in FREQS)}]

[method]
kind = "stepped"
settle_s = {settle_s}
dwell_cycles = 20

[scope]
drive_channel = 1
velocity_channel = 2

[vibrometer]
scale_mm_s_per_v = 25.0
""")
    return path


def _wait_for(cond, timeout_s: float, what: str, proc: subprocess.Popen | None = None):
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        got = cond()
        if got:
            return got
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"{what}: the run ended first ({proc.returncode}): {proc.stderr.read()}")
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _records(stream: Path) -> list[dict]:
    return [rec for _off, rec in live.follow(stream, wait=False)]


def _start_view(run: Path) -> tuple[subprocess.Popen, str]:
    proc = _popen("view", str(run), "--json")
    line = proc.stdout.readline()
    assert line, proc.stderr.read()
    return proc, json.loads(line)["url"]


def _page_points(page) -> int:
    return int(page.evaluate("window.__labkit.points.length"))


@pytest.mark.slow
def test_live_page_follows_a_real_sweep_and_stops_it_after_a_point(tmp_path, served_lab):
    from playwright.sync_api import sync_playwright

    cfg = _config(tmp_path / "c.toml", served_lab, settle_s=0.5)
    run = tmp_path / "run.h5"
    stream = live.live_path(run)
    sweep = _popen("sweep", "inchip", str(cfg), "--out", str(run))
    view = watch = None
    try:
        _wait_for(lambda: stream.is_file(), 60, "the live stream", sweep)
        view, url = _start_view(run)
        watch = _popen("watch", str(run))          # joins now, follows until the run ends
        with sync_playwright() as pw:
            b = Browser(pw)
            try:
                page = b.page(url)
                _wait_for(lambda: _page_points(page) >= 2, 60, "two points on the page", sweep)
                # points appear as they arrive: a new one shows up while the page is open
                n0 = _page_points(page)
                _wait_for(lambda: _page_points(page) > n0, 30, "a new point on the page", sweep)
                k_text = page.inner_text("#k")
                assert int(k_text) >= n0 + 1
                assert page.inner_text("#n") == str(len(FREQS) * len(LOCS))
                # the run's heartbeat freezes with the run: "run not responding" and the way back
                sweep.send_signal(signal.SIGSTOP)
                try:
                    page.wait_for_selector("#banner:not([hidden])", timeout=15000)
                    banner = page.inner_text("#banner")
                finally:
                    sweep.send_signal(signal.SIGCONT)
                assert "Run not responding" in banner and f"labkit off {cfg}" in banner
                page.wait_for_selector("#banner", state="hidden", timeout=15000)     # it recovers
                # both locations on the plots (the screenshot), well before the run's end
                _wait_for(lambda: _page_points(page) >= len(FREQS) + 3, 90, "the knee's points", sweep)
                page.wait_for_timeout(300)
                shot = tmp_path / "live-view.png"
                page.screenshot(path=str(shot), full_page=True)
                # each point drawn (one marker per point on the |H| plot), and the lamps
                page.wait_for_function("() => document.querySelectorAll('#mag circle.pt').length === "
                                       "window.__labkit.points.filter(p => p.status === 'ok').length", timeout=5000)
                assert page.inner_text("#drive") in ("DRIVE ON", "DRIVE OFF")
                latency = page.evaluate("window.__labkit.latency")
                # Stop after this point: the run's own shutdown, exit 130
                page.click("#stop-point")
                page.wait_for_function("() => document.getElementById('stop-result').textContent.includes('sent')")
                sweep.wait(60)
                page.wait_for_function("() => document.getElementById('state').textContent.includes('exit 130')",
                                       timeout=15000)
                events = page.inner_text("#events")
                assert "drive off" in events and "stop requested" in events
                assert page.is_disabled("#stop-point") and page.is_disabled("#stop-now")
                # opened after the run ended: the whole run replays
                late = b.page(url)
                late.wait_for_function("() => document.getElementById('state').textContent.includes('exit 130')",
                                       timeout=15000)
                n_points = _page_points(page)
                ok = page.evaluate("window.__labkit.points.filter(p => p.status === 'ok').length")
                assert _page_points(late) == n_points
                assert late.locator("#mag circle.pt").count() == ok == page.locator("#mag circle.pt").count()
                assert b.console == [], b.console
            finally:
                b.close()
        out, err = sweep.communicate(timeout=10)
        w_out, w_err = watch.communicate(timeout=30)
    finally:
        for p in (sweep, view, watch):
            if p is not None:
                _stop(p)
    assert sweep.returncode == 130, err
    assert "interrupted by STOP (labkit view)" in err and "Traceback" not in err
    assert "Traceback" not in w_err and watch.returncode == 0, w_err
    # every point on the page arrived within a second of the run writing it (same machine, same clock)
    # (points written before the page connected are replayed, not counted)
    assert len(latency) >= 3 and float(np.median(latency)) < 1.0 and max(latency) < 2.0, latency
    recs = _records(stream)
    ends = [r for r in recs if r["t"] == "end"]
    assert ends == [ends[0]] and ends[0]["exit"] == 130
    texts = [r["text"] for r in recs if r["t"] == "event"]
    i_stop = next(i for i, t in enumerate(texts) if t.startswith("stop requested"))
    assert any(t.startswith("drive off") for t in texts[i_stop:])
    with h5py.File(run, "r") as f:
        assert f.attrs["status"] == "interrupted: STOP (labkit view)"
        n_file = f["points/index"].shape[0]
        ev = list(f["events/text"].asstr()[...])
        assert any(e.startswith("drive off") for e in ev) and any(e.startswith("stop requested") for e in ev)
    assert 5 <= n_file < len(FREQS) * len(LOCS) and n_points == n_file
    # the run's console (not a terminal) printed a row per point; watch printed the same rows
    rows = [ln for ln in out.splitlines() if f"/{len(FREQS) * len(LOCS)} " in ln]
    assert len(rows) == n_file
    assert [ln for ln in w_out.splitlines() if f"/{len(FREQS) * len(LOCS)} " in ln] == rows
    assert "end: interrupted: STOP (labkit view) (exit 130)" in w_out
    # resumable: --resume completes it, every point once
    done = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--resume", str(run),
                           "--json", "--quiet"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert last_json(done)["status"] == "complete"
    with h5py.File(run, "r") as f:
        assert sorted(f["points/index"][...]) == list(range(len(FREQS) * len(LOCS)))
    assert [r["exit"] for r in _records(stream) if r["t"] == "end"] == [130, 0]
    if os.environ.get("LABKIT_DOCS_FIGURES"):
        shutil.copy(shot, REPO / "docs" / "figures" / "live-view.png")


def _request(port: int, method: str, path: str, headers: dict[str, str], body: bytes = b"") -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.request(method, path, body=body or None, headers=headers)
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


@pytest.mark.slow
def test_stop_now_is_sigint_and_only_the_page_may_send_it(tmp_path, served_lab):
    from labkit.experiments.liveview import LiveView

    cfg = _config(tmp_path / "c.toml", served_lab, settle_s=0.25)
    run = tmp_path / "run.h5"
    sweep = _popen("sweep", "inchip", str(cfg), "--out", str(run), "--quiet")
    try:
        stream = live.live_path(run)
        _wait_for(lambda: stream.is_file() and sum(r["t"] == "point" for r in _records(stream)) >= 2, 60,
                  "two points", sweep)
        with LiveView(run) as view:
            host = f"127.0.0.1:{view.port}"
            good = {"Host": host, "Origin": f"http://{host}", "X-Labkit-Token": view.token,
                    "Content-Type": "application/json"}
            body = json.dumps({"when": "now"}).encode()
            # refused: no token, a wrong token, another site's Origin, a rebinding Host, no Origin
            for bad in ({"X-Labkit-Token": ""}, {"X-Labkit-Token": view.token[:-1] + "x"},
                        {"Origin": "http://evil.example"}, {"Host": f"evil.example:{view.port}"},
                        {"Origin": ""}):
                status, reply = _request(view.port, "POST", "/stop", good | bad, body)
                assert status == 403, (bad, status, reply)
            assert _request(view.port, "GET", "/", {"Host": host})[0] == 403            # the page needs the token
            assert _request(view.port, "GET", f"/?token={view.token}", {"Host": "evil.example"})[0] == 403
            status, page = _request(view.port, "GET", f"/?token={view.token}", {"Host": host})
            assert status == 200 and b"live-view.js" in page
            assert not stream.with_name("run.live.stop").exists() and sweep.poll() is None   # nothing sent
            t_stop = time.time()
            status, reply = _request(view.port, "POST", "/stop", good, body)
            assert status == 200 and json.loads(reply)["pid"] == sweep.pid
            sweep.wait(30)
            # the run has ended: a further stop is refused (no process holds the run file)
            status, reply = _request(view.port, "POST", "/stop", good, body)
            assert status == 409 and b"ended" in reply
    finally:
        _stop(sweep)
    err = sweep.stderr.read()
    assert sweep.returncode == 130 and "interrupted by SIGINT" in err, err
    recs = _records(live.live_path(run))
    offs = [r["time"] for r in recs if r["t"] == "event" and r.get("drive") is False]
    assert offs and offs[-1] - t_stop < 1.0              # the drive went off within a second
    assert recs[-1]["t"] == "end" and recs[-1]["exit"] == 130 and recs[-1]["status"] == "interrupted: SIGINT"
