"""FRF files from other software: universal file format 58, CSV and Touchstone; UFF 55/58 out.

Readers return :class:`~labkit.analysis.modal.io.RunChannels` (group ``"frf"``),
so :func:`~labkit.analysis.modal.robot.fit_robot` and ``labkit fit`` treat them like
labkit's own run files.  :func:`~labkit.analysis.modal.io.read_frf` picks the
reader by suffix.

* **UFF 58** (``.uff``, ``.unv``; Polytec PSV, Simcenter Testlab, most modal
  software) through ``pyuff``: every dataset 58 that is a frequency response
  function (function type 4) or a transmissibility (5); the FRF kind from the
  ordinate's data type (displacement, velocity, acceleration over force).
* **CSV** (``.csv``, ``.txt``, ``.tsv``): one frequency column in Hz and, per
  location, real and imaginary parts or magnitude (linear or dB) and phase
  (degrees or radians), named by ``columns`` (see :func:`parse_columns`).
* **Touchstone** (``.s1p``, ``.s2p``, ...) through ``scikit-rf``: every
  S-parameter (``S11``, ``S21``, ...), or those named in ``columns``; kind
  ``"scattering"`` (a constant-plus-slope background is fitted with the modes).

``pyuff`` and ``scikit-rf`` are the optional extra ``labkit[formats]``; without
them these readers raise :class:`~labkit.errors.InputError` (exit 2) saying
what to install.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import numpy as np

from labkit.analysis.modal.io import RunChannels
from labkit.errors import InputError

__all__ = ["read_uff", "read_csv", "read_touchstone", "parse_columns", "write_uff", "UFF_SUFFIXES",
           "CSV_SUFFIXES", "TOUCHSTONE_RE"]

UFF_SUFFIXES = (".uff", ".unv")
CSV_SUFFIXES = (".csv", ".txt", ".tsv")
TOUCHSTONE_RE = re.compile(r"^\.s\d+p$", re.IGNORECASE)

#: UFF 58 ordinate "specific data type" -> FRF kind (over force, data type 13).
_UFF_KIND = {8: "receptance", 11: "mobility", 12: "accelerance"}
_KIND_UFF = {"receptance": 8, "mobility": 11, "accelerance": 12}


def _need(module: str, package: str, path: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"reading this file needs the Python package {package!r}, which is not installed",
                         file=path, expected=f"pip install 'labkit[formats]' (or pip install {package})") from None


def _finish(out: RunChannels) -> RunChannels:
    if not out.names:
        raise InputError("no usable FRF lines (all NaN or at frequencies <= 0)", file=out.path)
    return out


# ---------------------------------------------------------------------------------------------- UFF
def read_uff(path: str | Path, *, kind: str | None = None) -> RunChannels:
    """Every FRF (dataset 58, function type 4 or 5) of a universal file."""
    path = str(path)
    pyuff = _need("pyuff", "pyuff", path)
    try:
        uff = pyuff.UFF(path)
        types = list(uff.get_set_types())
        idx = [i for i, t in enumerate(types) if int(t) == 58]
        sets = [uff.read_sets(i) for i in idx]
    except Exception as exc:        # pyuff raises bare Exceptions of many kinds on malformed files
        raise InputError(f"not a readable universal file ({type(exc).__name__}: {exc})", file=path,
                         expected="a UFF file with dataset 58") from None
    frfs = [s for s in sets if int(s.get("func_type", 0)) in (4, 5)]
    if not frfs:
        raise InputError(f"no frequency response function among {len(sets)} datasets 58 "
                         f"(function types {sorted({int(s.get('func_type', 0)) for s in sets})})",
                         file=path, key="func_type", expected="4 (FRF) or 5 (transmissibility)")
    out = RunChannels(path, "uff58", "frf", "complete", frf_kind="")
    kinds = set()
    for s in frfs:
        if int(s["func_type"]) == 5:
            kinds.add("transmissibility")
        else:
            kinds.add(_UFF_KIND.get(int(s.get("ordinate_spec_data_type", 0)), "?"))
        name = f"{int(s.get('rsp_node', 0))}{_dir(s.get('rsp_dir', 0))}_{int(s.get('ref_node', 0))}" \
               f"{_dir(s.get('ref_dir', 0))}"
        base, k = name, 2
        while name in out.names:
            name, k = f"{base}#{k}", k + 1
        f = np.asarray(s["x"], dtype=float)
        h = np.asarray(s["data"])
        if not np.iscomplexobj(h):
            out.warnings.append(f"{path}: {name} holds real values; fitted as a real FRF")
        out.add(name, name, f, h.astype(complex))
    if kind is not None:
        out.frf_kind = kind
    elif len(kinds) == 1 and "?" not in kinds:
        out.frf_kind = kinds.pop()
    else:
        raise InputError(f"the FRFs' ordinate types do not say one FRF kind ({sorted(kinds)})", file=path,
                         key="ordinate_spec_data_type",
                         expected="8, 11 or 12 over force (13), or name the kind (--kind)")
    out.units = {"receptance": "m/N", "mobility": "(m/s)/N", "accelerance": "(m/s^2)/N"}.get(out.frf_kind, "1")
    return _finish(out)


def _dir(d: Any) -> str:
    d = int(d)
    return {1: "+x", 2: "+y", 3: "+z", -1: "-x", -2: "-y", -3: "-z"}.get(d, "" if d == 0 else f"d{d}")


def write_uff(path: str | Path, fits: dict[str, Any]) -> Path:
    """The fitted modes as UFF 55 (complex mode shapes: residues per location, with the poles) and
    the fitted model FRFs as UFF 58 (one per location, on the measured lines).

    Locations are numbered nodes 1, 2, ... in the order of each fit's
    ``locations`` (groups one after another; the node names are in ID line 4).
    The residues are the nodes' z (out-of-plane, what the vibrometer sees)
    components; x and y are zero.  UFF 55 stores 6 significant digits.
    """
    import pyuff

    from labkit.analysis.modal.lscf import modal_to_pole

    path = Path(path)
    sets: list[dict[str, Any]] = []
    node0 = 0
    for group, fit in fits.items():
        nodes = list(range(node0 + 1, node0 + len(fit.locations) + 1))
        names = " ".join(f"{n}={loc}" for n, loc in zip(nodes, fit.locations))[:80]
        for i, m in enumerate(fit.modes):
            lam = complex(modal_to_pole(np.array([m.freq_hz]), np.array([m.damping_ratio]))[0])
            sets.append(pyuff.prepare_55(
                model_type=1, id1=f"labkit fit: {group} mode {i + 1}", id2=f"f = {m.freq_hz:.8g} Hz",
                id3=f"zeta = {m.damping_ratio:.6g}", id4=names or "NONE", id5="residues (FRF units * rad/s)",
                analysis_type=3, data_ch=2, spec_data_type=8, data_type=5, n_data_per_node=1,
                r1=np.zeros(len(nodes), complex), r2=np.zeros(len(nodes), complex),
                r3=np.asarray(m.amplitude, dtype=complex), node_nums=nodes, load_case=1, mode_n=i + 1,
                eig=lam, modal_a=0j, modal_b=0j))
        uff_kind = _KIND_UFF.get(fit.kind)
        for k, loc in enumerate(fit.locations):
            f = np.asarray(fit.freq_hz[k], dtype=float)
            # Even lines are stored as start + step (exact); uneven ones as a list of 6-digit numbers.
            even = f.size > 1 and bool(np.allclose(np.diff(f), f[1] - f[0], rtol=1e-9, atol=0))
            sets.append(pyuff.prepare_58(
                id1=f"labkit fit model: {group} {loc}"[:80], id2="NONE", id3="NONE", id4="NONE", id5="NONE",
                func_type=5 if fit.kind == "transmissibility" else 4, rsp_node=nodes[k], rsp_dir=3,
                ref_node=0, ref_dir=3, ord_data_type=6, num_pts=f.size, abscissa_spacing=int(even),
                abscissa_spec_data_type=18, ordinate_spec_data_type=uff_kind or 0,
                orddenom_spec_data_type=13 if uff_kind else 0, data=fit.model(f, k).astype(complex), x=f,
                ))
    if path.exists():
        path.unlink()               # pyuff appends to an existing file; the caller decided to replace it
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


# ---------------------------------------------------------------------------------------------- CSV
_PAIRS = {"re": "im", "mag": ("deg", "rad"), "db": ("deg", "rad")}


def parse_columns(spec: str) -> list[tuple[str, str]]:
    """``"f=freq_hz,re=H_re,im=H_im"`` -> ``[("f", "freq_hz"), ("re", "H_re"), ("im", "H_im")]``.

    Roles: ``f`` (frequency, Hz), then per location a pair: ``re`` + ``im``,
    or ``mag`` (linear) / ``db`` (20 log10) + ``deg`` / ``rad`` (phase).  A
    column is a header name or a 1-based column number.  The location is
    named after the pair's first column.
    """
    items = [s.strip() for s in spec.split(",") if s.strip()]
    out = []
    for it in items:
        if "=" not in it:
            raise InputError(f"bad item {it!r}", key="--columns",
                             expected="ROLE=COLUMN items, e.g. f=freq_hz,re=H_re,im=H_im")
        role, col = (x.strip() for x in it.split("=", 1))
        if role.lower() not in ("f", "re", "im", "mag", "db", "deg", "rad"):
            raise InputError(f"unknown role {role!r}", key="--columns",
                             expected="f, re, im, mag, db, deg or rad")
        out.append((role.lower(), col))
    if not out or out[0][0] != "f" or len(out) < 3 or (len(out) - 1) % 2:
        raise InputError(f"{spec!r}", key="--columns",
                         expected="f=COL first, then pairs re=,im= or mag=/db=, deg=/rad=")
    for (a, _), (b, _) in zip(out[1::2], out[2::2]):
        ok = _PAIRS.get(a)
        if ok is None or b not in (ok if isinstance(ok, tuple) else (ok,)):
            raise InputError(f"{a}= followed by {b}=", key="--columns",
                             expected="re then im, or mag/db then deg/rad")
    return out


def read_csv(path: str | Path, *, columns: str | None = None, kind: str | None = None) -> RunChannels:
    """FRFs from a delimited text file (comma, semicolon, tab or spaces; ``#`` comments).

    Without ``columns`` the first column is the frequency in Hz and the rest
    are real/imaginary pairs.
    """
    path = str(path)
    try:
        lines = [ln for ln in Path(path).read_text(encoding="utf-8-sig").splitlines()
                 if ln.strip() and not ln.lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read ({exc})", file=path) from None
    if not lines:
        raise InputError("empty", file=path, expected="a header line and rows of numbers")
    dialect = "," if "," in lines[0] else (";" if ";" in lines[0] else ("\t" if "\t" in lines[0] else None))
    rows = [next(csv.reader([ln], delimiter=dialect)) if dialect else ln.split() for ln in lines]
    rows = [[c.strip() for c in r] for r in rows]
    header: list[str] | None = None
    try:
        float(rows[0][0])
    except ValueError:
        header, rows = rows[0], rows[1:]
    width = len(header) if header else len(rows[0])
    try:
        data = np.array([[float(c) for c in r] for r in rows], dtype=float)
    except ValueError as exc:
        raise InputError(f"a row is not numeric ({exc})", file=path, expected="numbers below the header") from None
    if data.ndim != 2 or data.shape[1] != width:
        raise InputError("rows have different numbers of columns", file=path, expected=f"{width} columns each")
    spec = parse_columns(columns) if columns else (
        [("f", "1")] + [(r, str(k)) for j in range(2, width, 2) for r, k in (("re", j), ("im", j + 1))]
        if width >= 3 and width % 2 == 1 else None)
    if spec is None:
        raise InputError(f"{width} columns and no --columns", file=path,
                         expected="frequency then real/imaginary pairs, or name them with --columns")

    def col(name: str) -> tuple[np.ndarray, str]:
        if header and name in header:
            j = header.index(name)
        else:
            try:
                j = int(name) - 1
            except ValueError:
                raise InputError(f"no column {name!r}", file=path, key="--columns",
                                 expected=f"one of {', '.join(header or [])} or a column number") from None
            if not 0 <= j < width:
                raise InputError(f"no column number {name}", file=path, key="--columns",
                                 expected=f"1..{width}")
        return data[:, j], (header[j] if header else f"col{j + 1}")

    f, _ = col(spec[0][1])
    out = RunChannels(path, "csv", "frf", "complete", frf_kind=kind or "mobility", units="")
    if kind is None:
        out.warnings.append(f"{path}: FRF kind not given; fitted as a mobility (name it with --kind)")
    for (ra, ca), (rb, cb) in zip(spec[1::2], spec[2::2]):
        a, name = col(ca)
        b, _ = col(cb)
        h: np.ndarray
        if ra == "re":
            h = a + 1j * b
        else:
            mag = 10 ** (a / 20) if ra == "db" else a
            h = mag * np.exp(1j * (np.radians(b) if rb == "deg" else b))
        out.add(name, name, f, h)
    return _finish(out)


# ---------------------------------------------------------------------------------------------- Touchstone
def read_touchstone(path: str | Path, *, columns: str | None = None, kind: str | None = None) -> RunChannels:
    """S-parameters of a Touchstone file (``columns``: which, e.g. ``"S21"`` or ``"S11,S21"``)."""
    path = str(path)
    skrf = _need("skrf", "scikit-rf", path)
    try:
        net = skrf.Network(path)
    except Exception as exc:        # scikit-rf raises many kinds on malformed files
        raise InputError(f"not a readable Touchstone file ({type(exc).__name__}: {exc})", file=path,
                         expected="a .sNp file") from None
    f = np.asarray(net.f, dtype=float)
    s = np.asarray(net.s)
    n_ports = s.shape[1]
    all_names = [f"S{i + 1}{j + 1}" for i in range(n_ports) for j in range(n_ports)]
    wanted = [c.strip().upper() for c in columns.split(",")] if columns else all_names
    for w in wanted:
        if w not in all_names:
            raise InputError(f"no {w} in a {n_ports}-port file", file=path, key="--columns",
                             expected=", ".join(all_names))
    out = RunChannels(path, "touchstone", "frf", "complete", frf_kind=kind or "scattering", units="1")
    for w in wanted:
        i, j = int(w[1]) - 1, int(w[2]) - 1
        out.add(w, w, f, s[:, i, j].astype(complex))
    return _finish(out)


def suffix_kind(path: str | Path) -> str:
    """``"run"``, ``"uff"``, ``"csv"`` or ``"touchstone"`` from a file name."""
    suf = Path(path).suffix.lower()
    if suf in UFF_SUFFIXES:
        return "uff"
    if suf in CSV_SUFFIXES:
        return "csv"
    if TOUCHSTONE_RE.match(suf):
        return "touchstone"
    return "run"
