"""Helpers of the virtual-lab tests: fixtures, a raw-socket SCPI client, signal fits.

The fixtures live here, not in a ``conftest.py``: a second top-level-importable
``conftest`` module would shadow ``tests/conftest.py`` for modules that do
``from clihelpers import run_cli``. Test modules import them by name.
"""
from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from labkit.lab import VirtualLab


class Raw:
    """A bare TCP client: lines out, lines and IEEE 488.2 blocks in (no pyvisa)."""

    def __init__(self, resource: str, timeout_s: float = 5.0) -> None:
        _, host, port, _ = resource.split("::")
        self.sock = socket.create_connection((host, int(port)), timeout=timeout_s)
        self.buf = b""

    def write(self, text: str) -> None:
        self.sock.sendall(text.encode("ascii") + b"\n")

    def _fill(self, n: int) -> None:
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise ConnectionError(f"closed after {len(self.buf)} bytes")
            self.buf += chunk

    def readline(self) -> str:
        while b"\n" not in self.buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode("ascii")

    def query(self, text: str) -> str:
        self.write(text)
        return self.readline()

    def query_block(self, text: str) -> bytes:
        """Send ``text``; return the payload of the definite-length block it answers."""
        self.write(text)
        self._fill(2)
        assert self.buf[:1] == b"#", self.buf[:20]
        n = int(self.buf[1:2])
        self._fill(2 + n)
        size = int(self.buf[2:2 + n])
        self._fill(2 + n + size + 1)
        payload = self.buf[2 + n:2 + n + size]
        assert self.buf[2 + n + size:2 + n + size + 1] == b"\n"
        self.buf = self.buf[2 + n + size + 1:]
        return payload

    def reply(self) -> bytes:
        """The next reply: a line, or one definite-length block (its own length says where it ends),
        without the terminator."""
        self._fill(1)
        if self.buf[:1] == b"#":
            self._fill(2)
            n = int(self.buf[1:2])
            self._fill(2 + n)
            end = 2 + n + (int(self.buf[2:2 + n]) if n else 0)
        else:
            while b"\n" not in self.buf:
                self._fill(len(self.buf) + 1)
            end = self.buf.index(b"\n")
        self._fill(end + 1)
        out, self.buf = self.buf[:end], self.buf[end + 1:]
        return out

    def close(self) -> None:
        self.sock.close()


def drive_sine(fg: Raw, freq_hz: float, amp_vpp: float) -> None:
    """Program generator channel 1 for a sine into the high-Z PZT and switch it on."""
    fg.write("OUTP1:LOAD INF")
    fg.write(f"SOUR1:FUNC SIN;FREQ {freq_hz};VOLT {amp_vpp};VOLT:OFFS 0")
    fg.write("OUTP1 ON")
    assert fg.query("SYST:ERR?") == '+0,"No error"'


def fit_sine(t: np.ndarray, y: np.ndarray, freq_hz: float) -> complex:
    """Complex amplitude c of y ~ Im(c exp(j w t)) (least squares)."""
    w = 2 * np.pi * freq_hz
    m = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(m, y, rcond=None)[0]
    return complex(a, b)


def read_word(sc: Raw, ch: int) -> tuple[np.ndarray, np.ndarray]:
    """Transfer channel ``ch`` as WORD and scale it with the preamble: (t_s, volts)."""
    sc.write(f":WAV:SOUR CHAN{ch};:WAV:FORM WORD;:WAV:BYT MSBF;:WAV:UNS 1")
    pre = [float(x) for x in sc.query(":WAV:PRE?").split(",")]
    data = np.frombuffer(sc.query_block(":WAV:DATA?"), dtype=">u2")
    assert len(data) == int(pre[2])
    xinc, xorig, xref, yinc, yorig, yref = pre[4], pre[5], pre[6], pre[7], pre[8], pre[9]
    return (np.arange(len(data)) - xref) * xinc + xorig, (data - yref) * yinc + yorig


def instruments_toml(res: dict[str, str], *, scope_model: str = "InfiniiVision", scope_timeout_s: float = 10,
                     funcgen_timeout_s: float | None = None) -> str:
    """The ``[instruments.*]`` tables of an in-chip config for a lab's resources (33500B, the given
    scope driver, OFV-5000, the control channel)."""
    fg_timeout = "" if funcgen_timeout_s is None else f"timeout_s = {funcgen_timeout_s}\n"
    return f"""[instruments.funcgen]
model = "33500B"
resource = "{res['funcgen']}"
{fg_timeout}
[instruments.scope]
model = "{scope_model}"
resource = "{res['scope']}"
timeout_s = {scope_timeout_s}

[instruments.vibrometer]
model = "OFV-5000"
resource = "{res['vibrometer']}"

[instruments.control]
model = "LabControl"
resource = "{res['control']}"
"""


def decoder_lag(lab: VirtualLab, freq_hz: float) -> complex:
    """What the vibrometer decoder's signal delay does to a velocity phasor at ``freq_hz``: the
    analog output is the velocity ``signal_delay_s`` ago (7.6 us on the lab's OFV-5000)."""
    return complex(np.exp(-2j * np.pi * freq_hz * lab.vibrometer.signal_delay_s))


def settle(lab: VirtualLab) -> None:
    """Wait until the structure's transient after a drive change has died out."""
    time.sleep(lab.model.settle_s() + 0.02)


@pytest.fixture
def lab():
    with VirtualLab(seed=0) as lab:
        yield lab


@pytest.fixture
def raw(lab):
    opened: list[Raw] = []

    def connect(name: str, timeout_s: float = 20.0) -> Raw:
        client = Raw(lab.resources[name], timeout_s)
        opened.append(client)
        return client

    yield connect
    for client in opened:
        client.close()


def knee_frf_over(lab: VirtualLab, funcgen: str, scope: str) -> complex:
    """labkit's 33500B and InfiniiVision drivers at these resources measure the knee's FRF at
    3.4 kHz (sync on EXT, one triggered record); returned over the lab's truth (seen through the
    decoder's delay): 1 when the link carried every setting and sample faithfully."""
    from labkit.drivers.funcgen import Keysight33500B
    from labkit.drivers.scope import InfiniiVision

    with Keysight33500B.open(funcgen, timeout_s=5, max_amp_vpp=10) as fg, \
            InfiniiVision.open(scope, timeout_s=10, points=20_000) as sc:
        fg.set_load()
        fg.enable_sync()
        fg.set_sine(3400.0, 2.0)
        fg.output(True)
        lab.set_spot("knee")
        settle(lab)
        sc.setup_channel(1, 0.5)
        sc.setup_channel(2, 1.0)
        sc.set_timebase(30 / 3400.0)
        sc.set_trigger("EXT", 1.0)
        sc.single()
        sc.wait_done(10)
        d, v = sc.read_waveform(1), sc.read_waveform(2)
    h = fit_sine(v.t_s, v.volts * lab.vibrometer.scale_mm_s_per_v, 3400.0) / fit_sine(d.t_s, d.volts, 3400.0)
    return complex(h / (complex(lab.frf("knee", 3400.0)) * decoder_lag(lab, 3400.0)))
