"""``labkit view``: a run's live stream as a page in the browser, served on loopback.

The server reads only the stream beside the run file (``RUN.live.jsonl``, see
:mod:`labkit.experiments.live`) and sends it to the page as Server-Sent Events
(``/events``: each line as one event, its id the byte offset after it, so a
reconnecting page resumes where it was); every second it also sends the age of
the stream's last line as the server's clock sees it (the run's heartbeat).
The page (``labkit/data/live-view.*``: plain JavaScript drawing SVG, no
library, nothing fetched from elsewhere) builds its plots from the events.

Shaker runs with video: the server (not the run) tracks each point's video as the point
appears in the stream (:class:`SpeedTracker`, the method of ``labkit track``, in a thread
at low priority) and sends the robot's speed with its confidence interval as ``speed``
events.

Stop: ``POST /stop`` with ``{"when": "point"}`` writes the stop request the
run looks for before each point (:func:`labkit.experiments.live.stop_path`);
``{"when": "now"}`` also sends SIGINT to the process that holds the run
file's lock, so the run stops exactly as on Ctrl-C (drive off, file finished,
exit 130). Who may stop a run:

* the server listens on 127.0.0.1 only (from another machine: ``ssh -L``);
* every request but the page's static files needs the secret token of the
  page's URL (``secrets.token_urlsafe``, compared in constant time), sent by the
  page as the ``X-Labkit-Token`` header for ``/stop``: a form or an image on
  another site cannot set a header, and a cross-origin ``fetch`` with one needs
  a CORS pre-flight this server never grants;
* ``Host`` must name this server (a DNS-rebinding page names its own host),
  and ``/stop`` needs an ``Origin`` equal to the server's own;
* the page may not be framed (``frame-ancestors 'none'``), runs only its own
  script (Content-Security-Policy), and sends no referrer (the token stays out
  of other sites' logs).
"""
from __future__ import annotations

import hmac
import json
import math
import os
import secrets
import signal
import socket
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any, NotRequired, TypedDict
from urllib.parse import parse_qs, urlsplit

from labkit.experiments import live


class ViewStatus(TypedDict):
    """``GET /status``: the stream's age on this machine's clock and whether a process writes the run."""

    now: float
    stream_age_s: float | None
    running: bool
    stale_s: float


class SpeedRecord(TypedDict):
    """The page's ``speed`` event of one shaker point: the point (as the stream names it) and its
    video's tracked speed with its interval, or the ``error`` that kept it from being tracked."""

    t: str
    index: int
    k: int | None
    video: str
    freq_hz: float | None
    tray_amp_um: float | None
    error: NotRequired[str]
    speed_mm_s: NotRequired[float | None]
    ci_mm_s: NotRequired[list[float | None]]
    ci_level: NotRequired[float | None]
    frames: NotRequired[int]
    scaled_by: NotRequired[str]


class StopReply(TypedDict):
    """``POST /stop``: whether the request went to the run (``sent``, the run's ``pid``) or why not."""

    ok: bool
    error: NotRequired[str]
    sent: NotRequired[str]
    pid: NotRequired[int]


#: the page's own files (labkit/data/), by URL path
STATIC = {"/live-view.js": ("live-view.js", "text/javascript; charset=utf-8"),
          "/live-view.css": ("live-view.css", "text/css; charset=utf-8")}
PAGE = ("live-view.html", "text/html; charset=utf-8")
SECURITY_HEADERS = {
    "Content-Security-Policy": ("default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; "
                                "img-src 'self' data:; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"),
    "X-Frame-Options": "DENY", "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-store",
}
#: seconds between the server's status events (stream age, run alive)
STATUS_S = 1.0


def _asset(name: str) -> bytes:
    return (resources.files("labkit") / "data" / name).read_bytes()


