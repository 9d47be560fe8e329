"""Run files in, modal-fit files out: what ``labkit fit`` reads and writes.

Reads in-chip run files (``kind = "run_inchip"``: ``/locations/<loc>/freq_hz``,
``frf``, ``quality``) and shaker run files (``kind = "run_shaker"``:
``/points`` rows with ``status == "ok"``, ``freq_hz``, ``transmissibility``,
``quality``; root attribute ``robot_spot``), layout in
:mod:`labkit.experiments.runfile`.

Writes ``*.fit.h5`` (``kind = "modal_fit"``)::

    /                      attrs: runs_json, assignment_json, summary_json
    /groups/<group>/       group = "inchip" (tethered robot) | "shaker" (released robot)
        attrs: method, frf_kind, band_hz, quality, warnings_json, locations_json
        locations/<loc>/   freq_hz (Hz), frf (measured), model (fitted, same lines), quality (1)
        modes/             freq_hz, freq_hz_std (Hz), damping_ratio, damping_ratio_std (1),
                           amplitude (modes x locations, complex residue), amplitude_std,
                           peak (modes x locations: |R| / (zeta wn)), dominant_location (label)
        stabilisation/     order (1), freq_hz (Hz), damping_ratio (1), status (label codes
                           0 new, 1 stable frequency, 2 stable frequency and damping), chosen_hz (Hz)
        covariance         parameter covariance of the refinement (mixed units; above
                           MAX_STORED_COVARIANCE parameters only the poles' block)

Every array's dimensions are named (HDF5 dimension scales, :func:`label_fit_dimensions`), so
xarray/h5netcdf and HDFView show coordinates: ``freq_hz`` in ``locations/<loc>/`` (the lines)
and ``modes/`` (one per mode), ``modes/location`` (the locations' names, label) as the second
axis of the modes x locations arrays, ``stabilisation/freq_hz`` and ``chosen_hz``, and index
scales ``parameter_i``, ``parameter_j`` (1) beside ``covariance``. Fit files written before
carry only the ``freq_hz`` scales (the rest opens as ``phony_dim``); they read the same.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.errors import InputError
from labkit.jsonutil import Json

if TYPE_CHECKING:
    from labkit.analysis.modal.fit import ModalFit

__all__ = ["RunChannels", "label_fit_dimensions", "read_run", "read_frf", "write_fit_h5", "write_uff"]

FRF_UNITS = {"inchip": "(mm/s)/V", "shaker": "1"}

#: Above this many parameters (a scan of many locations) a fit file keeps the poles' covariance only.
MAX_STORED_COVARIANCE = 1000


@dataclass
class RunChannels:
    """The FRF channels of one run file."""

    path: str
    kind: str                       # "run_inchip" | "run_shaker"
    group: str                      # "inchip" | "shaker"
    status: str
    names: list[str] = field(default_factory=list)
    freq_hz: list[np.ndarray] = field(default_factory=list)
    frf: list[np.ndarray] = field(default_factory=list)
    quality: list[np.ndarray] = field(default_factory=list)
    dropped: int = 0
    warnings: list[str] = field(default_factory=list)
    frf_kind: str = ""              # mobility | transmissibility | receptance | accelerance | scattering
    units: str = ""                 # of the FRF, for figures and the fit file

    def __post_init__(self) -> None:
        if not self.frf_kind:
            self.frf_kind = {"inchip": "mobility", "shaker": "transmissibility"}.get(self.group, "mobility")
        if not self.units:
            self.units = FRF_UNITS.get(self.group, "")

    def add(self, name: str, key: str, f: np.ndarray, h: np.ndarray, q: np.ndarray | None = None,
            min_quality: float = 0.0) -> bool:
        """Keep channel ``name`` without its unusable lines (non-finite, ``f <= 0``, quality below
        ``min_quality``; counted in :attr:`dropped`). False when no line is left (nothing kept)."""
        fr, hh, qq, bad = _clean(self.path, key, f, h, np.ones(f.size) if q is None else q, min_quality)
        self.dropped += bad
        if not fr.size:
            return False
        self.names.append(name)
        self.freq_hz.append(fr)
        self.frf.append(hh)
        self.quality.append(qq)
        return True


def _clean(path: str, key: str, f: np.ndarray, h: np.ndarray, q: np.ndarray, min_quality: float):
    if not (f.shape == h.shape == q.shape):
        raise InputError(f"freq_hz, frf and quality have lengths {f.size}, {h.size}, {q.size}",
                         file=path, key=key, expected="equal lengths")
    ok = np.isfinite(f) & np.isfinite(h) & (f > 0) & (np.nan_to_num(q, nan=0.0) >= min_quality)
    return f[ok], h[ok], q[ok], int(np.sum(~ok))


def read_run(path: str | Path, *, min_quality: float = 0.0) -> RunChannels:
    """The FRF channels of an in-chip or shaker run file (bad or low-quality lines dropped).

    Reads through :func:`labkit.files.runs.read_run_file`, the one run-file reader
    (complete points only).
    """
    from labkit.files.runs import InchipRun, read_run_file

    path = str(path)
    run = read_run_file(path)
    status = run.status
    if isinstance(run, InchipRun):
        out = RunChannels(path, run.kind, "inchip", status)
        if not run.locations:
            raise InputError("no /locations group with data", file=path, key="locations",
                             expected="an in-chip run with at least one location")
        for loc, lg in run.locations.items():
            if "freq_hz" not in lg.columns or "frf" not in lg.columns:
                name = "freq_hz" if "freq_hz" not in lg.columns else "frf"
                raise InputError("missing dataset", file=path, key=f"locations/{loc}/{name}")
            if not out.add(loc, f"locations/{loc}", lg.freq_hz.astype(float), lg.frf.astype(complex),
                           lg.quality.astype(float), min_quality):
                out.warnings.append(f"{path}: location {loc} has no usable lines")
    else:
        out = RunChannels(path, run.kind, "shaker", status)
        pts = run.points
        if "transmissibility" not in pts:
            raise InputError("missing dataset", file=path, key="points/transmissibility",
                             expected="a shaker run file")
        n = run.complete_points
        fr = np.asarray(pts["freq_hz"], dtype=float)
        h = np.asarray(pts["transmissibility"], dtype=complex)
        q = np.asarray(pts["quality"], dtype=float) if "quality" in pts else np.ones(n)
        sel = run.ok
        out.dropped += int(np.sum(~sel))
        out.add(run.robot_spot if run.robot_spot != "?" else "robot", "points", fr[sel], h[sel], q[sel], min_quality)
    if not out.names:
        raise InputError("no usable FRF lines (all NaN, interlocked or below --min-quality)", file=path)
    if not status.startswith("complete"):
        out.warnings.append(f"{path}: run status is {status!r}; fitting the points it holds")
    return out


def read_frf(path: str | Path, *, min_quality: float = 0.0, kind: str | None = None,
             columns: str | None = None) -> RunChannels:
    """The FRF channels of any file ``labkit fit`` reads, chosen by suffix.

    ``.h5`` run files (:func:`read_run`), UFF 58 (``.uff``, ``.unv``), CSV
    (``.csv``, ``.txt``, ``.tsv``) and Touchstone (``.s1p``, ``.s2p``, ...);
    see :mod:`labkit.analysis.modal.formats`.  ``kind`` and ``columns``
    apply to the files other than run files.
    """
    from labkit.analysis.modal import formats

    path = str(path)
    if not Path(path).is_file():
        raise InputError("no such file", file=path)
    which = formats.suffix_kind(path)
    if which == "csv":
        return formats.read_csv(path, columns=columns, kind=kind)
    if which == "touchstone":
        return formats.read_touchstone(path, columns=columns, kind=kind)
    out = formats.read_uff(path, kind=kind) if which == "uff" else read_run(path, min_quality=min_quality)
    if columns is not None:
        out.warnings.append(f"{path}: --columns applies to CSV and Touchstone files; ignored here")
    if kind is not None and which == "run":
        out.warnings.append(f"{path}: --kind applies to files other than run files; ignored here (a run file "
                            "says its own kind)")
    return out


def write_uff(path: str | Path, fits: dict[str, ModalFit]) -> Path:
    """The fitted modes as UFF 55 and the fitted FRFs as UFF 58.

    See :func:`labkit.analysis.modal.formats.write_uff`.
    """
    from labkit.analysis.modal.formats import write_uff as _write

    return _write(path, fits)


def write_fit_h5(path: str | Path, fits: dict[str, ModalFit], runs: dict[str, list[str]],
                 assignment: Mapping[str, Json], summary: Mapping[str, Json]) -> Path:
    """Write the ``modal_fit`` file (layout in the module docstring)."""
    import h5py

    from labkit.h5io import put, put_json, stamp

    path = Path(path)
    with h5py.File(path, "w") as f:
        stamp(f, "modal_fit")
        put_json(f, "runs_json", runs)
        put_json(f, "assignment_json", assignment)
        put_json(f, "summary_json", summary)
        for group, fit in fits.items():
            g = f.create_group(f"groups/{group}")
            g.attrs["method"] = fit.method
            g.attrs["frf_kind"] = fit.kind
            g.attrs["band_hz"] = np.asarray(fit.band_hz, dtype=float)
            g.attrs["quality"] = float(fit.quality)
            put_json(g, "warnings_json", fit.warnings)
            put_json(g, "locations_json", fit.locations)
            units = FRF_UNITS.get(group, "1")
            for k, loc in enumerate(fit.locations):
                lg = g.create_group(f"locations/{loc.replace('/', '_')}")
                lg.attrs["name"] = loc
                put(lg, "freq_hz", fit.freq_hz[k], "Hz")
                put(lg, "frf", fit.frf[k], units)
                put(lg, "model", fit.model(fit.freq_hz[k], k), units)
            mg = g.create_group("modes")
            md = fit.modes
            put(mg, "freq_hz", [m.freq_hz for m in md], "Hz")
            put(mg, "freq_hz_std", [m.freq_hz_std for m in md], "Hz")
            put(mg, "damping_ratio", [m.damping_ratio for m in md], "1")
            put(mg, "damping_ratio_std", [m.damping_ratio_std for m in md], "1")
            shape = (len(md), len(fit.locations))
            put(mg, "amplitude", np.array([m.amplitude for m in md]).reshape(shape), f"{units} * rad/s")
            put(mg, "amplitude_std", np.array([m.amplitude_std for m in md]).reshape(shape), f"{units} * rad/s")
            put(mg, "peak", np.array([m.peak for m in md]).reshape(shape), units)
            mg.create_dataset("dominant_location", data=np.array([m.dominant_location for m in md], dtype=object),
                              dtype=h5py.string_dtype()).attrs["units"] = "label"
            if fit.stabilisation is not None:
                s = fit.stabilisation
                sg = g.create_group("stabilisation")
                put(sg, "order", s.order, "1")
                put(sg, "freq_hz", s.freq_hz, "Hz")
                put(sg, "damping_ratio", s.damping_ratio, "1")
                put(sg, "status", s.status, "label", codes="0 new, 1 stable frequency, 2 stable frequency+damping")
                put(sg, "chosen_hz", s.chosen_hz, "Hz")
            if fit.covariance is not None and fit.covariance.shape[0] <= MAX_STORED_COVARIANCE:
                put(g, "covariance", fit.covariance, "mixed",
                    order="f_1, zeta_1, ..., then per location Re R_i, Im R_i ..., Re c_q, Im c_q")
            elif fit.covariance is not None:       # a scan of many locations: the poles' block only
                n = 2 * len(fit.modes)
                put(g, "covariance", fit.covariance[:n, :n], "mixed", order="f_1, zeta_1, f_2, zeta_2, ... "
                    f"(the poles' block only: the full matrix has {fit.covariance.shape[0]} rows)")
        label_fit_dimensions(f)     # named dimensions and coordinates (xarray, HDFView)
    return path


def label_fit_dimensions(f: Any) -> None:
    """Name every dimension of a fit file's arrays with HDF5 dimension scales (``f``: open for writing).

    Per fit group: ``modes/freq_hz`` and a ``modes/location`` label scale (from the group's
    ``locations_json``) on the modes x locations arrays, ``stabilisation/chosen_hz`` its own
    scale, ``parameter_i``/``parameter_j`` index scales on ``covariance``; then the ``freq_hz``
    axes of every group (:func:`labkit.h5io.label_dimensions`). Idempotent; labels an older fit
    file in place (an array whose shape does not match is left as it is).
    """
    import h5py

    from labkit.h5io import label_dimensions, put

    def own_scale(ds: Any, name: str) -> Any:
        # "axes" naming itself: label_dimensions then neither attaches the group's axis to it nor relabels it
        ds.attrs["axes"] = name
        if not ds.is_scale:
            ds.make_scale(name)
        return ds

    def attach(ds: Any, *scales: Any) -> None:
        if ds.ndim != len(scales) or any(len(d) for d in ds.dims) or ds.is_scale:
            return                  # labelled already (or a scale itself)
        if any(ds.shape[i] != sc.shape[0] for i, sc in enumerate(scales)):
            return
        for i, sc in enumerate(scales):
            ds.dims[i].attach_scale(sc)

    for g in (f["groups"].values() if "groups" in f else []):
        try:
            locations = [str(x) for x in json.loads(g.attrs.get("locations_json", "[]"))]
        except (TypeError, ValueError):
            locations = []
        mg = g.get("modes")
        if isinstance(mg, h5py.Group) and isinstance(mg.get("freq_hz"), h5py.Dataset) and locations:
            two_d = [v for v in mg.values() if isinstance(v, h5py.Dataset) and v.ndim == 2]
            if two_d and all(v.shape[1] == len(locations) for v in two_d):
                loc = mg.get("location")
                if loc is None:
                    loc = mg.create_dataset("location", data=np.array(locations, dtype=object),
                                            dtype=h5py.string_dtype())
                    loc.attrs["units"] = "label"
                own_scale(loc, "location")
                freq = mg["freq_hz"]
                if not freq.is_scale:
                    freq.make_scale("freq_hz")
                for v in two_d:
                    attach(v, freq, loc)
        sg = g.get("stabilisation")
        if isinstance(sg, h5py.Group) and isinstance(sg.get("chosen_hz"), h5py.Dataset):
            chosen = sg["chosen_hz"]
            if chosen.ndim == 1 and not any(len(d) for d in chosen.dims):
                own_scale(chosen, "chosen_hz")
        cov = g.get("covariance")
        if isinstance(cov, h5py.Dataset) and cov.ndim == 2 and not any(len(d) for d in cov.dims):
            scales = []
            for axis, n in zip(("parameter_i", "parameter_j"), cov.shape, strict=True):
                sc = g.get(axis)
                if sc is None:
                    sc = put(g, axis, np.arange(n), "1")
                scales.append(own_scale(sc, axis))
            attach(cov, *scales)
    label_dimensions(f)


def runs_json(runs: list[RunChannels]) -> dict[str, list[str]]:
    """``{group: [paths]}`` for the provenance and the fit file."""
    out: dict[str, list[str]] = {}
    for r in runs:
        out.setdefault(r.group, []).append(r.path)
    return out


def dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True)
