"""``labkit view RUN.h5``: a run's live page in the browser, served on this computer only.

Serves the page of the run's live stream (``RUN.live.jsonl``, written by every
run beside its run file) on 127.0.0.1 and prints its URL, which holds a secret
token: only a page opened from that URL can stop the run. From another computer,
forward the port (``ssh -L PORT:127.0.0.1:PORT host``) and open the same URL.
Works for a run started from any terminal, joins a run late (the page replays
the stream from its start), and replays a finished run. The page's Stop
buttons: "after this point" (the run stops before its next point) and "now"
(SIGINT to the run: its drive goes off and its file is finished, as on
Ctrl-C); both end the run with exit 130 and leave it resumable (``--resume``).
Shaker runs with video: each point's video is tracked as it appears (the robot's
speed, as ``labkit track`` measures it, at low priority; ``--no-track`` not).
Serves until Ctrl-C; nothing is sent to any instrument.
"""
from __future__ import annotations

import argparse
import sys
from typing import TypedDict


class ViewSummary(TypedDict):
    """``labkit view --json``'s first line: where the page is served and what it shows."""

    url: str
    file: str
    stream: str
    port: int

NAME = "view"
HELP = "a run's live page in the browser (FRF building up, drive lamp, events, Stop), on 127.0.0.1"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="RUN.h5", help="the run file (or its RUN.live.jsonl)")
    parser.add_argument("--port", type=int, default=0, help="TCP port on 127.0.0.1 (default: any free one)")
    parser.add_argument("--open", action="store_true", help="also open the page in the default browser")
    parser.add_argument("--no-track", action="store_true",
                        help="do not track shaker points' videos (the robot's speed) as they appear")


def run(args: argparse.Namespace) -> ViewSummary:
    from labkit.cli import emit_json
    from labkit.errors import InputError, Interrupted
    from labkit.experiments.liveview import LiveView
    from labkit.experiments.safety import stop_handled

    if not 0 <= args.port <= 65535:
        raise InputError(f"{args.port}", key="--port", expected="a TCP port, 0..65535 (0: any free one)")
    try:
        view = LiveView(args.run, port=args.port, track_videos=not args.no_track)
    except OSError as exc:
        raise InputError(f"cannot listen on 127.0.0.1:{args.port} ({exc.strerror or exc})", key="--port",
                         expected="a free port, or 0") from None
    out: ViewSummary = {"url": view.url, "file": str(view.run_path), "stream": str(view.stream), "port": view.port}
    try:
        if args.json:
            emit_json(out)              # the first line: how a script (or a test) finds the page
        else:
            print(f"live view of {view.run_path.name}: {view.url}", flush=True)
            import socket

            print("(this computer only; from elsewhere: ssh -L "
                  f"{view.port}:127.0.0.1:{view.port} {socket.gethostname()}, then the same URL; "
                  "Ctrl-C to stop serving)", file=sys.stderr, flush=True)
        if args.open:
            import webbrowser

            webbrowser.open(view.url)
        view.serve_forever()
    except (KeyboardInterrupt, Interrupted):     # Ctrl-C is how serving ends: not an error
        stop_handled()
    finally:
        view.close()
    return out
