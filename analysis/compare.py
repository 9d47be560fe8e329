"""Model against measurement: plain functions over arrays, each result with its provenance.

Three comparisons, as in the paper's section 5:

* :func:`speed_agreement` — average robot speed against shaker frequency,
  measured (with its confidence interval) against simulated (Monte Carlo mean
  and band) (paper Fig. 8);
* :func:`pattern_agreement` — the leg-motion pattern (``firm_contact``,
  ``partial_contact``, ``jumping``) observed against simulated (Fig. 9-11);
* :func:`knee_motion_agreement` — the knee's vertical velocity measured by the
  vibrometer against the simulated one at the same drive: amplitude and phase
  of the fundamental, and the correlation of one drive period (Fig. 10/11).

Every function returns a frozen dataclass holding the numbers *and* a
``provenance`` entry (which files, which parameters, which method), so a
report can say where each number came from; its ``to_dict()`` is the
JSON-able form the report writes to ``agreement.json``. Inputs are plain numpy arrays;
reading files is :mod:`labkit.analysis.report.inputs`' job.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from labkit.files.base import Json

#: Pattern labels, as the simulator writes them (SimResult.patterns); re-exported, with the
#: knee-record classifier shared with the simulator's calibration.
from labkit.sim.knee_patterns import PATTERNS as PATTERNS
from labkit.sim.knee_patterns import classify_knee_pattern as classify_knee_pattern
from labkit.sim.knee_patterns import fundamental


def _f(x: Any) -> float | None:
    """A float for JSON, or None for NaN/inf (JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation; NaN when undefined (fewer than 3 points or a constant series)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.size < 3 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


class Result:
    """What every comparison result has: its JSON-able form (fields in order, nested results as dicts)."""

    def to_dict(self) -> dict[str, Json]:
        return {k: _plain(v) for k, v in asdict(self).items()}  # type: ignore[call-overload]  # subclasses are dataclasses


def _plain(value: Any) -> Json:
    """A value of :func:`dataclasses.asdict` with tuples as lists (as JSON has them)."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


# --------------------------------------------------------------------------- speed vs frequency

@dataclass(frozen=True)
class SpeedPoint(Result):
    """One measured point against the simulated curve interpolated at its frequency (None: not finite)."""

    freq_hz: float | None
    measured_mm_s: float | None
    measured_lo_mm_s: float | None
    measured_hi_mm_s: float | None
    simulated_mm_s: float | None
    band_lo_mm_s: float | None
    band_hi_mm_s: float | None
    error_mm_s: float | None
    inside_band: bool


@dataclass(frozen=True)
class SpeedAgreement(Result):
    """:func:`speed_agreement`'s metrics (None where undefined: no points, no moving robot)."""

    n_points: int
    n_outside_range: int
    rms_error_mm_s: float | None
    mean_error_mm_s: float | None
    relative_rms_error: float | None
    median_relative_error: float | None
    min_speed_mm_s: float
    correlation: float | None
    fraction_inside_band: float | None
    fraction_ci_overlaps_band: float | None
    points: tuple[SpeedPoint, ...]
    method: str
    provenance: dict[str, Json]


def speed_agreement(meas_freq_hz: ArrayLike, meas_speed_mm_s: ArrayLike,
                    meas_lo_mm_s: ArrayLike | None, meas_hi_mm_s: ArrayLike | None,
                    sim_freq_hz: ArrayLike, sim_mean_mm_s: ArrayLike,
                    sim_lo_mm_s: ArrayLike, sim_hi_mm_s: ArrayLike, *,
                    min_speed_mm_s: float = 0.1,
                    provenance: Mapping[str, Json] | None = None) -> SpeedAgreement:
    """Error metrics of simulated against measured speed over frequency.

    The simulated curve (mean and band) is linearly interpolated at the
    measured frequencies; measured points outside the simulated frequency
    range are left out (and counted), never extrapolated.

    Parameters
    ----------
    meas_freq_hz, meas_speed_mm_s:
        Measured points (any order; repeated frequencies allowed).
    meas_lo_mm_s, meas_hi_mm_s:
        Their confidence interval (or None).
    sim_freq_hz, sim_mean_mm_s, sim_lo_mm_s, sim_hi_mm_s:
        The simulated sweep: Monte Carlo mean and band at every frequency.
    min_speed_mm_s:
        Relative errors are taken only where the measured speed is at least
        this (a relative error of a robot standing still means nothing).
    provenance:
        Where the inputs came from; copied into the result.

    Returns
    -------
    SpeedAgreement
        ``n_points``, ``n_outside_range``, ``rms_error_mm_s``,
        ``mean_error_mm_s`` (bias, simulated minus measured),
        ``relative_rms_error`` (RMS error over RMS measured speed),
        ``median_relative_error`` (over points >= ``min_speed_mm_s``),
        ``correlation`` (Pearson, measured vs simulated mean),
        ``fraction_inside_band`` (measured value inside the simulated band),
        ``fraction_ci_overlaps_band``, ``points`` and ``provenance``.
    """
    mf = np.asarray(meas_freq_hz, float)
    ms = np.asarray(meas_speed_mm_s, float)
    mlo = ms if meas_lo_mm_s is None else np.asarray(meas_lo_mm_s, float)
    mhi = ms if meas_hi_mm_s is None else np.asarray(meas_hi_mm_s, float)
    order = np.argsort(np.asarray(sim_freq_hz, float))
    sf = np.asarray(sim_freq_hz, float)[order]
    smean = np.asarray(sim_mean_mm_s, float)[order]
    slo = np.asarray(sim_lo_mm_s, float)[order]
    shi = np.asarray(sim_hi_mm_s, float)[order]
    if not (mf.shape == ms.shape == mlo.shape == mhi.shape):
        raise ValueError("measured frequency, speed and interval arrays differ in length")
    if sf.size == 0:
        raise ValueError("the simulated sweep has no points")
    inside_range = (mf >= sf[0] - 1e-9) & (mf <= sf[-1] + 1e-9)
    f, m, lo, hi = mf[inside_range], ms[inside_range], mlo[inside_range], mhi[inside_range]
    sim = np.interp(f, sf, smean)
    band_lo = np.interp(f, sf, slo)
    band_hi = np.interp(f, sf, shi)
    err = sim - m
    in_band = (m >= band_lo) & (m <= band_hi)
    overlaps = (hi >= band_lo) & (lo <= band_hi)
    moving = np.abs(m) >= min_speed_mm_s
    n = int(f.size)
    rms_meas = float(np.sqrt(np.mean(m ** 2))) if n else float("nan")
    rms_err = float(np.sqrt(np.mean(err ** 2))) if n else float("nan")
    points = tuple(SpeedPoint(_f(a), _f(b), _f(c), _f(d), _f(e), _f(g), _f(h), _f(e - b), bool(i))
                   for a, b, c, d, e, g, h, i in zip(f, m, lo, hi, sim, band_lo, band_hi, in_band))
    return SpeedAgreement(
        n_points=n,
        n_outside_range=int((~inside_range).sum()),
        rms_error_mm_s=_f(rms_err),
        mean_error_mm_s=_f(err.mean()) if n else None,
        relative_rms_error=_f(rms_err / rms_meas) if n and rms_meas > 0 else None,
        median_relative_error=(_f(np.median(np.abs(err[moving]) / np.abs(m[moving]))) if moving.any() else None),
        min_speed_mm_s=float(min_speed_mm_s),
        correlation=_f(_corr(m, sim)),
        fraction_inside_band=_f(in_band.mean()) if n else None,
        fraction_ci_overlaps_band=_f(overlaps.mean()) if n else None,
        points=points,
        method="simulated mean and band linearly interpolated at measured frequencies; error = simulated - measured",
        provenance=dict(provenance or {}),
    )


def band_from_draws(speeds_mm_s: np.ndarray, *, k: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Monte Carlo mean and band ``mean +- k * std`` (ddof=1) from a (points, draws) array.

    With one draw the band collapses to the curve itself. ``k = 2`` is about a
    95 % band for a normal spread, the paper's error-bar convention being
    unstated.
    """
    s = np.asarray(speeds_mm_s, float)
    if s.ndim == 1:
        s = s[:, None]
    mean = s.mean(axis=1)
    std = s.std(axis=1, ddof=1) if s.shape[1] > 1 else np.zeros(s.shape[0])
    return mean, mean - k * std, mean + k * std


def percentile_band(speeds_mm_s: np.ndarray, percentiles: tuple[float, float] = (10.0, 90.0)
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper percentiles over draws of a (points, draws) array (a band that does not
    assume a normal spread, and cannot run below the smallest draw as ``mean - k std`` can)."""
    s = np.asarray(speeds_mm_s, float)
    if s.ndim == 1:
        s = s[:, None]
    lo, hi = np.percentile(s, percentiles, axis=1)
    return lo, hi


def draw_percentiles(meas_freq_hz: ArrayLike, meas_value: ArrayLike, sim_freq_hz: ArrayLike,
                     sim_draws: np.ndarray) -> np.ndarray:
    """Each observed value's percentile (0-100) within the Monte Carlo draws at its frequency.

    Every draw's curve is interpolated linearly at the measured frequency; the percentile is
    the mid-rank ``100 (#below + #equal / 2) / draws``. NaN outside the simulated range.
    A model whose draws describe the spread of real robots puts the observations at uniformly
    spread percentiles; a biased model piles them near 0 or 100.
    """
    mf = np.asarray(meas_freq_hz, float)
    mv = np.asarray(meas_value, float)
    sf = np.asarray(sim_freq_hz, float)
    d = np.asarray(sim_draws, float)
    if d.ndim == 1:
        d = d[:, None]
    order = np.argsort(sf)
    sf, d = sf[order], d[order]
    out = np.full(mf.size, np.nan)
    for i, (f, v) in enumerate(zip(mf, mv)):
        if not (sf[0] - 1e-9 <= f <= sf[-1] + 1e-9) or not np.isfinite(v):
            continue
        at = np.array([np.interp(f, sf, d[:, j]) for j in range(d.shape[1])])
        out[i] = 100.0 * (np.sum(at < v) + 0.5 * np.sum(at == v)) / at.size
    return out


@dataclass(frozen=True)
class Coverage(Result):
    """:func:`coverage`: observations inside the percentile band, the fraction expected, the median percentile."""

    n: int
    fraction_inside: float | None
    expected_fraction: float
    median_percentile: float | None
    band_percentiles: list[float]


def coverage(percentiles: Sequence[float], inside: Sequence[bool],
             band: tuple[float, float] = (10.0, 90.0)) -> Coverage:
    """Coverage score: the fraction of observations inside the Monte Carlo percentile band
    (``inside``, as :func:`speed_agreement` finds it against that band), against the fraction
    expected if the draws were the observations' distribution, with the observations' median
    percentile within the draws (:func:`draw_percentiles`; 50 for an unbiased model)."""
    p = np.asarray(percentiles, float)
    p = p[np.isfinite(p)]
    ins = np.asarray(inside, bool)
    return Coverage(int(ins.size), _f(ins.mean()) if ins.size else None, (band[1] - band[0]) / 100.0,
                    _f(np.median(p)) if p.size else None, list(band))


# --------------------------------------------------------------------------- tolerances and verdicts

@dataclass(frozen=True)
class Tolerances:
    """What each comparison is judged against (change any with ``labkit report --tolerance KEY=VALUE``).

    Defaults, and why:

    * ``speed_relative_rms_max = 0.30``: the nominal robot's RMS speed error over the RMS
      measured speed. The paper's simulated speeds follow the measured ones within about a
      third at the same drive; a model that misses by more does not reproduce Fig. 8.
    * ``speed_coverage_min = 0.5``: fraction of measured speeds inside the Monte Carlo
      ``band_lo_pct``-``band_hi_pct`` percentile band (0.8 expected if the draws describe the
      robots' spread; 0.5 leaves room for few points and few draws).
    * ``band_lo_pct = 10``, ``band_hi_pct = 90``: the band drawn and scored.
    * ``knee_amplitude_ratio_max = 1.33`` (and its inverse as the minimum): simulated over
      measured knee amplitude at the drive frequency, a third either way.
    * ``knee_phase_deg_max = 20``: phase of the knee relative to the tray, simulated minus
      measured (one twentieth of a period is about the vibrometer/scope timing one trusts).
    * ``knee_correlation_min = 0.9``: correlation of one phase-folded period.
    * ``pattern_agreement_min = 0.75``: fraction of drives with the same leg pattern.
    * ``fit_quality_min = 0.95``: the fit's quality (1 - NRMSE^2, worst location).
    """

    speed_relative_rms_max: float = 0.30
    speed_coverage_min: float = 0.5
    band_lo_pct: float = 10.0
    band_hi_pct: float = 90.0
    knee_amplitude_ratio_max: float = 1.33
    knee_phase_deg_max: float = 20.0
    knee_correlation_min: float = 0.9
    pattern_agreement_min: float = 0.75
    fit_quality_min: float = 0.95

    @classmethod
    def from_mapping(cls, values: Mapping[str, float] | None) -> Tolerances:
        """Defaults overridden by ``values``; an unknown key raises ValueError naming the known ones."""
        names = {f.name for f in fields(cls)}
        bad = sorted(set(values or {}) - names)
        if bad:
            raise ValueError(f"unknown tolerance {', '.join(bad)} (known: {', '.join(sorted(names))})")
        t = cls(**{k: float(v) for k, v in (values or {}).items()})
        for name, value in t.as_dict().items():
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} = {value:g}: expected a finite number >= 0")
        for name in ("speed_coverage_min", "knee_correlation_min", "pattern_agreement_min", "fit_quality_min"):
            if getattr(t, name) > 1:
                raise ValueError(f"{name} = {getattr(t, name):g}: expected a fraction in [0, 1]")
        if t.knee_amplitude_ratio_max < 1:
            raise ValueError(f"knee_amplitude_ratio_max = {t.knee_amplitude_ratio_max:g}: expected >= 1 "
                             "(its inverse is the minimum)")
        if not 0 <= t.band_lo_pct < t.band_hi_pct <= 100:
            raise ValueError("band_lo_pct and band_hi_pct must satisfy 0 <= lo < hi <= 100")
        return t

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def verdict(value: float | None, *, at_most: float | None = None, at_least: float | None = None) -> str:
    """``"pass"`` if ``value`` is within the limit(s), ``"fail"`` if not, ``"n/a"`` without a value."""
    if value is None or not np.isfinite(value):
        return "n/a"
    ok = (at_most is None or value <= at_most) and (at_least is None or value >= at_least)
    return "pass" if ok else "fail"


# --------------------------------------------------------------------------- leg patterns

@dataclass(frozen=True)
class PatternMatch(Result):
    """One condition of :func:`pattern_agreement`: what it is (``key``), both labels, whether they agree."""

    key: str | float | None
    measured: str
    simulated: str
    agree: bool


@dataclass(frozen=True)
class PatternAgreement(Result):
    """:func:`pattern_agreement`: the fraction agreeing, the confusion counts and every pair."""

    n: int
    fraction_agree: float | None
    confusion: dict[str, dict[str, int]]
    pairs: tuple[PatternMatch, ...]
    provenance: dict[str, Json]


def pattern_agreement(measured: Sequence[str], simulated: Sequence[str], *,
                      keys: Sequence[str | float] | None = None,
                      provenance: Mapping[str, Json] | None = None) -> PatternAgreement:
    """Agreement of observed and simulated leg-motion patterns, one label per condition.

    Parameters
    ----------
    measured, simulated:
        Labels from :data:`PATTERNS`, paired by position (one per drive
        condition; for a simulation with many feet and draws pass the
        dominant one, see :func:`dominant_pattern`).
    keys:
        What each pair is (a frequency, a drive voltage), for the table.

    Returns
    -------
    PatternAgreement
        ``n``, ``fraction_agree``, ``confusion`` (measured -> simulated ->
        count), ``pairs`` and ``provenance``.
    """
    meas = [str(m) for m in measured]
    sim = [str(s) for s in simulated]
    if len(meas) != len(sim):
        raise ValueError(f"{len(meas)} measured patterns but {len(sim)} simulated")
    for label in meas + sim:
        if label not in PATTERNS:
            raise ValueError(f"unknown pattern label {label!r} (expected one of {', '.join(PATTERNS)})")
    names: list[str | float] = list(range(len(meas))) if keys is None else list(keys)
    confusion = {a: {b: 0 for b in PATTERNS} for a in PATTERNS}
    for a, b in zip(meas, sim):
        confusion[a][b] += 1
    agree = [a == b for a, b in zip(meas, sim)]
    return PatternAgreement(len(meas), _f(np.mean(agree)) if agree else None, confusion,
                            tuple(PatternMatch(k if isinstance(k, str) else _f(k), a, b, bool(c))
                                  for k, a, b, c in zip(names, meas, sim, agree)),
                            dict(provenance or {}))


def dominant_pattern(labels: Sequence[str] | np.ndarray) -> str:
    """The most frequent label (ties go to the first in :data:`PATTERNS`)."""
    flat = [str(x) for x in np.asarray(labels).ravel()]
    return max(PATTERNS, key=lambda p: flat.count(p))


# --------------------------------------------------------------------------- knee vertical motion

def fold_period(t_s: np.ndarray, x: np.ndarray, freq_hz: float, *, bins: int = 64,
                phase_rad: float = 0.0) -> np.ndarray:
    """Average ``x`` over drive periods into ``bins`` phase bins (phase measured from ``phase_rad``).

    Empty bins are filled by circular interpolation.
    """
    t = np.asarray(t_s, float)
    x = np.asarray(x, float)
    phase = np.mod(2 * np.pi * freq_hz * t + phase_rad, 2 * np.pi) / (2 * np.pi)
    idx = np.minimum((phase * bins).astype(int), bins - 1)
    sums = np.bincount(idx, weights=x, minlength=bins)
    counts = np.bincount(idx, minlength=bins)
    out = np.full(bins, np.nan)
    ok = counts > 0
    out[ok] = sums[ok] / counts[ok]
    if not ok.all() and ok.any():
        centres = (np.arange(bins) + 0.5) / bins
        out[~ok] = np.interp(centres[~ok], centres[ok], out[ok], period=1.0)
    return out


@dataclass(frozen=True)
class KneeAgreement(Result):
    """:func:`knee_motion_agreement`: fundamentals, their ratio and phase difference, the folded periods."""

    freq_hz: float
    amplitude_meas_mm_s: float | None
    amplitude_sim_mm_s: float | None
    amplitude_ratio: float | None
    phase_meas_deg: float | None
    phase_sim_deg: float | None
    phase_diff_deg: float | None
    correlation: float | None
    rms_diff_mm_s: float | None
    method: str
    cycle_meas_mm_s: list[float | None]
    cycle_sim_mm_s: list[float | None]
    provenance: dict[str, Json]


def knee_motion_agreement(t_meas_s: np.ndarray, vz_meas_mm_s: np.ndarray,
                          t_sim_s: np.ndarray, vz_sim_mm_s: np.ndarray, freq_hz: float, *,
                          ref_meas: np.ndarray | None = None, ref_sim: np.ndarray | None = None,
                          bins: int = 64, provenance: Mapping[str, Json] | None = None) -> KneeAgreement:
    """Compare measured and simulated knee vertical velocity at one drive.

    Phases are taken relative to a reference signal recorded with each (the
    tray's velocity or displacement: ``ref_meas``, ``ref_sim``), so the
    arbitrary start times of the two records do not matter; without a
    reference, ``t = 0`` is taken as the tray's phase zero (true for the
    simulator, whose tray moves as ``A sin(2 pi f t)``).

    Returns
    -------
    KneeAgreement
        ``freq_hz``, ``amplitude_meas_mm_s``, ``amplitude_sim_mm_s``,
        ``amplitude_ratio`` (sim / meas), ``phase_meas_deg``,
        ``phase_sim_deg``, ``phase_diff_deg`` (sim - meas, wrapped to
        +-180), ``correlation`` (one drive period, phase-folded, both aligned
        to their reference), ``rms_diff_mm_s`` and ``provenance``.
    """
    fm = fundamental(t_meas_s, vz_meas_mm_s, freq_hz)
    fs = fundamental(t_sim_s, vz_sim_mm_s, freq_hz)
    ref_m = fundamental(t_meas_s, ref_meas, freq_hz)["phase_rad"] if ref_meas is not None else 0.0
    ref_s = fundamental(t_sim_s, ref_sim, freq_hz)["phase_rad"] if ref_sim is not None else 0.0
    phase_m = fm["phase_rad"] - ref_m
    phase_s = fs["phase_rad"] - ref_s
    diff = np.angle(np.exp(1j * (phase_s - phase_m)))
    # Fold both onto the tray's phase: bin 0 is where each reference crosses zero upward.
    cyc_m = fold_period(t_meas_s, vz_meas_mm_s, freq_hz, bins=bins, phase_rad=ref_m)
    cyc_s = fold_period(t_sim_s, vz_sim_mm_s, freq_hz, bins=bins, phase_rad=ref_s)
    return KneeAgreement(
        freq_hz=float(freq_hz),
        amplitude_meas_mm_s=_f(fm["amplitude"]),
        amplitude_sim_mm_s=_f(fs["amplitude"]),
        amplitude_ratio=_f(fs["amplitude"] / fm["amplitude"]) if fm["amplitude"] > 0 else None,
        phase_meas_deg=_f(np.degrees(np.angle(np.exp(1j * phase_m)))),
        phase_sim_deg=_f(np.degrees(np.angle(np.exp(1j * phase_s)))),
        phase_diff_deg=_f(np.degrees(diff)),
        correlation=_f(_corr(cyc_m, cyc_s)),
        rms_diff_mm_s=_f(np.sqrt(np.nanmean((cyc_s - cyc_m) ** 2))),
        method=f"fundamental by least squares at the drive frequency; correlation of one period "
               f"folded into {bins} phase bins, each aligned to its tray reference",
        cycle_meas_mm_s=[_f(v) for v in cyc_m],
        cycle_sim_mm_s=[_f(v) for v in cyc_s],
        provenance=dict(provenance or {}),
    )
