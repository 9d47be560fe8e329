"""The virtual lab: simulated instruments on real transports, driven by the project's physics.

Wiring (what a person would have cabled on the bench)
-----------------------------------------------------
* generator channel 1 -> the robot's PZT (``inchip``) or the amplifier input
  (``shaker``); its sync output -> the scope's EXT trigger input;
* scope channel 1 <- generator channel 1 (the drive, volts at the high-Z load);
* scope channel 2 <- the vibrometer's analog output at the laser spot
  (velocity / scale factor, clipped at +-10 V);
* scope channel 3 <- (``shaker``) a reference vibrometer on the tray, same
  scale factor; in-chip it only carries noise; channel 4: noise.

Time is the wall clock (``time.monotonic``): settings take effect when they
are received and the scope acquires in real time. After a change of the
drive (frequency, amplitude, output on, ...) the structure is taken to start
from rest; responses are computed with their transients until they have
decayed (12 time constants of the slowest mode), then analytically (sine).
"""
from __future__ import annotations

import itertools
import os
import tempfile
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.errors import ConfigError
from labkit.jsonutil import Json
from labkit.lab import camera
from labkit.lab.control import LabTruth, SimLabControl
from labkit.lab.funcgen import Drive, SimAgilent33220A, SimKeysight33500B, SimRigolDG1000Z
from labkit.lab.miswire import Miswiring
from labkit.lab.models import FUNCGEN_MODELS, SCOPE_MODELS, TWO_CHANNEL_SCOPES, VIBROMETER_MODELS
from labkit.lab.physics import SPOTS, ShakerChain, TetheredModel, simulate_linear
from labkit.lab.scope import SimInfiniiVision, SimRigolDS1000Z
from labkit.lab.transport import Fault, PtyServer, TcpServer
from labkit.lab.vibrometer import FULL_SCALE_V, SimOFV3001, SimOFV5000

if TYPE_CHECKING:
    from labkit.lab.hislip import HislipServer
    from labkit.lab.vxi11 import Vxi11Server

SETUPS = ("inchip", "shaker")
#: the lab's log keeps this many entries (the newest), each text at most LOG_TEXT_CHARS long
LOG_ENTRIES = 20_000
LOG_TEXT_CHARS = 240

LogEntry = tuple[float, str, str, str]


class LogRing:
    """The lab's log: the newest :data:`LOG_ENTRIES` entries ``(t_s, instrument, direction, text)``.

    ``len()`` and indices count every entry ever appended, so ``log[n:]`` is what came
    after the first ``n`` (less whatever has been dropped since); iteration sees a copy.
    """

    def __init__(self, maxlen: int = LOG_ENTRIES) -> None:
        self._entries: deque[LogEntry] = deque(maxlen=maxlen)
        self._count = 0
        self._lock = threading.Lock()

    def append(self, entry: LogEntry) -> None:
        with self._lock:
            self._entries.append(entry)
            self._count += 1

    def __len__(self) -> int:
        return self._count

    def _kept(self) -> tuple[int, list[LogEntry]]:
        with self._lock:
            return self._count - len(self._entries), list(self._entries)

    def __iter__(self) -> Iterator[LogEntry]:
        return iter(self._kept()[1])

    def __getitem__(self, key: int | slice) -> Any:
        first, kept = self._kept()
        if isinstance(key, slice):
            start, stop, step = key.indices(self._count)
            return [kept[i - first] for i in range(start, stop, step) if i >= first]
        i = key + self._count if key < 0 else key
        if not first <= i < self._count:
            raise IndexError("log entry dropped or not yet written")
        return kept[i - first]


def _pick(role: str, model: str, table: dict[str, str]) -> str:
    key = str(model).strip().upper()
    for name in table:
        if name.upper() == key:
            return name
    raise ConfigError(f"the virtual lab has no {role} {model!r}", key=f"{role}_model",
                      expected=f"one of {', '.join(table)}")


