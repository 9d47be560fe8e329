"""One rig, one run, however the config spells the rig.

A run holds the virtual lab's instruments (here: this process, through the same locks a run
takes); a second ``labkit sweep`` in another process, with another user's runtime folder,
names an instrument four other ways. Each is refused with exit 2 naming the holder, and the
generator receives no OFF (no command at all, or only the identity query when the instrument
could only be recognised by its ``*IDN?`` serial).
"""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time

import h5py
import pytest
from labcfg import inchip_toml, on_lab_resources

from clihelpers import REPO
from labkit.experiments.locks import claim_identity, lock_run, resource_key
from labkit.lab import VirtualLab


@pytest.fixture(scope="module")
def lab():
    with VirtualLab(seed=3) as lab:
        yield lab


class _Forward:
    """A TCP port forwarder to ``127.0.0.1:port``: the same instrument at another address, and a
    link that can be cut (every connection dropped, new ones refused) for a while."""

    def __init__(self, port: int) -> None:
        self.srv = socket.create_server(("127.0.0.1", 0))
        self.port = self.srv.getsockname()[1]
        self.stop = threading.Event()
        self.down_until = 0.0
        self.socks: list[socket.socket] = []
        threading.Thread(target=self._serve, args=(port,), daemon=True).start()

    def cut(self, seconds: float) -> None:
        self.down_until = time.monotonic() + seconds
        for s in list(self.socks):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    @staticmethod
    def _pump(a: socket.socket, b: socket.socket) -> None:
        try:
            while data := a.recv(65536):
                b.sendall(data)
        except OSError:
            pass
        finally:
            for s in (a, b):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def _serve(self, port: int) -> None:
        srv: socket.socket | None = self.srv
        while not self.stop.is_set():
            if time.monotonic() < self.down_until:
                if srv is not None:             # the link is down: connections refused
                    srv.close()
                    srv = None
                time.sleep(0.01)
                continue
            if srv is None:
                srv = socket.create_server(("127.0.0.1", self.port))
            srv.settimeout(0.05)
            try:
                client, _ = srv.accept()
            except TimeoutError:
                continue
            upstream = socket.create_connection(("127.0.0.1", port))
            self.socks += [client, upstream]
            threading.Thread(target=self._pump, args=(client, upstream), daemon=True).start()
            threading.Thread(target=self._pump, args=(upstream, client), daemon=True).start()
        if srv is not None:
            srv.close()


def _port(resource: str) -> int:
    return int(resource.split("::")[2])


def _config(tmp_path, lab, **spelled) -> str:
    cfg = inchip_toml(tmp_path / "c.toml", [1000.0, 2000.0], locations=("hip",))
    return str(on_lab_resources(cfg, lab, **spelled))


def _rx(lab, inst):
    return [text for _, who, kind, text in lab.log if who == inst and kind == "rx"]


def test_four_spellings_of_one_rig_are_one_rig(tmp_path, lab):
    fg, vib = lab.resources["funcgen"], lab.resources["vibrometer"]
    port = _port(fg)
    link = tmp_path / "ttyLAB"
    link.symlink_to(vib[len("ASRL"):-len("::INSTR")])
    fwd = _Forward(port)
    spellings = [
        ("funcgen", f"TCPIP::localhost::{port}::SOCKET", "resource"),        # host name, no board number
        ("funcgen", f"tcpip0::127.0.0.1::{port}::socket", "resource"),       # letter case
        ("vibrometer", f"ASRL{link}::INSTR", "resource"),                     # a symlink to the serial port
        ("funcgen", f"TCPIP0::127.0.0.1::{fwd.port}::SOCKET", "serial"),     # another address: its *IDN? serial
    ]
    assert len({resource_key(s) for _, s, why in spellings if why == "resource" and _ == "funcgen"}) == 1
    env = dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path))       # another user's runtime folder
    try:
        for role, spelling, why in spellings:
            holder_cfg = _config(tmp_path, lab)
            with lock_run([(role, lab.resources[role])], tmp_path / "first.h5", holder_cfg):
                if role == "funcgen":
                    claim_identity(role, lab.funcgen.idn, lab.resources[role])
                cfg = _config(tmp_path, lab, **{role: spelling})
                before = len(_rx(lab, role))
                second = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", cfg, "--out",
                                         str(tmp_path / "second.h5"), "--quiet"], cwd=REPO, env=env,
                                        capture_output=True, text=True, timeout=120)
            err = second.stderr.strip()
            assert second.returncode == 2 and len(err.splitlines()) == 1, (spelling, err)
            assert f"PID {os.getpid()}" in err and "in use by another run" in err, (spelling, err)
            assert f"instruments.{role}.resource" in err, err
            sent = _rx(lab, role)[before:]
            if why == "resource":
                assert sent == [], (spelling, sent)
            else:
                assert "serial" in err and not any(c.upper().startswith(("OUTP", "SOUR", "APPL")) for c in sent), sent
                assert any(c.upper().startswith("*IDN") for c in sent), sent
            assert not (tmp_path / "second.h5").exists()
    finally:
        fwd.stop.set()


