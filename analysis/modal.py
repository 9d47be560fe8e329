"""Resonance fitting: modes with standard uncertainties from one or several FRFs with common poles.

>>> fit = fit_modes(freq_hz, {"body": H_body, "knee": H_knee}, band_hz=(200, 5000))
>>> [(m.freq_hz, m.freq_hz_std, m.damping_ratio, m.damping_ratio_std) for m in fit.modes]

Methods
-------
``"lscf"`` (default)
    Poles from a least-squares complex-frequency (LSCF) stabilisation diagram
    (:mod:`analysis.modal_lscf`), chosen automatically (or the ``n_modes`` most
    stable), residues by linear least squares, then every pole, residue and
    residual term refined together by nonlinear least squares on the
    pole-residue model (:mod:`analysis.modal_refine`); standard uncertainties
    from the covariance at the optimum (robust sandwich form by default, or
    scaled by the residual variance).  Poles narrower than the line spacing or
    with residues below 3 standard uncertainties everywhere are dropped (with
    a warning) and the rest refitted; with several locations each is then
    weighted by its own noise level and refitted.  Resolves overlapping modes.
``"peak"``
    Peak picking on the locations' combined mobility magnitude, half-power
    bandwidth for damping (:mod:`analysis.modal_sdof`).
``"circle"``
    Peak picking, then a circle fit per mode in the Nyquist plane.

For ``"peak"`` and ``"circle"`` the residues come from linear least squares
with the poles fixed, and every standard uncertainty from a wild bootstrap
(the fitted model plus the residuals rotated by random phases, re-estimated
``n_boot`` times), which keeps each line's own noise level.

Conventions: the FRF is output over input with ``exp(+j w t)`` phasors (see
:mod:`analysis.frf`); a mode's ``amplitude`` is its complex residue ``R`` per
location in the model ``R / (j w - lam) + conj(R) / (j w - conj(lam))``
(units of the FRF times rad/s), ``lam = -zeta wn + j wn sqrt(1 - zeta^2)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from analysis import modal_sdof
from analysis.frf import KINDS
from analysis.modal_lscf import Stabilisation, choose_poles, modal_to_pole, pole_to_modal, stabilisation
from analysis.modal_refine import Channel, basis, refine, residues_ls
from labkit.errors import InputError

__all__ = ["Mode", "ModalFit", "fit_modes", "METHODS", "DEFAULT_RESIDUALS"]

METHODS = ("lscf", "peak", "circle")

#: Residual-term powers of ``j w`` by FRF kind (modes outside the band; see modal_refine).
DEFAULT_RESIDUALS = {"mobility": (-1, 0, 1), "receptance": (-2, 0), "accelerance": (0, 2),
                     "transmissibility": (0, 2)}


@dataclass
class Mode:
    """One fitted mode; ``*_std`` are standard uncertainties (1 sigma)."""

    freq_hz: float
    freq_hz_std: float
    damping_ratio: float
    damping_ratio_std: float
    amplitude: np.ndarray            # complex residue per location
    amplitude_std: np.ndarray        # sqrt(var Re + var Im) per location
    peak: np.ndarray                 # |R| / (zeta wn): the mode's own FRF peak per location
    dominant_location: str
    freq_damping_cov: float = 0.0    # covariance of freq_hz and damping_ratio (Hz)

    def to_dict(self, locations: Sequence[str]) -> dict[str, Any]:
        return {"freq_hz": self.freq_hz, "freq_hz_std": self.freq_hz_std,
                "damping_ratio": self.damping_ratio, "damping_ratio_std": self.damping_ratio_std,
                "dominant_location": self.dominant_location,
                "amplitude": {loc: [float(a.real), float(a.imag)] for loc, a in zip(locations, self.amplitude)},
                "amplitude_std": dict(zip(locations, map(float, self.amplitude_std))),
                "peak": dict(zip(locations, map(float, self.peak)))}


@dataclass
class ModalFit:
    """The result of :func:`fit_modes`."""

    modes: list[Mode]
    locations: list[str]
    method: str
    kind: str
    band_hz: tuple[float, float]
    residual_powers: tuple[int, ...]
    freq_hz: list[np.ndarray]                 # per location, the lines used
    frf: list[np.ndarray]                     # per location, measured
    residual_terms: list[np.ndarray]          # per location, complex coefficients of (j w)^q
    nrmse: dict[str, float]                   # per location, rms|model - H| / rms|H|
    quality: float                            # min over locations of 1 - nrmse^2
    dominant_mode: dict[str, int]             # per location, index into modes
    stabilisation: Stabilisation | None = None
    covariance: np.ndarray | None = None
    converged: bool = True
    warnings: list[str] = field(default_factory=list)

    def model(self, freq_hz: Any, location: int | str = 0) -> np.ndarray:
        """The fitted FRF at ``freq_hz`` for a location (index or name)."""
        k = self.locations.index(location) if isinstance(location, str) else int(location)
        lam = modal_to_pole(np.array([m.freq_hz for m in self.modes]),
                            np.array([m.damping_ratio for m in self.modes]))
        p = [v for m in self.modes for v in (m.amplitude[k].real, m.amplitude[k].imag)]
        p += [v for c in self.residual_terms[k] for v in (c.real, c.imag)]
        w = 2 * np.pi * np.asarray(freq_hz, dtype=float)
        return basis(w, lam, self.residual_powers) @ np.asarray(p, dtype=float)

    def summary(self) -> dict[str, Any]:
        """A JSON-able summary."""
        return {"method": self.method, "kind": self.kind, "band_hz": list(self.band_hz),
                "locations": self.locations, "n_modes": len(self.modes), "quality": self.quality,
                "nrmse": self.nrmse, "converged": self.converged,
                "dominant_mode": self.dominant_mode, "warnings": self.warnings,
                "modes": [m.to_dict(self.locations) for m in self.modes],
                "stabilisation": None if self.stabilisation is None else self.stabilisation.to_dict()}


# ---------------------------------------------------------------------------------------------
def _channels(freq_hz: Any, frf: Any, locations: Sequence[str] | None, weights: Any,
              band_hz: tuple[float, float] | None) -> tuple[list[Channel], tuple[float, float]]:
    if isinstance(frf, Mapping):
        names = [str(k) for k in frf]
        frfs = [frf[k] for k in frf]
    else:
        arr = frf if isinstance(frf, (list, tuple)) else np.asarray(frf)
        if isinstance(arr, np.ndarray) and arr.ndim == 1:
            frfs = [arr]
        elif isinstance(arr, np.ndarray) and arr.ndim == 2:
            frfs = list(arr)
        elif isinstance(arr, (list, tuple)):
            frfs = list(arr)
        else:
            raise InputError(f"frf has {np.ndim(arr)} dimensions", expected="1-D, (locations, lines), list or dict")
        names = list(locations) if locations is not None else (
            ["0"] if len(frfs) == 1 else [str(i) for i in range(len(frfs))])
    if locations is not None and len(locations) != len(frfs):
        raise InputError(f"{len(locations)} location names for {len(frfs)} FRFs", expected="one name per FRF")
    if isinstance(freq_hz, (list, tuple)) and len(freq_hz) and np.ndim(freq_hz[0]) == 1:
        freqs = list(freq_hz)
    else:
        freqs = [freq_hz] * len(frfs)
    if len(freqs) != len(frfs):
        raise InputError(f"{len(freqs)} frequency axes for {len(frfs)} FRFs", expected="one per FRF or one shared")
    wts = [None] * len(frfs) if weights is None else (
        [weights[k] for k in weights] if isinstance(weights, Mapping) else list(np.atleast_2d(weights)))
    raw = []
    for name, f, h, wt in zip(names, freqs, frfs, wts):
        try:
            f = np.asarray(f, dtype=float)
            h = np.asarray(h, dtype=complex)
        except (TypeError, ValueError):
            raise InputError(f"location {name!r}: not numeric", expected="numbers") from None
        if f.ndim != 1 or h.shape != f.shape:
            raise InputError(f"location {name!r}: freq_hz has shape {f.shape}, frf {h.shape}",
                             expected="1-D arrays of equal length")
        wt = np.ones(f.size) if wt is None else np.asarray(wt, dtype=float)
        if wt.shape != f.shape:
            raise InputError(f"location {name!r}: weights have shape {wt.shape}", expected=f"{f.shape}")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(h)) and np.all(np.isfinite(wt))):
            raise InputError(f"location {name!r}: NaN or infinite values in freq_hz, frf or weights",
                             expected="finite numbers (drop bad points first)")
        if np.any(f <= 0):
            raise InputError(f"location {name!r}: freq_hz <= 0", expected="frequencies > 0 Hz")
        raw.append((name, f, h, wt))
    if not raw:
        raise InputError("no FRF given", expected="at least one location")
    if band_hz is None:
        band = (min(float(r[1].min()) for r in raw), max(float(r[1].max()) for r in raw))
    else:
        band = (float(band_hz[0]), float(band_hz[1]))
        if not (0 < band[0] < band[1]):
            raise InputError(f"band_hz = {band_hz!r}", expected="0 < low < high")
    chans = []
    for name, f, h, wt in raw:
        sel = (f >= band[0]) & (f <= band[1]) & (wt > 0)
        o = np.argsort(f[sel])
        f, h, wt = f[sel][o], h[sel][o], wt[sel][o]
        if f.size < 12:
            raise InputError(f"location {name!r}: only {f.size} lines in {band[0]:g}-{band[1]:g} Hz",
                             expected="at least 12 frequency lines")
        rms = float(np.sqrt(np.mean(np.abs(h) ** 2)))
        if rms == 0:
            raise InputError(f"location {name!r}: the FRF is zero everywhere", expected="a response")
        chans.append(Channel(name, 2 * np.pi * f, h, wt / rms))
    return chans, band


def fit_modes(freq_hz: Any, frf: Any, n_modes: int | None = None, band_hz: tuple[float, float] | None = None,
              method: str = "lscf", *, locations: Sequence[str] | None = None, weights: Any = None,
              kind: str = "mobility", residual_powers: Sequence[int] | None = None,
              covariance: str = "sandwich", n_max: int | None = None, n_boot: int = 100,
              seed: int = 0) -> ModalFit:
    """Fit modes (common poles) to one or several FRFs.

    Parameters
    ----------
    freq_hz:
        Frequency lines, one array shared by every location or a list with one
        per location.
    frf:
        Complex FRF: ``(lines,)``, ``(locations, lines)``, a list, or a dict
        ``{location: frf}``.
    n_modes:
        Number of modes; ``None`` chooses from the stabilisation diagram
        (``"lscf"``) or from peak prominence (``"peak"``, ``"circle"``).
    band_hz:
        ``(low, high)``: only lines inside are fitted.
    method:
        ``"lscf"``, ``"peak"`` or ``"circle"`` (see the module docstring).
    locations:
        Names when ``frf`` is not a dict.
    weights:
        Optional per-line weights (>= 0; 0 drops a line), same layout as ``frf``.
    kind:
        ``"mobility"``, ``"receptance"``, ``"accelerance"`` or ``"transmissibility"``
        (robot over base velocity); sets the residual terms and the form the
        single-mode methods work on.
    residual_powers:
        Powers ``q`` of ``(j w)^q`` terms for out-of-band modes (default by kind).
    covariance:
        ``"sandwich"`` (default; HC3, honest when the noise level varies from
        line to line, as it does along a sweep) or ``"residual"``
        (``s^2 (J^T J)^-1``, for white noise of one level).
    n_max:
        Highest LSCF order in the stabilisation diagram.
    n_boot, seed:
        Bootstrap replicates and seed for ``"peak"`` and ``"circle"``.

    Raises
    ------
    InputError
        Mismatched lengths, NaN or infinite values, frequencies <= 0, fewer than
        12 lines in the band, an unknown method or kind.
    """
    if method not in METHODS:
        raise InputError(f"method = {method!r}", expected=f"one of {', '.join(METHODS)}")
    if kind not in DEFAULT_RESIDUALS:
        raise InputError(f"kind = {kind!r}", expected=f"one of {', '.join(DEFAULT_RESIDUALS)}")
    if covariance not in ("residual", "sandwich"):
        raise InputError(f"covariance = {covariance!r}", expected="'residual' or 'sandwich'")
    if n_modes is not None and (int(n_modes) != n_modes or n_modes < 1):
        raise InputError(f"n_modes = {n_modes!r}", expected="an integer >= 1 or None")
    chans, band = _channels(freq_hz, frf, locations, weights, band_hz)
    powers = tuple(DEFAULT_RESIDUALS[kind] if residual_powers is None else residual_powers)
    n_lines = min(c.w.size for c in chans)
    warnings: list[str] = []
    if method == "lscf":
        if n_max is None:
            n_max = int(min(40, 32 if n_modes is None else max(16, 4 * n_modes + 12), 2 * ((n_lines - 4) // 2)))
        stab = stabilisation([(c.w, c.H, c.weight) for c in chans], n_max, band)
        lam0 = choose_poles(stab, n_modes, band_hz=band)
        if n_modes is not None and lam0.size < n_modes:
            warnings.append(f"only {lam0.size} of {n_modes} modes found in the stabilisation diagram")
        if lam0.size == 0:
            raise InputError("no stable mode found in the band", expected="an FRF with a resonance")
        stab.chosen_hz = pole_to_modal(lam0)[0]
        _check_size(chans, lam0.size, powers)
        ref = refine(chans, lam0, powers, band_hz=band, covariance=covariance)
        for _ in range(3):
            keep = _credible(chans, ref, warnings)
            if keep.all() or not keep.any():
                break
            ref = refine(chans, modal_to_pole(ref.freq_hz[keep], ref.damping_ratio[keep]), powers,
                         band_hz=band, covariance=covariance)
        if len(chans) > 1:
            # Weight each location by its own noise level (feasible weighted least squares).
            _reweight(chans, ref, powers)
            ref = refine(chans, modal_to_pole(ref.freq_hz, ref.damping_ratio), powers, band_hz=band,
                         covariance=covariance)
        if n_modes is not None and ref.freq_hz.size < n_modes:
            warnings.append(f"{ref.freq_hz.size} of the {n_modes} modes asked for are credible")
        if not ref.success:
            warnings.append("nonlinear refinement did not converge")
        order = np.argsort(ref.freq_hz)
        m = ref.freq_hz.size
        std = np.sqrt(np.clip(np.diag(ref.cov), 0, None))
        f_std, z_std = std[0:2 * m:2], std[1:2 * m:2]
        lin = ref.lin
        lin_var = [np.clip(np.diag(ref.cov)[2 * m + k * lin[0].size: 2 * m + (k + 1) * lin[0].size], 0, None)
                   for k in range(len(chans))]
        fz_cov = np.array([ref.cov[2 * i, 2 * i + 1] for i in range(m)])
        fit = _assemble(chans, ref.freq_hz, ref.damping_ratio, f_std, z_std, lin, lin_var, order,
                        method, kind, band, powers, stab, ref.cov, ref.success, warnings, fz_cov)
        _warn_outside(fit)
        return fit
    return _fit_sdof(chans, n_modes, band, method, kind, powers, n_boot, seed, warnings)


def _credible(chans: list[Channel], ref, warnings: list[str]) -> np.ndarray:
    """Which refined modes are real: resolvable by the line spacing and significantly non-zero.

    A mode narrower than the spacing of the lines around it (half-power
    bandwidth ``2 zeta f`` below it) is fitting noise between lines; a mode
    whose residue is nowhere larger than 3 standard uncertainties is not
    supported by the data.
    """
    m = ref.freq_hz.size
    n_lin = ref.lin[0].size
    var = np.clip(np.diag(ref.cov), 0, None)
    keep = np.ones(m, dtype=bool)
    for i in range(m):
        f, z = ref.freq_hz[i], ref.damping_ratio[i]
        spacing = np.inf
        snr = 0.0
        for k, c in enumerate(chans):
            fk = c.w / (2 * np.pi)
            j = int(np.searchsorted(fk, f))
            near = fk[max(j - 1, 0):j + 1]
            if near.size == 2 and fk[0] <= f <= fk[-1]:
                spacing = min(spacing, float(near[1] - near[0]))
            R = abs(complex(ref.lin[k][2 * i], ref.lin[k][2 * i + 1]))
            sd = np.sqrt(var[2 * m + k * n_lin + 2 * i] + var[2 * m + k * n_lin + 2 * i + 1])
            snr = max(snr, R / sd if sd > 0 else np.inf)
        if 2 * z * f < spacing:
            keep[i] = False
            warnings.append(f"dropped a pole at {f:.5g} Hz: narrower (2 zeta f = {2 * z * f:.3g} Hz) than the "
                            f"line spacing ({spacing:.3g} Hz)")
        elif snr < 3.0:
            keep[i] = False
            warnings.append(f"dropped a pole at {f:.5g} Hz: its residue is below 3 standard uncertainties")
    return keep


def _check_size(chans: list[Channel], m: int, powers: Sequence[int]) -> None:
    n_obs = sum(2 * c.w.size for c in chans)
    n_par = 2 * m + len(chans) * (2 * m + 2 * len(powers))
    if n_obs <= n_par + 2:
        raise InputError(f"{n_obs // 2} lines cannot fit {m} modes with {len(powers)} residual terms",
                         expected="more frequency lines or fewer modes")


def _reweight(chans: list[Channel], ref, powers: Sequence[int]) -> None:
    lam = modal_to_pole(ref.freq_hz, ref.damping_ratio)
    for c, p in zip(chans, ref.lin):
        r = (basis(c.w, lam, powers) @ p - c.H) * c.weight
        n_par = p.size + 2 * lam.size / len(chans)
        s = np.sqrt(np.sum(np.abs(r) ** 2) / max(2 * c.w.size - n_par, 1) * 2)
        if s > 0:
            c.weight = c.weight / s


def _assemble(chans, f, z, f_std, z_std, lin, lin_var, order, method, kind, band, powers, stab, cov,
              converged, warnings, fz_cov=None) -> ModalFit:
    m = len(f)
    names = [c.name for c in chans]
    modes = []
    for i in order:
        amp = np.array([p[2 * i] + 1j * p[2 * i + 1] for p in lin])
        amp_std = np.array([np.sqrt(v[2 * i] + v[2 * i + 1]) for v in lin_var])
        wn = 2 * np.pi * f[i]
        peak = np.abs(amp) / max(z[i] * wn, 1e-300)
        modes.append(Mode(float(f[i]), float(f_std[i]), float(z[i]), float(z_std[i]), amp, amp_std, peak,
                          names[int(np.argmax(peak))], 0.0 if fz_cov is None else float(fz_cov[i])))
    resid_terms = [np.array([p[2 * m + 2 * k] + 1j * p[2 * m + 2 * k + 1] for k in range(len(powers))])
                   for p in lin]
    fit = ModalFit(modes, names, method, kind, band, tuple(powers), [c.w / (2 * np.pi) for c in chans],
                   [c.H for c in chans], resid_terms, {}, 0.0, {}, stab, cov, converged, warnings)
    q = []
    for k, c in enumerate(chans):
        r = fit.model(c.w / (2 * np.pi), k) - c.H
        nr = float(np.sqrt(np.sum(np.abs(r) ** 2) / np.sum(np.abs(c.H) ** 2)))
        fit.nrmse[c.name] = nr
        q.append(1 - nr ** 2)
        fit.dominant_mode[c.name] = int(np.argmax([md.peak[k] for md in modes])) if modes else -1
    fit.quality = float(np.clip(min(q), 0.0, 1.0))
    return fit


def _warn_outside(fit: ModalFit) -> None:
    """Warn about modes the refinement pushed out of the band (they model out-of-band behaviour)."""
    lo, hi = fit.band_hz
    for md in fit.modes:
        if not (lo <= md.freq_hz <= hi):
            fit.warnings.append(f"mode at {md.freq_hz:.4g} Hz lies outside the band {lo:g}-{hi:g} Hz")


# ---------------------------------------------------------------------------------------------
def _as_mobility(chans: list[Channel], kind: str) -> list[np.ndarray]:
    out = []
    for c in chans:
        h = c.H - 1.0 if kind == "transmissibility" else c.H
        p = 1 - (KINDS["accelerance"] if kind == "transmissibility" else KINDS[kind])
        out.append(h * (1j * c.w) ** p)
    return out


def _sdof_poles(chans: list[Channel], n_modes: int | None, method: str, kind: str,
                f_grid: np.ndarray) -> np.ndarray:
    mob = [np.interp(f_grid, c.w / (2 * np.pi), m.real) + 1j * np.interp(f_grid, c.w / (2 * np.pi), m.imag)
           for c, m in zip(chans, _as_mobility(chans, kind))]
    wts = [1.0 / np.sqrt(np.mean(np.abs(m) ** 2)) for m in mob]
    a = modal_sdof.indicator(mob, wts)
    peaks = modal_sdof.pick_peaks(f_grid, a, n_modes)
    fz = []
    for k in peaks:
        fn, z = modal_sdof.half_power(f_grid, a, int(k))
        if not np.isfinite(z) or z <= 0:
            continue
        if method == "circle":
            best = int(np.argmax([wt * abs(m[k]) for m, wt in zip(mob, wts)]))
            try:
                fn, z = modal_sdof.circle_fit(f_grid, mob[best], fn, z)
            except (ValueError, np.linalg.LinAlgError):
                pass
        fz.append((fn, min(z, 0.95)))
    if not fz:
        return np.zeros(0, complex)
    fz_a = np.array(fz)
    return modal_to_pole(fz_a[:, 0], fz_a[:, 1])


def _fit_sdof(chans, n_modes, band, method, kind, powers, n_boot, seed, warnings) -> ModalFit:
    f_grid = np.unique(np.concatenate([c.w / (2 * np.pi) for c in chans]))
    lam = _sdof_poles(chans, n_modes, method, kind, f_grid)
    if lam.size == 0:
        raise InputError("no resonance peak found in the band", expected="an FRF with a resonance")
    if n_modes is not None and lam.size < n_modes:
        warnings.append(f"only {lam.size} of {n_modes} peaks found")
    _check_size(chans, lam.size, powers)
    lin = residues_ls(chans, lam, powers)
    f0, z0 = pole_to_modal(lam)
    # Wild bootstrap: model + residuals with random phases (keeps each line's noise level).
    rng = np.random.default_rng(seed)
    fitted = [basis(c.w, lam, powers) @ p for c, p in zip(chans, lin)]
    resid = [c.H - fh for c, fh in zip(chans, fitted)]
    boots_f, boots_z, boots_lin = [], [], []
    for _ in range(n_boot):
        bc = [Channel(c.name, c.w, fh + r * np.exp(2j * np.pi * rng.random(r.size)), c.weight)
              for c, fh, r in zip(chans, fitted, resid)]
        lb = _sdof_poles(bc, lam.size, method, kind, f_grid)
        if lb.size != lam.size:
            continue
        fb, zb = pole_to_modal(lb)
        boots_f.append(fb)
        boots_z.append(zb)
        boots_lin.append(residues_ls(bc, lb, powers))
    if len(boots_f) < max(10, n_boot // 2):
        warnings.append(f"only {len(boots_f)} of {n_boot} bootstrap replicates found every mode")
    if boots_f:
        f_std = np.std(boots_f, axis=0, ddof=1) if len(boots_f) > 1 else np.full(lam.size, np.nan)
        z_std = np.std(boots_z, axis=0, ddof=1) if len(boots_z) > 1 else np.full(lam.size, np.nan)
        lin_var = [np.var([b[k] for b in boots_lin], axis=0, ddof=1) for k in range(len(chans))]
        fz_cov = np.array([np.cov(np.array(boots_f)[:, i], np.array(boots_z)[:, i])[0, 1]
                           if len(boots_f) > 1 else np.nan for i in range(lam.size)])
    else:
        fz_cov = np.full(lam.size, np.nan)
        f_std = z_std = np.full(lam.size, np.nan)
        lin_var = [np.full(p.size, np.nan) for p in lin]
    order = np.argsort(f0)
    fit = _assemble(chans, f0, z0, f_std, z_std, lin, lin_var, order, method, kind, band, powers, None,
                    None, True, warnings, fz_cov)
    _warn_interference(fit)
    return fit


def _warn_interference(fit: ModalFit, limit: float = 0.03) -> None:
    """Warn where other modes (and residual terms) add more than ``limit`` of a mode's own peak.

    Single-mode estimators assume each resonance is alone; there the result is
    biased, and a bootstrap uncertainty covers noise, not that bias.
    """
    for m in fit.modes:
        k = fit.locations.index(m.dominant_location)
        lam = modal_to_pole(np.array([m.freq_hz]), np.array([m.damping_ratio]))[0]
        jw = 2j * np.pi * m.freq_hz
        R = m.amplitude[k]
        own = R / (jw - lam) + np.conj(R) / (jw - np.conj(lam))
        rest = fit.model([m.freq_hz], k)[0] - own
        ratio = abs(rest) / max(abs(own), 1e-300)
        if ratio > limit:
            fit.warnings.append(f"mode at {m.freq_hz:.4g} Hz: neighbouring modes add {ratio:.0%} of its peak "
                                f"at {m.dominant_location}; single-mode estimates are biased there (the "
                                "bootstrap uncertainty covers noise, not that bias): use method 'lscf'")