def load_robot(robot: Any) -> Any:
    """``None`` -> default :class:`RobotParams`; a path -> read the TOML; params pass through."""
    if robot is not None and not isinstance(robot, (str, Path)):
        return robot
    try:
        from labkit.sim import RobotParams
    except ImportError as exc:  # the simulator package is missing or broken
        if robot is None:
            return None
        raise ConfigError(f"cannot read robot parameters: labkit.sim unavailable ({exc})", file=robot) from None
    if robot is None:
        return RobotParams()
    return RobotParams.from_toml(robot)


#: numbers the labs of this process (each lab's instruments get serial numbers of their own)
_BENCHES = itertools.count(1)


def _own_serial(idn: str, bench: str) -> str:
    """``*IDN?`` with ``-<bench>`` after its serial number (the third field)."""
    parts = idn.split(",")
    if len(parts) >= 3:
        parts[2] = f"{parts[2]}-{bench}"
    return ",".join(parts)


class VirtualLab:
    """Start the simulated generator, scope, vibrometer controller and the control channel.

    By default a Keysight 33522B, an InfiniiVision DSOX3024T and an OFV-5000;
    ``funcgen_model`` (:data:`FUNCGEN_MODELS`: 33511B/33512B/33521B/33522B,
    DG1022Z/DG1032Z/DG1062Z, 33220A), ``scope_model`` (:data:`SCOPE_MODELS`)
    and ``vibrometer_model`` (OFV-5000, OFV-3001) pick others, so every
    driver in :mod:`labkit.drivers` has a counterpart; :attr:`models` names
    the driver model for each role.

    Parameters
    ----------
    robot:
        None (default parameters), a parameter-file path, or a ``RobotParams``.
    seed:
        Seed of every random draw (noise, garbage faults).
    tether_hz, tether_damping, knee_hz, knee_damping:
        The in-chip-only modes (the hip mode comes from the robot parameters).
    shapes_mm_s_per_v:
        Peak mobility per spot and mode (see :mod:`labkit.lab.physics`).
    amplifier_gain_db, shaker_accel_m_s2_per_v:
        The declared amplifier gain and the shaker's sensitivity.
    noise_v_rms, noise_mm_s_rms:
        Scope input noise (volts) and vibrometer noise floor (mm/s).
    sim_duration_s:
        Length of each cached shaker simulation.
    scope_memory_points:
        The scope's acquisition memory (a record has the requested
        ``:WAVeform:POINts``, at most this many).

    Attributes
    ----------
    log:
        ``(t_s, instrument, kind, text)`` since the lab started: ``kind`` is
        ``"rx"`` (a line received), ``"tx"`` (a reply sent; binary blocks
        summarised), ``"fault"`` (an injected fault acted), ``"state"`` (spot,
        set-up, camera), ``"error"`` (a simulation failed) or ``"warning"`` (a simulation
        chaotic or not converged).
    burst_timeline:
        ``(start_s, instrument, channel, end_s)`` of every triggered (BUS, EXT)
        burst: ``end_s`` is when the output fell silent by itself after its
        cycles, or when the burst was cut short (output off, burst off,
        ``*RST``, a setting change); inf for ``BURS:NCYC INF``.
    output_timeline:
        ``(t_s, instrument, channel, on)``: the initial states at t = 0, then
        every change (``OUTP``, ``*RST``, ``APPLy``, the lab's shutdown).

    Examples
    --------
    >>> with VirtualLab(seed=1) as lab:            # doctest: +SKIP
    ...     lab.set_spot("knee")
    ...     print(lab.resources["scope"])
    """

    def __init__(self, robot: Any = None, seed: int = 0, *, tether_hz: float = 830.0,
                 tether_damping: float = 0.02, knee_hz: float = 3400.0, knee_damping: float = 0.015,
                 shapes_mm_s_per_v: dict[str, tuple[float, float, float]] | None = None,
                 amplifier_gain_db: float = 20.0, shaker_accel_m_s2_per_v: float = 20.0,
                 noise_v_rms: float = 5e-4, noise_mm_s_rms: float = 0.01,
                 sim_duration_s: float = 1.0, scope_memory_points: int = 1_000_000,
                 funcgen_model: str = "33522B", scope_model: str = "DSOX3024T",
                 vibrometer_model: str = "OFV-5000", miswire: Miswiring | None = None,
                 vxi11: bool = False, hislip: bool = False) -> None:
        self.seed = int(seed)
        self.miswire = miswire or Miswiring()
        self.params = load_robot(robot)
        hip_hz, hip_zeta = 438.0, 0.25
        if self.params is not None:
            hip_hz = float(self.params.modal_freq_hz[0])
            hip_zeta = float(self.params.modal_damping_ratio[0])
        self.model = TetheredModel(freq_hz=(hip_hz, float(tether_hz), float(knee_hz)),
                                   damping_ratio=(hip_zeta, float(tether_damping), float(knee_damping)))
        if shapes_mm_s_per_v is not None:
            self.model = replace(self.model, shapes_mm_s_per_v=dict(shapes_mm_s_per_v))
        self.chain = ShakerChain(amplifier_gain_db=float(amplifier_gain_db),
                                 accel_m_s2_per_v=float(shaker_accel_m_s2_per_v))
        self.noise_v_rms = float(noise_v_rms)
        self.noise_mm_s_rms = float(noise_mm_s_rms)
        self.sim_duration_s = float(sim_duration_s)
        self._spot = "knee"
        self._setup = "inchip"
        self._state_lock = threading.Lock()
        self._sim_cache: OrderedDict[tuple[float, float], Any] = OrderedDict()
        self._sim_lock = threading.Lock()
        self.log = LogRing()
        self.output_timeline: list[tuple[float, str, int, bool]] = []
        self.t0 = time.monotonic()
        self.servers: dict[str, TcpServer | PtyServer] = {}
        #: VXI-11 servers of the generator and the scope (``vxi11=True``; needs root for port 111)
        self.vxi11 = bool(vxi11)
        self.vxi11_servers: dict[str, Vxi11Server] = {}
        #: HiSLIP servers of the generator and the scope (``hislip=True``; ephemeral ports, no root)
        self.hislip = bool(hislip)
        self.hislip_servers: dict[str, HislipServer] = {}
        self.camera_fps = 30.0
        self.last_recording: camera.Recording | None = None
        #: clips filmed so far: the camera's noise and frame jitter are drawn from (seed, take), so a
        #: lab with the same seed films the same clips whatever the timing of the queries around them
        self.takes = 0
        #: the only folder the camera writes to (``CAM:REC "<file name>"``); a fresh one per lab
        self.recordings_dir = Path(tempfile.mkdtemp(prefix="labkit-lab-camera-"))

        self.burst_timeline: list[tuple[float, str, int, float]] = []
        fg_model = _pick("funcgen", funcgen_model, FUNCGEN_MODELS)
        sc_model = _pick("scope", scope_model, SCOPE_MODELS)
        vib_model = _pick("vibrometer", vibrometer_model, VIBROMETER_MODELS)
        #: driver model names (labkit.drivers) of the simulated instruments, by role
        self.models = {"funcgen": FUNCGEN_MODELS[fg_model], "scope": SCOPE_MODELS[sc_model],
                       "vibrometer": VIBROMETER_MODELS[vib_model]}
        fg_class = {"33500B": SimKeysight33500B, "DG1000Z": SimRigolDG1000Z,
                    "33220A": SimAgilent33220A}[self.models["funcgen"]]
        self.funcgen = fg_class(on_output=lambda ch, on: self._output("funcgen", ch, on),
                                on_burst=lambda ch, t0, t1: self._burst("funcgen", ch, t0, t1), model=fg_model)
        # each lab is a bench of its own: its instruments' serial numbers say so (runs lock them by identity)
        bench = f"{os.getpid()}x{next(_BENCHES)}"
        self.funcgen.idn = _own_serial(self.funcgen.idn, bench)
        sc_class = SimRigolDS1000Z if self.models["scope"] == "DS1000Z" else SimInfiniiVision
        self.scope = sc_class(self._signals, self._sync, seed=self.seed, memory_points=scope_memory_points)
        self.scope.idn = self.scope.idn.replace("DSOX3024T", sc_model).replace("DS1104Z", sc_model)
        self.scope.idn = _own_serial(self.scope.idn, bench)
        if sc_model in TWO_CHANNEL_SCOPES:
            self.scope.suffix_limits = {"CHAN": 2}
        vib_class = SimOFV3001 if vib_model == "OFV-3001" else SimOFV5000
        self.vibrometer: SimOFV5000 | SimOFV3001 = vib_class(self.spot_peak_velocity_mm_s)
        if self.miswire.vibrometer_range_mm_s_per_v is not None:
            self.vibrometer.lock_range(self.miswire.vibrometer_range_mm_s_per_v)
        self.control = SimLabControl(self)
        for ch in self.funcgen.ch:
            self.output_timeline.append((0.0, "funcgen", ch, False))
        self._started = False

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> VirtualLab:
        if self._started:
            return self
        self.servers = {
            "funcgen": TcpServer(self.funcgen, self._log, seed=self.seed + 1),
            "scope": TcpServer(self.scope, self._log, seed=self.seed + 2),
            "vibrometer": PtyServer(self.vibrometer, self._log, seed=self.seed + 3),
            "control": TcpServer(self.control, self._log, seed=self.seed + 4),
        }
        for server in self.servers.values():
            server.start()
        if self.vxi11:
            from labkit.lab.vxi11 import Vxi11Server

            for name in ("funcgen", "scope"):
                vx = Vxi11Server(self.servers[name])
                vx.start()
                self.vxi11_servers[name] = vx
        if self.hislip:
            from labkit.lab.hislip import HislipServer

            for name in ("funcgen", "scope"):
                hs = HislipServer(self.servers[name])
                hs.start()
                self.hislip_servers[name] = hs
        # compiled once the transports are bound (a refused port 111 ends the start without the wait);
        # clients learn the resources only when start() has returned
        self._warm_simulator()
        self._started = True
        return self

    def close(self) -> None:
        """Stop every server; outputs are switched off first (logged in the timeline)."""
        for ch in list(self.funcgen.ch):
            with self.funcgen.lock:
                self.funcgen._set_output(ch, False)
        self.scope.close()
        for vx in self.vxi11_servers.values():
            vx.close()
        for hs in self.hislip_servers.values():
            hs.close()
        self.vxi11_servers, self.hislip_servers = {}, {}
        for server in self.servers.values():
            server._stop.set()   # every server winds down at once, then each is joined
        for server in self.servers.values():
            server.close()
        self._started = False
        import shutil
        shutil.rmtree(self.recordings_dir, ignore_errors=True)    # clips not moved out are the lab's

    def __enter__(self) -> VirtualLab:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def resources(self) -> dict[str, str]:
        """VISA resource strings of the instruments and of the control channel."""
        return {name: server.resource for name, server in self.servers.items()}

    @property
    def hislip_resources(self) -> dict[str, str]:
        """``TCPIP0::127.0.0.1::hislip0,<port>::INSTR`` of the generator and the scope (``hislip=True``)."""
        return {name: server.resource for name, server in self.hislip_servers.items()}

    @property
    def vxi11_resources(self) -> dict[str, str]:
        """``TCPIP0::127.x.y.z::inst0::INSTR`` of the generator and the scope (with ``vxi11=True``)."""
        return {name: server.resource for name, server in self.vxi11_servers.items()}

    # -- the person at the bench ----------------------------------------------------------------
    def set_spot(self, spot: str) -> None:
        """Point the laser at ``body``, ``hip``, ``knee`` or ``tray``."""
        spot = str(spot).strip().lower()
        if spot not in SPOTS:
            raise ValueError(f"spot must be one of {', '.join(SPOTS)}, not {spot!r}")
        with self._state_lock:
            self._spot = spot
        self._log("lab", "state", f"spot {spot}")

    @property
    def spot(self) -> str:
        return self._spot

    def set_setup(self, setup: str) -> None:
        """``inchip`` (generator -> PZT of the tethered robot) or ``shaker`` (-> amplifier -> shaker)."""
        setup = str(setup).strip().lower()
        if setup not in SETUPS:
            raise ValueError(f"setup must be one of {', '.join(SETUPS)}, not {setup!r}")
        with self._state_lock:
            self._setup = setup
        self._log("lab", "state", f"setup {setup}")

    @property
    def setup(self) -> str:
        return self._setup

    def inject_fault(self, instrument: str, kind: str = "drop", after: int = 0, match: str | None = None,
                     count: int = 1, interval_s: float = 0.5) -> Fault:
        """Arm a fault on ``instrument``'s replies (see :class:`labkit.lab.transport.Fault`).

        ``after`` replies (to commands containing ``match``, if given) go out
        normally first; the next ``count`` are dropped mid-transfer, withheld
        (``stall``), replaced by ``garbage`` or sent a byte every ``interval_s``
        (``trickle``).
        """
        if instrument not in self.servers:
            raise ValueError(f"instrument must be one of {', '.join(self.servers)}, not {instrument!r}")
        fault = Fault(kind, int(after), match, int(count), float(interval_s))
        self.servers[instrument].inject(fault)
        self._log("lab", "state", f"fault armed on {instrument}: {kind} after {after} (match {match!r})")
        return fault

    def clear_faults(self, instrument: str | None = None) -> None:
        for name, server in self.servers.items():
            if instrument in (None, name):
                server.clear_faults()

    # -- the camera -----------------------------------------------------------------------------
    def record_video(self, path: str | Path, duration_s: float) -> dict[str, Json]:
        """Film ``duration_s`` of the robot at :attr:`camera_fps` to ``path``; keep it as :attr:`last_recording`.

        The lab hands the camera what it needs (the simulator's run for the
        present drive, whether the tray shakes); the camera knows nothing of the lab.
        """
        drive = self.funcgen.drive(1)
        shaker = self.setup == "shaker"
        sim = None
        now = time.monotonic()
        # a sine, also in bursts: the robot walks while the drive carries the sine (until the
        # end of a triggered burst, if that comes within the clip), then stands
        moving = shaker and drive.sine_like() and drive.active(now)
        if moving:
            sim = self._simulation(drive.freq_hz, self.chain.tray_amp_um(drive.freq_hz, drive.amp_v))
        rec = camera.record(path, duration_s, fps=self.camera_fps, seed=self.seed, take=self.takes,
                            sim=sim, shaking=shaker and drive.active(now),
                            move_s=drive.idle_after() - now if moving else float("inf"))
        self.last_recording = rec
        self.takes += 1
        self._log("camera", "state", f"recorded {rec.frames} frames to {rec.path} (speed {rec.speed_mm_s:.3f} mm/s)")
        return {"path": rec.path, "frames": rec.frames, "timestamps_s": list[Json](rec.timestamps_s)}

    # -- records --------------------------------------------------------------------------------
    def now_s(self) -> float:
        return time.monotonic() - self.t0

    def _log(self, instrument: str, direction: str, text: str) -> None:
        if len(text) > LOG_TEXT_CHARS:      # a 1 MiB line is logged by its start and its length
            text = text[:LOG_TEXT_CHARS] + f"...<{len(text)} chars>"
        self.log.append((self.now_s(), instrument, direction, text))

    def _output(self, instrument: str, channel: int, on: bool) -> None:
        self.output_timeline.append((self.now_s(), instrument, channel, on))

    def _burst(self, instrument: str, channel: int, start: float, end: float) -> None:
        """A triggered burst started (or, for the same start, was cut short): keep its lab times."""
        start_s, end_s = start - self.t0, end - self.t0
        for i in range(len(self.burst_timeline) - 1, -1, -1):
            t, inst, ch, _ = self.burst_timeline[i]
            if inst == instrument and ch == channel:
                if abs(t - start_s) < 1e-9:
                    self.burst_timeline[i] = (t, inst, ch, end_s)
                    self._log(instrument, "state", f"burst on channel {channel} cut at {end_s:.6f} s")
                    return
                break
        self.burst_timeline.append((start_s, instrument, channel, end_s))
        self._log(instrument, "state", f"burst on channel {channel} from {start_s:.6f} s to {end_s:.6f} s")

    def output_volts(self, channel: int = 1) -> float:
        """The generator's ``channel`` output now, volts into its high-impedance load (0 when off)."""
        with self.funcgen.lock:
            return float(self.funcgen.drive(channel).voltage(np.array([time.monotonic()]))[0])

    def drive_idle_after_s(self, channel: int = 1) -> float:
        """Lab time (s) after which the generator's ``channel`` carries no signal; inf if it runs on.

        Off: the moment it was switched off. A triggered burst: the end of the
        last burst, which the generator reaches by itself, whatever happens to
        the client that triggered it. A continuous or internally repeated
        waveform: inf.
        """
        with self.funcgen.lock:
            return self.funcgen.drive(channel).idle_after() - self.t0

    def output_state(self, instrument: str = "funcgen", channel: int = 1) -> bool:
        """The latest state of one output in :attr:`output_timeline`."""
        states = [on for _, inst, ch, on in self.output_timeline if inst == instrument and ch == channel]
        return states[-1] if states else False

    # -- truth ----------------------------------------------------------------------------------
    @property
    def truth(self) -> LabTruth:
        """What the lab really is: modes, mode shapes, chain, robot parameters."""
        return {
            "setup": self._setup,
            "spot": self._spot,
            "seed": self.seed,
            "tethered_modes": {"names": list(self.model.names), "freq_hz": list(self.model.freq_hz),
                               "damping_ratio": list(self.model.damping_ratio)},
            "mode_shapes_mm_s_per_v": {k: list(v) for k, v in self.model.shapes_mm_s_per_v.items()},
            "frf_model": "H(f) = sum_i R_i 2 zeta_i w_i (j w) / (w_i^2 - w^2 + 2 j zeta_i w_i w), (mm/s)/V",
            "amplifier_gain_db": self.chain.amplifier_gain_db,
            "shaker_accel_m_s2_per_v": self.chain.accel_m_s2_per_v,
            "shaker_suspension_hz": self.chain.suspension_hz,
            "shaker_suspension_damping_ratio": self.chain.suspension_damping_ratio,
            "generator_source_ohm": 50.0,
            "vibrometer_full_scale_v": FULL_SCALE_V,
            "noise_v_rms": self.noise_v_rms,
            "noise_mm_s_rms": self.noise_mm_s_rms,
            "scope_channels": {"1": "drive_v (generator channel 1 at the high-Z load)",
                               "2": "vibrometer output at the spot, V",
                               "3": "tray reference vibrometer, V (shaker setup)", "4": "noise"},
            "robot": None if self.params is None else self.params.to_dict(),
        }

    def frf(self, spot: str, freq_hz: np.ndarray | float) -> np.ndarray:
        """True in-chip velocity per drive volt at ``spot``, (mm/s)/V."""
        return self.model.frf(spot, freq_hz)

    # -- physics --------------------------------------------------------------------------------
    def _linear(self, parts: list, frf: Any, drive: Drive, t_abs: np.ndarray, settle_s: float,
                f_max: float) -> np.ndarray:
        t0 = float(t_abs[0])
        if not drive.on and drive.t_epoch <= t0:
            return np.zeros(len(t_abs))
        if drive.is_sine() and drive.t_epoch <= t0 - settle_s:
            h = complex(np.ravel(frf(drive.freq_hz))[0])
            phase = 2 * np.pi * drive.freq_hz * (t_abs - drive.t_epoch) + drive.phase_rad
            return abs(h) * drive.amp_v * np.sin(phase + np.angle(h))
        t_start = max(drive.t_epoch, t0 - settle_s)
        f_top = max(f_max, drive.freq_range_hz()[1])
        return simulate_linear(parts, drive.voltage, t_abs, t_start, f_top)

    def _tray_velocity(self, drive: Drive, t_abs: np.ndarray) -> np.ndarray:
        return self._linear(self.chain.transfer(), self.chain.tray_velocity_frf, drive, t_abs,
                            self.chain.settle_s(), 200.0)

    def _spot_velocity(self, spot: str, setup: str, drive: Drive, t_abs: np.ndarray) -> np.ndarray:
        if setup == "inchip":
            if spot == "tray":
                return np.zeros(len(t_abs))
            return self._linear(self.model.transfer(spot), lambda f: self.model.frf(spot, f), drive,
                                t_abs, self.model.settle_s(), self.model.max_freq_hz())
        tray = self._tray_velocity(drive, t_abs)
        if spot == "tray":
            return tray
        return self._robot_velocity(spot, drive, t_abs, tray)

    def _signals(self) -> Any:
        """The scope's view of the bench now: a function of sample times, frozen at this moment.

        What the generator, the spot, the set-up and the decoder range are at
        the trigger is what the record shows, however late it is transferred.
        """
        with self._state_lock:
            spot, setup = self._spot, self._setup
        drive = self.funcgen.drive(1)
        scale = self.vibrometer.scale_mm_s_per_v
        delay = self.vibrometer.signal_delay_s    # the decoder's output lags the velocity

        def render(t_abs: np.ndarray, rng: np.random.Generator,
                   channels: tuple[int, ...] = (1, 2, 3, 4)) -> dict[int, np.ndarray]:
            n = len(t_abs)
            out: dict[int, np.ndarray] = {}
            for ch in channels:
                src = self.miswire.source(ch)     # the signal the cable on this input carries
                if src == 1:
                    out[ch] = drive.voltage(t_abs)
                elif src == 2 or (src == 3 and setup == "shaker"):
                    v = (self._spot_velocity(spot, setup, drive, t_abs - delay) if src == 2
                         else self._tray_velocity(drive, t_abs - delay))
                    v = v + rng.normal(0.0, self.noise_mm_s_rms, n)
                    if src == 2:
                        self.vibrometer.clipped = bool(np.max(np.abs(v)) > scale * FULL_SCALE_V)
                    out[ch] = np.clip(v / scale, -FULL_SCALE_V, FULL_SCALE_V)
                else:
                    out[ch] = np.zeros(n)
                out[ch] += rng.normal(0.0, self.noise_v_rms, n)
            return out

        return render

    def _sync(self, source: str, t_min: float) -> float | None:
        """The scope's trigger: generator sync (EXT) or a rising edge of the drive (CHAN1)."""
        drive = self.funcgen.drive(1)
        if source == "EXT":
            # EXT is cabled to the Sync connector: off (or following a silent channel), or the
            # cable pulled out (a miswired lab), no trigger
            return None if self.miswire.sync_disconnected else self.funcgen.sync_edge(t_min)
        if source == "CHAN1":
            if drive.is_sine() and drive.amp_v > 0:
                level = self.scope.trigger_level("CHAN1")
                x = (level - drive.offset_v) / drive.amp_v
                if abs(x) >= 1:
                    return None
                slope_neg = self.scope.get("trig_slope") == "NEG"
                phi = np.pi - np.arcsin(x) if slope_neg else np.arcsin(x)
                period = 1 / drive.freq_hz
                t_phi = drive.t_epoch + (phi - drive.phase_rad) / (2 * np.pi * drive.freq_hz)
                return float(t_phi + np.ceil((t_min - t_phi) / period) * period)
            return drive.next_sync(t_min)   # sweeps/bursts: taken at their start (documented)
        return None

    def spot_peak_velocity_mm_s(self) -> float:
        """Steady-state peak velocity at the spot for the current drive (over-range check)."""
        drive = self.funcgen.drive(1)
        if not drive.on:
            return 0.0
        lo, hi = drive.freq_range_hz()
        freqs = np.geomspace(max(lo, 1.0), max(hi, 1.0), 200) if hi > lo else np.array([max(lo, 1e-3)])
        peak_v = drive.amp_v    # the offset is DC: no velocity
        with self._state_lock:
            spot, setup = self._spot, self._setup
        if setup == "inchip":
            return float(np.max(np.abs(self.model.frf(spot, freqs))) * peak_v)
        tray = float(np.max(np.abs(self.chain.tray_velocity_frf(freqs))) * peak_v)
        if spot == "tray" or not drive.sine_like():
            return tray
        res = self._simulation(drive.freq_hz, self.chain.tray_amp_um(drive.freq_hz, drive.amp_v))
        if res is None:
            return tray
        _, v = self._sim_velocity(res, spot)
        return float(np.max(np.abs(v[len(v) // 3:])))

    # -- shaker: the hybrid simulator -----------------------------------------------------------
    def _warm_simulator(self) -> None:
        """Load (or compile) the simulator's kernel before any instrument serves.

        The shaker physics runs inside the servers' threads while a scope waits
        for its trigger; numba's first call compiles the kernel (~10 s with an
        empty cache, holding the GIL), long enough for an acquisition to time
        out. Done once here, the kernel is in memory and in numba's disk cache.
        """
        if self.params is None:
            return
        from labkit.sim import Shaker, simulate

        simulate(self.params, Shaker(freq_hz=240.0, amp_um=25.0), duration_s=0.005)

    def _simulation(self, freq_hz: float, amp_um: float) -> Any:
        """A cached ``labkit.sim.simulate`` of the robot on the tray (None without the simulator)."""
        if self.params is None or amp_um <= 0:
            return None
        key = (round(float(freq_hz), 6), round(float(amp_um), 4))
        with self._sim_lock:
            if key in self._sim_cache:
                self._sim_cache.move_to_end(key)
                return self._sim_cache[key]
            try:
                from labkit.sim import Shaker, simulate
                res = simulate(self.params, Shaker(freq_hz=key[0], amp_um=key[1]),
                               duration_s=self.sim_duration_s, seed=self.seed,
                               record_dt_s=1.0 / (key[0] * 64))
            except Exception as exc:  # the instrument side keeps working; the log says why
                self._log("lab", "error", f"simulate failed at {key}: {type(exc).__name__}: {exc}")
                return None
            if res.convergence is not None and res.convergence.status in ("chaotic", "not_converged"):
                # every run checks its step (docs/model.md, "Error control and validity"); say when it could not
                self._log("lab", "warning", f"simulation at {key}: {res.convergence.status} "
                                            f"(step {res.dt_s:.3g} s)")
            self._sim_cache[key] = res
            while len(self._sim_cache) > 32:
                self._sim_cache.popitem(last=False)
            return res

    def _sim_velocity(self, res: Any, spot: str) -> tuple[np.ndarray, np.ndarray]:
        """(t_s, vertical velocity in mm/s) at a spot of the simulated robot."""
        t = np.asarray(res.t_s, dtype=float)
        if spot == "knee":
            return t, np.asarray(res.knee_vz_mm_s, dtype=float)[:, 0]
        z = np.asarray(res.body_z_um, dtype=float)
        if spot == "hip":
            # leg 1's attachment: x = +half width, y = +pitch (small angles, model.md section 3)
            ang = np.asarray(res.body_angles_rad, dtype=float)
            x_um = self.params.leg_half_width_mm * 1e3
            y_um = self.params.leg_pitch_mm * 1e3
            z = z + y_um * ang[:, 0] - x_um * ang[:, 1]
        return t, np.gradient(z, t) * 1e-3

    def _robot_velocity(self, spot: str, drive: Drive, t_abs: np.ndarray, tray: np.ndarray) -> np.ndarray:
        if not drive.sine_like():
            # the hybrid simulator is run for sines only; other drives: the robot rides the tray
            return tray
        # inside a burst of a sine the robot moves as under the continuous sine, in phase with the
        # burst's own start (a documented simplification: no start-up transient); outside, it rides
        # the tray (whose response, transients included, is the linear simulation)
        inside, epoch = drive.burst_epochs(t_abs)
        f = drive.freq_hz
        res = self._simulation(f, self.chain.tray_amp_um(f, drive.amp_v))
        if res is None:
            return tray
        t_sim, v_sim = self._sim_velocity(res, spot)
        w = 2 * np.pi * f
        # the simulator's ground phase, measured, so the lab does not depend on its convention
        g = np.asarray(res.ground_z_um, dtype=float)
        phi_g = float(np.angle(np.sum(g * np.exp(-1j * w * t_sim)))) + np.pi / 2
        # the lab's tray displacement phase: drive phase + shaker phase (velocity -> displacement)
        h = complex(np.ravel(self.chain.tray_velocity_frf(f))[0])
        phi_lab = (drive.burst_phase_rad if drive.burst else drive.phase_rad) + np.angle(h) - np.pi / 2
        tau = (t_abs - epoch) + (phi_lab - phi_g) / w
        # wrap into the simulation's settled part, a whole number of drive periods long
        start = t_sim[-1] / 3
        n_per = max(1, int(np.floor((t_sim[-1] - start) * f)))
        span = n_per / f
        tau = start + np.mod(tau - start, span)
        return np.where(inside, np.interp(tau, t_sim, v_sim), tray)
