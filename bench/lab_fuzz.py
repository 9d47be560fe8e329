"""The virtual lab under hostile input: time and memory; prints ONE JSON object.

    python bench/lab_fuzz.py [--commands N] [--unterminated-mib M]

Sends, over a real socket to the simulated 33522B: a message of N relative ``SOUR1:FREQ``
commands (the SCPI path used to grow with each one), N absolute ``FREQ`` commands, twenty
1 MiB lines, and M MiB without a line end; then times a query answered after each. Reports the
seconds each took, the lab process's peak RSS (MiB) and the log's size (entries, characters).
"""
from __future__ import annotations

import argparse
import json
import resource
import socket
import time

from labkit.lab import VirtualLab


def _query(sock: socket.socket, text: str) -> str:
    sock.sendall(text.encode() + b"\n")
    buf = b""
    while not buf.endswith(b"\n"):
        buf += sock.recv(65536)
    return buf.decode().strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--commands", type=int, default=100_000)
    ap.add_argument("--unterminated-mib", type=int, default=48)
    args = ap.parse_args()
    out: dict[str, float | int] = {}
    with VirtualLab(seed=0) as lab:
        _, host, port, _ = lab.resources["funcgen"].split("::")
        with socket.create_connection((host, int(port)), timeout=600) as sock:
            cases = {
                "relative_commands_s": ";".join(["SOUR1:FREQ 1000"] * args.commands).encode(),
                "absolute_commands_s": ";".join(["FREQ 1000"] * args.commands).encode(),
                "twenty_1mib_lines_s": b"\n".join([b'DISP:TEXT "' + b"x" * (1 << 20) + b'"'] * 20),
                "unterminated_s": b"DISP:TEXT " + b"A" * (args.unterminated_mib << 20),
            }
            for key, data in cases.items():
                t0 = time.monotonic()
                sock.sendall(data + b"\n")
                _query(sock, "*CLS;*OPC?")
                out[key] = round(time.monotonic() - t0, 3)
        out["commands"] = args.commands
        out["unterminated_mib"] = args.unterminated_mib
        out["peak_rss_mib"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
        out["log_entries"] = len(lab.log)
        out["log_chars"] = sum(len(e[3]) for e in lab.log)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