def _leave_on(lab) -> None:
    """What an earlier session may leave: the generator driving, output on."""
    from labkit.drivers.registry import open_instrument

    fg = open_instrument("33500B", lab.resources["funcgen"], name="funcgen")
    try:
        fg.set_load_high_z()
        fg.set_sine(300.0, 1.0, 0.5)
        fg.output(True)
    finally:
        fg.close()
    assert lab.output_state("funcgen", 1) is True


@pytest.mark.parametrize("fault, code", [("garbage", 3), ("drop", 4)])
def test_a_generator_failing_its_handshake_with_the_output_on(tmp_path, lab, fault, code):
    """The link fails at the connect handshake (a garbled or dropped ``*IDN?`` reply) while the
    output is on from an earlier session. The run sends the OFF on a fresh link without the
    handshake: confirmed -> exit 3 and the output is off; the replies keep failing (every
    ``*OPC?`` dropped), so the OFF cannot be confirmed -> exit 4 with the banner (it was exit 3,
    no banner, output on)."""
    _leave_on(lab)
    cfg = _config(tmp_path, lab)
    if fault == "garbage":
        lab.inject_fault("funcgen", "garbage", match="*IDN")
    else:
        lab.inject_fault("funcgen", "drop", count=10_000)
    try:
        proc = subprocess.run([sys.executable, "-m", "labkit", "sweep", "inchip", cfg, "--out",
                               str(tmp_path / "run.h5"), "--quiet"], cwd=REPO, capture_output=True, text=True,
                              timeout=120)
    finally:
        lab.clear_faults("funcgen")
    assert proc.returncode == code and "Traceback" not in proc.stderr, proc.stderr
    if code == 3:
        assert lab.output_state("funcgen", 1) is False
        assert len(proc.stderr.strip().splitlines()) == 1
    else:
        assert "DRIVE MAY STILL BE ON" in proc.stderr and "failed while connecting" in proc.stderr
        assert "labkit off" in proc.stderr
    # labkit off recovers either way
    off = subprocess.run([sys.executable, "-m", "labkit", "off", cfg], cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert off.returncode == 0, off.stderr
    assert lab.output_state("funcgen", 1) is False


@pytest.mark.parametrize("down_s, code", [(1.0, 0), (6.0, 4)])
def test_a_generator_link_down_for_a_moment_is_reconnected_and_the_run_goes_on(tmp_path, lab, down_s, code):
    """The generator's link drops mid-run and refuses connections for ``down_s``. Within the
    reconnect window (2 s) the run reconnects, checks the generator (same ``*IDN?``, output read
    back off) and measures the interrupted point again: exit 0, every point once (it was exit 3
    at 1.6 s, and before that exit 4). Down longer than the window: the run gives up and its OFF
    cannot be confirmed either: exit 4 with the banner."""
    from labcfg import wait_points

    freqs = [800.0 + 100 * i for i in range(12)]
    fwd = _Forward(_port(lab.resources["funcgen"]))
    try:
        cfg = inchip_toml(tmp_path / "c.toml", freqs, locations=("hip",), timeout_s=1.0)
        cfg = on_lab_resources(cfg, lab, funcgen=f"TCPIP0::127.0.0.1::{fwd.port}::SOCKET")
        out = tmp_path / "run.h5"
        proc = subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                                 "--quiet"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            wait_points(out, 2, proc)
            fwd.cut(down_s)
            _, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == code and "Traceback" not in err, err
        with h5py.File(out, "r") as f:
            index = sorted(f["points/index"][...])
            events = list(f["events/text"].asstr()[...])
        assert len(index) == len(set(index))                       # no point twice
        if code == 0:
            assert index == list(range(len(freqs)))                # none lost
            assert any("the funcgen is back (same *IDN?)" in e for e in events), events
            assert lab.output_state("funcgen", 1) is False
        else:
            assert "DRIVE MAY STILL BE ON" in err and "labkit off" in err
    finally:
        fwd.stop.set()