class SpeedTracker:
    """Tracks each shaker point's video as it appears in the stream; :attr:`results` grows.

    A video in which the robot did not walk far enough to find its own scale is tracked
    again with the scale of the run's other videos (one camera, one zoom), as ``labkit
    demo`` does; until one has been measured, such a point gets an ``error``.
    """

    def __init__(self, run_path: Path, stream: Path, closing: threading.Event) -> None:
        self.run_path, self.stream, self.closing = run_path, stream, closing
        self.results: list[SpeedRecord] = []
        self.scales: list[tuple[float, float]] = []        # (mm/px, its standard uncertainty)

    def run(self) -> None:
        try:        # Linux: this thread only; the run on the same machine keeps its share of the CPU
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 10)
        except (AttributeError, OSError):
            pass
        pos = 0
        while not self.closing.is_set():
            for end, rec in live.follow(self.stream, pos, wait=False):
                pos = end
                if rec.get("t") == "point" and rec.get("video") and rec.get("status") == "ok":
                    self.results.append(self.track(rec))
                if self.closing.is_set():
                    return
            self.closing.wait(0.5)

    def track(self, rec: dict[str, Any]) -> SpeedRecord:
        """The ``speed`` record of one point's video (``error`` when it could not be tracked)."""
        from labkit.analysis.tracking import Scale, track_file
        from labkit.errors import InputError

        out: SpeedRecord = {"t": "speed", "index": rec["index"], "k": rec.get("k"), "video": rec["video"],
                            "freq_hz": rec.get("freq_hz"), "tray_amp_um": rec.get("tray_amp_um")}
        video = self.run_path.parent / str(rec["video"])
        scale = None
        try:
            try:
                summ = track_file(video, quiet=True).summary
                self.scales.append((float(summ["mm_per_px"]), float(summ["mm_per_px_std"] or 0.0)))
            except InputError:
                if not self.scales:
                    raise
                mm = [m for m, _ in self.scales]
                scale = Scale(sum(mm) / len(mm), max(d for _, d in self.scales), "other videos of the run",
                              {"videos": len(mm)})
                summ = track_file(video, quiet=True, scale=scale).summary
        except Exception as exc:        # one bad video must not stop the page
            out["error"] = f"{type(exc).__name__}: {str(exc)[:300]}"
            return out
        lo, hi = summ["speed_ci_mm_s"]
        out["speed_mm_s"] = live.num(summ["mean_speed_mm_s"])
        out["ci_mm_s"] = [live.num(lo), live.num(hi)]
        out["ci_level"] = live.num(summ.get("ci_level", math.nan))
        out["frames"] = int(summ["frames"])
        out["scaled_by"] = "other videos of the run" if scale is not None else "the robot's length"
        return out


class LiveView:
    """The server of one run's page; :meth:`start` serves in a thread, :meth:`close` stops.

    Parameters
    ----------
    run_path:
        The run file (or its ``.live.jsonl``); InputError when it has no stream.
    port:
        TCP port on 127.0.0.1 (0: any free one).
    token:
        The secret of the page's URL (default: a new random one).
    track_videos:
        Track shaker points' videos as they appear (:class:`SpeedTracker`).
    """

    def __init__(self, run_path: str | Path, port: int = 0, token: str | None = None,
                 track_videos: bool = True) -> None:
        self.run_path, self.stream = live.stream_of(run_path)
        self.token = token or secrets.token_urlsafe(24)
        self.closing = threading.Event()
        handler = type("Handler", (_Handler,), {"view": self})
        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), handler)
        self.httpd.daemon_threads = True
        self.port = int(self.httpd.server_address[1])
        self.hosts = {f"127.0.0.1:{self.port}", f"localhost:{self.port}"}
        self._thread: threading.Thread | None = None
        self.tracker = SpeedTracker(self.run_path, self.stream, self.closing) if track_videos else None
        if self.tracker is not None:
            threading.Thread(target=self.tracker.run, name="labkit-view-track", daemon=True).start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/?token={self.token}"

    def start(self) -> LiveView:
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="labkit-view", daemon=True)
        self._thread.start()
        return self

    def serve_forever(self) -> None:
        self.httpd.serve_forever(poll_interval=0.2)

    def close(self) -> None:
        """Stop serving. ``shutdown()`` only for the thread of :meth:`start`: it waits for a loop
        that is running, and hangs when the loop never started (Ctrl-C before serving)."""
        self.closing.set()
        if self._thread is not None:
            self.httpd.shutdown()
            self._thread.join(timeout=5)
        self.httpd.server_close()

    def __enter__(self) -> LiveView:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- what the page may ask -----------------------------------------------------------------
    def status(self) -> ViewStatus:
        """The stream's age on this machine's clock and whether a process is writing the run."""
        try:
            age = time.time() - self.stream.stat().st_mtime
        except OSError:
            age = None
        holder = live.run_holder(self.run_path)
        return {"now": time.time(), "stream_age_s": age, "running": holder is not None,
                "stale_s": live.STALE_S}

    def stop(self, when: str) -> StopReply:
        """Ask the run to stop after its point (``"point"``) or at once (``"now"``, SIGINT)."""
        holder = live.run_holder(self.run_path)
        if holder is None:
            return {"ok": False, "error": "no process is writing this run (it has ended)"}
        pid, host = int(holder.get("pid") or 0), str(holder.get("host") or "")
        if host and host != socket.gethostname():
            return {"ok": False, "error": f"the run is on {host}: stop it there"}
        text = "Stop after this point (labkit view)" if when == "point" else "Stop now (labkit view)"
        live.stop_path(self.run_path).write_text(text + "\n", encoding="utf-8")
        if when == "now":
            os.kill(pid, signal.SIGINT)        # the run's own Ctrl-C path: drive off, file finished
        return {"ok": True, "sent": text, "pid": pid}


