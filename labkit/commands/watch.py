"""``labkit watch RUN.h5``: a run's live stream as rows in a terminal (for SSH).

Reads only ``RUN.live.jsonl``, the stream every run writes beside its run file
(one line per point and per event, flushed as it happens): nothing is sent to
any instrument and the run file is not opened. Replays the stream from its
first line, then follows it until the run ends; a finished run is replayed and
the command returns. When no line (not even the run's heartbeat) arrives for
a few seconds it says so, with the way back (``labkit off CONFIG``); when the
process writing the run is gone, it ends.
"""
from __future__ import annotations

import argparse
import time
from typing import TYPE_CHECKING, TypedDict

if TYPE_CHECKING:
    from labkit.experiments.live import Record
    from labkit.jsonutil import Json


class WatchSummary(TypedDict):
    """``labkit watch --json``: the run, its stream, the points seen and how the run ended (None: not yet)."""

    file: str
    stream: str
    points: int
    status: Json
    exit: Json

NAME = "watch"
HELP = "follow a run's live stream as rows in the terminal (points, drive on/off, events, end)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="RUN.h5", help="the run file (or its RUN.live.jsonl)")
    parser.add_argument("--no-follow", action="store_true", help="print what the stream holds now and return")


def run(args: argparse.Namespace) -> WatchSummary:
    from labkit.experiments import live

    run_path, stream = live.stream_of(args.run)
    out: WatchSummary = {"file": str(run_path), "stream": str(stream), "points": 0, "status": None, "exit": None}
    pos, last, warned, config = 0, time.time(), False, ""
    follow = not args.no_follow
    while True:
        for end, rec in live.follow(stream, pos, wait=follow, timeout_s=live.STALE_S):
            pos, last, warned = end, time.time(), False
            _count(out, rec)
            config = str(rec.get("config") or config)
            _say(args, live.format_record(rec))
        if not follow or out["status"] is not None:
            break
        # no end record yet and no line for a while: the run is frozen, or gone
        if live.run_holder(run_path) is None:
            _say(args, f"the run writing {run_path.name} has gone without an end record (killed?): "
                       f"its drive may be on; run: labkit off {config or 'CONFIG'}")
            out["status"] = "gone"
            break
        if not warned:
            _say(args, f"run not responding: no line for {time.time() - last:.0f} s; "
                       f"if it does not recover: labkit off {config or 'CONFIG'}")
            warned = True
    return out


def _count(out: WatchSummary, rec: Record) -> None:
    if rec.get("t") == "start":          # a resumed run's stream holds one session per start
        out["status"] = out["exit"] = None
    elif rec.get("t") == "point":
        out["points"] += 1
    elif rec.get("t") == "end":
        out["status"], out["exit"] = rec.get("status"), rec.get("exit")


def _say(args: argparse.Namespace, row: str | None) -> None:
    if row and not args.json:
        print(row, flush=True)
