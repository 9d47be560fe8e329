"""Open an instrument by model name: ``open_instrument("33500B", resource, **settings)``."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from labkit.errors import ConfigError

if TYPE_CHECKING:
    from labkit.drivers.base import Instrument


def _models() -> dict[str, type[Instrument]]:
    from labkit.drivers.funcgen import Agilent33220A, Keysight33500B, RigolDG1000Z
    from labkit.drivers.scope import InfiniiVision, RigolDS1000Z
    from labkit.drivers.vibrometer import OFV3001, OFV5000

    classes: list[type[Instrument]] = [Agilent33220A, Keysight33500B, RigolDG1000Z, InfiniiVision,
                                       RigolDS1000Z, OFV3001, OFV5000]
    table: dict[str, type[Instrument]] = {}
    for cls in classes:
        for key in (cls.model, cls.__name__):
            table[_norm(key)] = cls
    # common spellings of the same instruments
    aliases: dict[str, type[Instrument]] = {
        "33220": Agilent33220A, "33521B": Keysight33500B, "33522B": Keysight33500B,
        "DG1022Z": RigolDG1000Z, "DG1062Z": RigolDG1000Z, "DS1054Z": RigolDS1000Z,
        "DS1104Z": RigolDS1000Z, "OFV3001": OFV3001, "OFV5000": OFV5000}
    for alias, cls in aliases.items():
        table[_norm(alias)] = cls
    return table


def _norm(name: str) -> str:
    return "".join(ch for ch in name.upper() if ch.isalnum())


def model_names() -> list[str]:
    """The canonical model names :func:`open_instrument` accepts."""
    return sorted({cls.model for cls in _models().values()}) + list(CAMERAS)


def driver_class(model: str) -> type[Instrument]:
    """The driver class for ``model`` (case, spaces and dashes ignored); ConfigError if unknown."""
    cls = _models().get(_norm(str(model)))
    if cls is None:
        raise ConfigError(f"unknown instrument model {model!r}", key="model",
                          expected=f"one of {', '.join(model_names())}")
    return cls


#: camera "models": the resource is a file path (replay) or a device index / path / URL
CAMERAS = ("file", "opencv")


def open_instrument(model: str, resource: str, **settings: Any):
    """Open ``resource`` with the driver for ``model``; settings go to the driver's ``open``.

    ``model="file"`` replays the video ``resource`` (:class:`labkit.drivers.camera.FileCamera`);
    ``model="opencv"`` opens a live camera (:class:`labkit.drivers.camera.OpenCVCamera`,
    ``resource`` a device index such as ``"0"`` or a device path/URL).

    Examples
    --------
    >>> fg = open_instrument("33500B", "TCPIP0::127.0.0.1::5025::SOCKET",
    ...                      channel=1, max_amp_vpp=20)           # doctest: +SKIP
    """
    kind = _norm(str(model)).lower()
    if kind in CAMERAS:
        settings.pop("timeout_s", None)     # frame reads have the backend's own timeout
    if kind == "file":
        from labkit.drivers.camera import FileCamera
        return FileCamera(resource, **settings)
    if kind == "opencv":
        from labkit.drivers.camera import OpenCVCamera
        return OpenCVCamera(int(resource) if str(resource).isdigit() else resource, **settings)
    return driver_class(model).open(resource, **settings)
