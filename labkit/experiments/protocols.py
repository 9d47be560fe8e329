"""What the rig, the runner and the drive guard need from each instrument (``typing.Protocol``).

The experiments are typed against these, not against driver classes: any
object with these methods fits (the drivers in :mod:`labkit.drivers`, the
virtual lab's clients, a test double at a transport's edge). Nothing here
imports a driver. A ``snapshot()`` (identity and settings) is a JSON value: it is written
to the run file as the instrument's ``snapshot_json``.

==========================  ==============================================================
protocol                    satisfied by
==========================  ==============================================================
:class:`FunctionGenerator`  ``labkit.drivers.funcgen.{Agilent33220A,Keysight33500B,RigolDG1000Z}``
:class:`Scope`              ``labkit.drivers.scope.{InfiniiVision,RigolDS1000Z}``
:class:`Vibrometer`         ``labkit.drivers.vibrometer.{OFV3001,OFV5000}``
:class:`Camera`             ``labkit.drivers.camera.{OpenCVCamera,FileCamera}``, ``labkit.lab.client.LabCamera``
:class:`ShakerEnvelope`     ``labkit.drivers.shaker.Shaker4809Envelope``
:class:`Amplifier`          ``labkit.drivers.shaker.Amplifier2718``
:class:`SpotMover`          ``labkit.experiments.rig.{PromptSpot,LabSpot}``
==========================  ==============================================================
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from labkit.jsonutil import Json

if TYPE_CHECKING:  # pragma: no cover - only for annotations (keeps the CLI's start-up light)
    import numpy as np


@runtime_checkable
class FunctionGenerator(Protocol):
    """A generator whose output drives the PZT or the shaker amplifier.

    Limits (``max_amp_vpp``, ``max_v``, ``max_freq_hz``) are checked by the
    driver before anything is sent.
    """

    name: str
    state: dict[str, Json]

    def set_load_high_z(self) -> None: ...

    def set_load(self) -> None: ...

    def enable_sync(self) -> None: ...

    def set_sine(self, freq_hz: float, amp_vpp: float, offset_v: float = 0.0) -> None: ...

    def set_frequency(self, freq_hz: float) -> None: ...

    def set_amplitude(self, amp_vpp: float) -> None: ...

    def output(self, on: bool) -> None: ...

    @property
    def output_on(self) -> bool: ...

    def set_sweep(self, start_hz: float, stop_hz: float, time_s: float, spacing: str = "LIN",
                  trigger_source: str = "IMM") -> None: ...

    def sweep_off(self) -> None: ...

    def burst(self, ncycles: int, trigger_source: str = "BUS", start_phase_deg: float | None = None) -> None: ...

    def burst_off(self) -> None: ...

    def trigger(self) -> None: ...

    def safe_off(self) -> None: ...

    def snapshot(self) -> dict[str, Json]: ...

    def close(self) -> None: ...


class Waveform(Protocol):
    """One channel's record: volts and the sample interval."""

    volts: np.ndarray
    xinc_s: float


@runtime_checkable
class Scope(Protocol):
    """A digitiser of the drive and the vibrometer's analog output."""

    model: str
    poll_s: float
    record_delay: bool          # set_record_delay works on this model

    def setup_channel(self, ch: int, volts_per_div: float, offset_v: float = 0.0,
                      coupling: str = "DC") -> None: ...

    def set_timebase(self, record_s: float) -> None: ...

    def set_trigger(self, source: str = "CHAN1", level_v: float = 0.0, slope: str = "POS") -> None: ...

    def set_record_points(self, points: int) -> None: ...

    def set_averaging(self, count: int) -> None: ...

    def set_trigger_at_start(self, record_s: float) -> None: ...

    def set_record_delay(self, record_s: float, delay_s: float) -> None: ...

    def single(self) -> None: ...

    def wait_done(self, timeout_s: float = 10.0) -> None: ...

    def read_waveform(self, ch: int, fmt: str = "WORD") -> Any: ...

    def snapshot(self) -> dict[str, Json]: ...

    def close(self) -> None: ...


@runtime_checkable
class Vibrometer(Protocol):
    """A laser Doppler vibrometer controller: its decoder's scale factor and over-range flag."""

    scale_mm_s_per_v: float
    signal_delay_s: float

    def over_range(self) -> bool: ...

    def snapshot(self) -> dict[str, Json]: ...

    def close(self) -> None: ...


@runtime_checkable
class Camera(Protocol):
    """A camera that films for a while into a video file (frames keep their own times)."""

    def record(self, path: str | Path, duration_s: float) -> dict[str, Json]: ...

    def snapshot(self) -> dict[str, Json]: ...

    def close(self) -> None: ...


@runtime_checkable
class ShakerEnvelope(Protocol):
    """A shaker's operating envelope (stroke, velocity, force, frequency range)."""

    @property
    def freq_min_hz(self) -> float: ...

    @property
    def freq_max_hz(self) -> float: ...

    def check(self, freq_hz: float, disp_amp_um: float, payload_kg: float = 0.0) -> dict[str, float]: ...

    def max_disp_amp_um(self, freq_hz: float, payload_kg: float = 0.0) -> float: ...

    def snapshot(self) -> dict[str, Json]: ...


@runtime_checkable
class Amplifier(Protocol):
    """A power amplifier with declared (front-panel) settings and an input cap."""

    @property
    def gain_db(self) -> float: ...

    @property
    def max_input_vpp(self) -> float: ...

    @property
    def voltage_gain(self) -> float: ...

    def check_input(self, amp_vpp: float) -> float: ...

    def snapshot(self) -> dict[str, Json]: ...


class SpotMover(Protocol):
    """Points the laser vibrometer at a spot (asks the person, or tells the virtual lab)."""

    def move(self, spot: str) -> None: ...
