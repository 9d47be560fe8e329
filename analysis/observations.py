"""Measured speeds (and leg patterns) as the calibration's :class:`~labkit.sim.calibrate.Observations`.

The simulator's calibration takes its observations as arrays; reading them from
the files a user has (shaker run files, tracks, speed tables) is analysis, here.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from labkit.analysis.report import inputs as ri
from labkit.errors import InputError
from labkit.files import read_speed_table
from labkit.sim.calibrate import Observations
from labkit.sim.knee_patterns import PATTERNS


def observations_from_files(paths: Sequence[str], *, amp_um: float | None = None) -> Observations:
    """Measured speeds from shaker run files + track files, or CSV/HDF5 speed tables.

    The tray amplitude of each point is the run's measured one; tables (and
    tracks with their own ``freq_hz``) use ``amp_um`` (InputError if not given).
    Leg patterns come from a table's ``pattern`` column or from the knee
    records of shaker runs (classified by :func:`labkit.sim.knee_patterns.classify_knee_pattern`).
    """
    runs, tracks, tables = [], [], []
    for p in paths:
        if not Path(p).is_file():
            raise InputError("no such file", file=p)
        kind = None
        if Path(p).suffix.lower() not in (".csv", ".txt"):
            try:
                kind = ri.file_kind(p)
            except InputError:
                kind = None
        if kind == "run_shaker":
            runs.append(ri.load_shaker_run(p))
        elif kind == "track":
            tracks.append(ri.load_track(p))
        else:
            tables.append(read_speed_table(p))
    freq, amp, speed, sd, pats, src = [], [], [], [], [], []
    if runs or tracks:
        m = ri.measured_speeds(runs, tracks)
        for f, a, s, d, pat, source in zip(m.freq_hz, m.amp_um, m.speed_mm_s, m.std_mm_s, m.patterns, m.sources):
            if not math.isfinite(a):
                if amp_um is None:
                    raise InputError("tray amplitude unknown for a track with its own frequency", file=source,
                                     key="--amp-um", expected="--amp-um AMP (um)")
                a = amp_um
            freq.append(f)
            amp.append(a)
            speed.append(s)
            sd.append(d)
            pats.append(pat)
            src.append(source)
    for t in tables:
        if amp_um is None:
            raise InputError("a speed table holds no tray amplitude", file=t.file, key="--amp-um",
                             expected="--amp-um AMP (um)")
        n = t.freq_hz.size
        freq += list(t.freq_hz)
        amp += [amp_um] * n
        speed += list(t.speed_mm_s)
        sd += list(t.speed_std_mm_s if t.speed_std_mm_s is not None else np.full(n, np.nan))
        pats += list(t.pattern or [""] * n)
        src += [t.file] * n
    if not freq:
        raise InputError("no measured speeds in the given files", key="--measured",
                         expected="shaker run files with tracks, track files or a freq_hz,speed_mm_s table")
    for lab in pats:
        if lab and lab not in PATTERNS:
            raise InputError(f"unknown pattern {lab!r}", key="pattern", expected=" | ".join(PATTERNS))
    sd_a = np.asarray(sd, float)
    if np.isnan(sd_a).any():
        raise InputError("speed standard deviation missing for some points", key="speed_std_mm_s",
                         expected="a speed_std_mm_s column (or confidence intervals in the tracks)")
    return Observations(np.asarray(freq, float), np.asarray(amp, float), np.asarray(speed, float), sd_a,
                        pats if any(pats) else None, src)