class _Handler(BaseHTTPRequestHandler):
    view: LiveView
    protocol_version = "HTTP/1.1"
    server_version = "labkit-view"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the stdlib's name
        pass                                  # quiet: the console belongs to the person

    # -- checks --------------------------------------------------------------------------------
    def _host_ok(self) -> bool:
        return self.headers.get("Host", "") in self.view.hosts

    def _token_ok(self, given: str | None) -> bool:
        return bool(given) and hmac.compare_digest(str(given).encode(), self.view.token.encode())

    def _refuse(self, code: HTTPStatus, why: str) -> None:
        self._send(code, json.dumps({"ok": False, "error": why}).encode(), "application/json")

    def _send(self, code: HTTPStatus, body: bytes, ctype: str) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        for k, v in SECURITY_HEADERS.items():
            self.send_header(k, v)
        self.end_headers()
        self.wfile.write(body)

    # -- GET -----------------------------------------------------------------------------------
    def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
        if not self._host_ok():
            return self._refuse(HTTPStatus.FORBIDDEN, "wrong Host")
        url = urlsplit(self.path)
        if url.path in STATIC:
            name, ctype = STATIC[url.path]
            return self._send(HTTPStatus.OK, _asset(name), ctype)
        query = parse_qs(url.query)
        if not self._token_ok(query.get("token", [""])[0]):
            return self._refuse(HTTPStatus.FORBIDDEN, "missing or wrong token (open the URL labkit view printed)")
        if url.path == "/":
            return self._send(HTTPStatus.OK, _asset(PAGE[0]), PAGE[1])
        if url.path == "/events":
            start = self.headers.get("Last-Event-ID") or (query.get("from") or ["0"])[0]
            return self._events(int(start) if str(start).isdigit() else 0)
        if url.path == "/status":
            return self._send(HTTPStatus.OK, json.dumps(self.view.status()).encode(), "application/json")
        return self._refuse(HTTPStatus.NOT_FOUND, "no such page")

    def _events(self, offset: int) -> None:
        """Server-Sent Events: the stream's lines from ``offset`` on, and a status event every second."""
        self.send_response(HTTPStatus.OK)
        self.send_header("Content-Type", "text/event-stream")
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        self.close_connection = True
        next_status, speeds = 0.0, 0
        tracker = self.view.tracker
        try:
            while not self.view.closing.is_set():
                out = []
                for end, rec in live.follow(self.view.stream, offset, wait=False):
                    out.append(f"id: {end}\ndata: {json.dumps(rec, allow_nan=False)}\n\n")
                    offset = end
                for speed in (tracker.results[speeds:] if tracker is not None else []):
                    out.append(f"event: speed\ndata: {json.dumps(speed, allow_nan=False)}\n\n")
                    speeds += 1
                if time.monotonic() >= next_status:
                    out.append(f"event: status\ndata: {json.dumps(self.view.status())}\n\n")
                    next_status = time.monotonic() + STATUS_S
                if out:
                    self.wfile.write("".join(out).encode())
                    self.wfile.flush()
                time.sleep(0.1)
        except (BrokenPipeError, ConnectionResetError, OSError):
            return

    # -- POST ----------------------------------------------------------------------------------
    def do_POST(self) -> None:  # noqa: N802 - the stdlib's name
        if not self._host_ok():
            return self._refuse(HTTPStatus.FORBIDDEN, "wrong Host")
        if self.headers.get("Origin", "") != f"http://{self.headers.get('Host')}":
            return self._refuse(HTTPStatus.FORBIDDEN, "wrong or missing Origin")
        if not self._token_ok(self.headers.get("X-Labkit-Token")):
            return self._refuse(HTTPStatus.FORBIDDEN, "missing or wrong token")
        if urlsplit(self.path).path != "/stop":
            return self._refuse(HTTPStatus.NOT_FOUND, "no such action")
        if not self.headers.get("Content-Type", "").startswith("application/json"):
            return self._refuse(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, "expected application/json")
        try:
            n = min(int(self.headers.get("Content-Length") or 0), 4096)
            when = json.loads(self.rfile.read(n) or b"{}").get("when")
        except (ValueError, AttributeError):
            when = None
        if when not in ("point", "now"):
            return self._refuse(HTTPStatus.BAD_REQUEST, 'expected {"when": "point"} or {"when": "now"}')
        result = self.view.stop(when)
        code = HTTPStatus.OK if result["ok"] else HTTPStatus.CONFLICT
        self._send(code, json.dumps(result).encode(), "application/json")
