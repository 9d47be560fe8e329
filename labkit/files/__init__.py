"""Every file labkit writes, opened by one call: :func:`labkit.open` (this package's :func:`open_file`).

>>> run = labkit.open("sample_data/inchip_run.h5")          # doctest: +SKIP
>>> run.locations["knee"].frf, run.units["frf"]             # doctest: +SKIP

===========================  ===================  ==========================================
file                         kind                 object
===========================  ===================  ==========================================
in-chip run (``.h5``)        ``run_inchip``       :class:`~labkit.files.runs.InchipRun`
shaker run (``.h5``)         ``run_shaker``       :class:`~labkit.files.runs.ShakerRun`
track (``.h5``)              ``track``            :class:`~labkit.files.kinds.Track`
track table (``.csv``)       ``track_csv``        :class:`~labkit.files.kinds.Track`
modal fit (``.fit.h5``)      ``modal_fit``        :class:`~labkit.files.kinds.ModalFit`
simulation (``.h5``)         ``sim_result``       :class:`~labkit.files.kinds.SimRun`
simulated sweep (``.h5``)    ``sim_sweep``        :class:`~labkit.files.kinds.SimSweep`
scenario points (``.h5``)    ``sim_points``       :class:`~labkit.files.kinds.SimSweep`
scenario sweeps (``.h5``)    ``sim_sweep_set``    :class:`~labkit.files.kinds.SimSweepSet`
scenario runs (``.h5``)      ``sim_ablations``    :class:`~labkit.files.kinds.SimRunSet`
regime map (``.h5``)         ``sim_regime_map``   :class:`~labkit.files.regimes.SimRegimeMap`
robot parameters (``.toml``) ``robot_params``     :class:`~labkit.files.kinds.RobotParameters`
experiment config (``.toml``) ``config_inchip``,  :class:`~labkit.files.kinds.ExperimentConfig`
                             ``config_shaker``
video (``.mkv``, ``.avi``)   ``video``            :class:`~labkit.files.kinds.Video`
===========================  ===================  ==========================================

A simulated sweep is read back as the simulator's :class:`~labkit.sim.SweepResult` by
:func:`~labkit.files.sweeps.read_sweep_result`.
A table of measured speeds (CSV, or HDF5 datasets of any kind) is read by
:func:`~labkit.files.speeds.read_speed_table`; :func:`file_kind` reads only an HDF5 file's ``kind``.

Each has ``path``, ``kind``, ``schema_version``, ``attrs`` (root attributes, ``*_json`` decoded),
``units`` (name -> units of its arrays), ``summary()`` and ``to_xarray()``.
"""
from __future__ import annotations

import os
from pathlib import Path

from labkit.errors import InputError
from labkit.files.base import LabFile
from labkit.files.kinds import (
    ExperimentConfig,
    ModalFit,
    RobotParameters,
    SimRun,
    SimRunSet,
    SimSweep,
    SimSweepSet,
    Track,
    Video,
)
from labkit.files.regimes import SimRegimeMap
from labkit.files.runs import InchipRun, RunFile, ShakerRun, read_run_file
from labkit.files.speeds import SpeedTable, read_speed_table
from labkit.files.sweeps import read_sweep_result

__all__ = ["open_file", "LabFile", "RunFile", "InchipRun", "ShakerRun", "Track", "ModalFit", "SimRun",
           "SimSweep", "SimSweepSet", "SimRunSet", "SimRegimeMap", "RobotParameters", "ExperimentConfig", "Video",
           "read_run_file", "SpeedTable", "read_speed_table", "read_sweep_result", "file_kind", "VIDEO_SUFFIXES",
           "H5_KINDS"]

VIDEO_SUFFIXES = (".mkv", ".avi", ".mp4")
#: the ``kind`` attributes of the HDF5 files labkit writes
H5_KINDS = ("run_inchip", "run_shaker", "track", "modal_fit", "sim_result", "sim_sweep", "sim_points",
            "sim_sweep_set", "sim_ablations", "sim_regime_map")


def file_kind(path: str | os.PathLike[str]) -> str:
    """The ``kind`` root attribute of a labkit HDF5 file (InputError naming the file if unreadable or absent)."""
    from labkit.h5io import open_h5

    p = Path(path)
    with open_h5(p) as f:
        kind = f.attrs.get("kind")
    if kind is None:
        raise InputError("not a labkit file: no 'kind' attribute", file=p, key="kind")
    return kind.decode("utf-8", "replace") if isinstance(kind, bytes) else str(kind)


def open_file(path: str | os.PathLike[str]) -> LabFile:
    """Open any file labkit writes and return its typed object (see the module's table).

    Raises
    ------
    InputError
        Missing, unreadable, or not a file labkit writes (the message names the file and
        what was found).
    """
    from labkit.files import kinds
    from labkit.h5io import open_h5

    p = Path(path)
    if not p.is_file():
        raise InputError("no such file", file=p)
    suffix = p.suffix.lower()
    if suffix == ".toml":
        return kinds.read_toml(p)
    if suffix == ".csv":
        return kinds.read_track_csv(p)
    if suffix in VIDEO_SUFFIXES:
        return kinds.read_video(p)
    with open_h5(p, "r") as f:
        kind = f.attrs.get("kind")
        kind = kind.decode() if isinstance(kind, bytes) else kind
        if kind in ("run_inchip", "run_shaker"):
            pass
        elif kind == "track":
            return kinds.read_track(p, f)
        elif kind == "modal_fit":
            return kinds.read_fit(p, f)
        elif kind == "sim_result":
            return kinds.read_sim_result(p, f)
        elif kind in ("sim_sweep", "sim_points"):
            return kinds.read_sim_sweep(p, f)
        elif kind == "sim_sweep_set":
            return kinds.read_sim_sweep_set(p, f)
        elif kind == "sim_ablations":
            return kinds.read_sim_run_set(p, f)
        elif kind == "sim_regime_map":
            from labkit.files.regimes import read_sim_regime_map

            return read_sim_regime_map(p, f)
        else:
            raise InputError(f"not a file labkit reads: kind {kind!r}", file=p, key="kind",
                             expected=", ".join(H5_KINDS))
    return read_run_file(p)
