"""I/O benchmark: query round trip and 1 M-point WORD waveform throughput over loopback.

Uses the LAB engineer's :class:`labkit.lab.VirtualLab` InfiniiVision when it
imports and answers; otherwise (or with ``--own-server``) a minimal
InfiniiVision-like SCPI server in this script. Either way the client is the
real driver (:class:`labkit.drivers.scope.InfiniiVision`) over a real TCP socket
through pyvisa-py. Prints ONE JSON object; ``server`` says which was used.

    python bench/io_bench.py [--points 1000000] [--repeats 5] [--own-server]
"""
from __future__ import annotations

import argparse
import json
import socket
import statistics
import sys
import threading
import time

import numpy as np

TARGET_MB_S = 20.0


class _Server(threading.Thread):
    """A tiny InfiniiVision-like server: just enough SCPI for read_waveform."""

    def __init__(self, points: int) -> None:
        super().__init__(daemon=True)
        rng = np.random.default_rng(0)
        codes = (32768 + 20000 * np.sin(np.arange(points) * 2 * np.pi / 1000)
                 + rng.normal(0, 50, points)).astype(">u2")
        payload = codes.tobytes()
        size = str(len(payload)).encode()
        self.block = b"#" + str(len(size)).encode() + size + payload + b"\n"
        self.pre = f"1,0,{points},1,1.0E-07,0.0E+00,0,3.0E-05,0.0E+00,32768\n".encode()
        self.lsock = socket.create_server(("127.0.0.1", 0))
        self.port = self.lsock.getsockname()[1]

    def run(self) -> None:
        while True:                      # one client at a time, for as long as the bench runs
            conn, _ = self.lsock.accept()
            self._serve(conn)

    def _serve(self, conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = b""
        with conn:
            while True:
                data = conn.recv(65536)
                if not data:
                    return
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    cmd = line.strip().upper()
                    if cmd == b"*IDN?":
                        conn.sendall(b"KEYSIGHT TECHNOLOGIES,DSOX3024T,BENCH,1.0\n")
                    elif cmd.endswith(b"ERR?"):
                        conn.sendall(b'+0,"No error"\n')
                    elif cmd == b":WAV:PRE?":
                        conn.sendall(self.pre)
                    elif cmd == b":WAV:DATA?":
                        conn.sendall(self.block)


def _bench(scope_resource: str, points: int, repeats: int, n_queries: int,
           lab_points: bool = False) -> dict:
    """Time queries and ``read_waveform(1, "WORD")`` on ``scope_resource``."""
    from labkit.drivers.scope import InfiniiVision

    with InfiniiVision.open(scope_resource, timeout_s=30.0, points=points) as sc:
        sc.identity
        rtts = []
        for _ in range(n_queries):
            t0 = time.perf_counter()
            sc.query(":SYST:ERR?")
            rtts.append(time.perf_counter() - t0)
        times, n = [], 0
        for _ in range(repeats):
            t0 = time.perf_counter()
            wf = sc.read_waveform(1, "WORD")
            times.append(time.perf_counter() - t0)
            n = wf.volts.size
        if not lab_points and n != points:
            raise RuntimeError(f"got {n} points, expected {points}")
        block_s = _best_block_s(sc, repeats)
    with InfiniiVision.open(scope_resource, timeout_s=30.0, points=points,
                            fast_blocks=False) as slow:
        pyvisa_block_s = _best_block_s(slow, repeats)
    nbytes = 2 * n
    best = min(times)
    return {
        "query_rtt_us_median": 1e6 * statistics.median(rtts),
        "query_rtt_us_p95": 1e6 * float(np.percentile(rtts, 95)),
        "queries": n_queries,
        "waveform_points": n,
        "waveform_bytes": nbytes,
        "waveform_s_best": best,
        "waveform_s_median": statistics.median(times),
        "throughput_mb_s_best": nbytes / best / 1e6,
        "throughput_mb_s_median": nbytes / statistics.median(times) / 1e6,
        "repeats": repeats,
        "block_only_mb_s_best": nbytes / block_s / 1e6,
        "pyvisa_query_binary_values_block_mb_s_best": nbytes / pyvisa_block_s / 1e6,
        "note": "read_waveform = setup commands + error check + :WAV:PRE? + :WAV:DATA? + "
                "scaling; block_only = :WAV:DATA? alone (drivers' fast path: termchar off "
                "during the payload); pyvisa_query_binary_values = fast_blocks=False",
    }


def _best_block_s(sc, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        sc.query_binary(":WAV:DATA?", "H", big_endian=True)
        best = min(best, time.perf_counter() - t0)
    return best


def _virtual_lab(points: int, repeats: int, n_queries: int) -> dict:
    """Acquire one record on the VirtualLab's InfiniiVision, then time transfers of it."""
    from labkit.drivers.scope import InfiniiVision
    from labkit.lab import VirtualLab

    with VirtualLab(seed=0) as lab:
        res = lab.resources["scope"]
        with InfiniiVision.open(res, timeout_s=30.0, points=points) as sc:
            sc.setup_channel(1, 0.5)
            sc.set_timebase(0.01)
            # the lab sizes its record from the transfer settings at arm time
            sc.write(":WAV:POIN:MODE RAW")
            sc.write(f":WAV:POIN {points}")
            sc.single()
            sc.wait_done(30.0)
        return _bench(res, points, repeats, n_queries, lab_points=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--queries", type=int, default=200)
    ap.add_argument("--own-server", action="store_true", help="skip the VirtualLab")
    args = ap.parse_args(argv)

    result: dict = {"bench": "io_bench", "target_mb_s": TARGET_MB_S}
    out = None
    if not args.own_server:
        try:
            out = _virtual_lab(args.points, args.repeats, args.queries)
            result["server"] = "labkit.lab.VirtualLab InfiniiVision"
        except Exception as exc:  # the lab may not exist yet or may fail: fall back, say why
            result["virtual_lab_error"] = f"{type(exc).__name__}: {exc}"[:300]
    if out is None:
        srv = _Server(args.points)
        srv.start()
        out = _bench(f"TCPIP0::127.0.0.1::{srv.port}::SOCKET", args.points, args.repeats,
                     args.queries)
        result["server"] = "own loopback server in bench/io_bench.py"
    result.update(out)
    result["meets_target"] = result["throughput_mb_s_median"] >= TARGET_MB_S
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
