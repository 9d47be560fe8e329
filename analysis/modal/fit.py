"""Resonance fitting: modes with standard uncertainties from one or several FRFs with common poles.

>>> fit = fit_modes(freq_hz, {"body": H_body, "knee": H_knee}, band_hz=(200, 5000))
>>> [(m.freq_hz, m.freq_hz_std, m.damping_ratio, m.damping_ratio_std) for m in fit.modes]

Units and band placement do not matter: the frequencies are divided by the
band's centre before anything is computed (and the results multiplied back),
and the pole search maps the band onto the unit circle whatever its width
(:mod:`labkit.analysis.modal.lscf`), so the same data in Hz, kHz or GHz, over
a +-1 % band or a decade, give the same modes.

Methods
-------
``"lscf"`` (default)
    Poles from a least-squares complex-frequency (LSCF) stabilisation diagram
    (:mod:`labkit.analysis.modal.lscf`), chosen automatically (or the ``n_modes`` most
    stable), residues by linear least squares, then every pole, residue and
    residual term refined together by nonlinear least squares on the
    pole-residue model (:mod:`labkit.analysis.modal.refine`); standard uncertainties
    from the covariance at the optimum (robust sandwich form by default, or
    scaled by the residual variance).  With ``n_modes`` given, exactly that
    many modes are returned (poles the diagram does not offer are added where
    the residual is largest) or an error is raised.  Without it, poles
    with residues below 3 standard uncertainties everywhere are dropped (with
    a warning) and the rest refitted, and while the misfit is well above the
    noise level estimated from the data (:mod:`labkit.analysis.modal.noise`) a
    mode is added where the residual is largest and kept if it is credible
    (also: wider than the line spacing) and lowers the misfit.  Modes from
    the diagram narrower than the line spacing (lightly damped modes of an
    impact test) are kept, with a warning that their damping is not
    trustworthy.  With several locations each is weighted by its own noise
    level estimated from the data.
    Resolves overlapping modes.
``"peak"``
    Peak picking on the locations' combined mobility magnitude, half-power
    bandwidth for damping (:mod:`labkit.analysis.modal.sdof`).
``"circle"``
    Peak picking, then a circle fit per mode in the Nyquist plane.

``poles_hz`` (any method)
    Poles chosen by hand: the frequencies are held, damping ratios (unless
    given too) and residues fitted.

Every fit reports ``misfit_to_noise`` per location; above
:data:`MISFIT_WARN` the fit warns and its ``quality`` drops accordingly.
``background="linear"`` adds a constant and a slope to the model (a
resonance over a background, or seen as a dip); ``"linear+delay"`` also a
line delay ``exp(-j w tau)`` (reflection data, e.g. S11).

For ``"peak"`` and ``"circle"`` the residues come from linear least squares
with the poles fixed, and every standard uncertainty from a wild bootstrap
(the fitted model plus the residuals rotated by random phases, re-estimated
``n_boot`` times), which keeps each line's own noise level.

Conventions: the FRF is output over input with ``exp(+j w t)`` phasors (see
:mod:`labkit.analysis.frf`); a mode's ``amplitude`` is its complex residue ``R`` per
location in the model ``R / (j w - lam) + conj(R) / (j w - conj(lam))``
(units of the FRF times rad/s), ``lam = -zeta wn + j wn sqrt(1 - zeta^2)``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labkit.analysis.frf import KINDS
from labkit.analysis.modal import sdof as modal_sdof
from labkit.analysis.modal.lscf import Stabilisation, choose_poles, modal_to_pole, pole_to_modal, stabilisation
from labkit.analysis.modal.noise import misfit_to_noise, noise_variance
from labkit.analysis.modal.refine import Channel, Refined, _same_grid, basis, model_variance, refine, residues_ls
from labkit.errors import InputError as _InputError

__all__ = ["Mode", "ModalFit", "fit_modes", "FitInputError", "METHODS", "DEFAULT_RESIDUALS", "BACKGROUNDS",
           "MISFIT_WARN"]

METHODS = ("lscf", "peak", "circle")

#: Residual-term powers of ``j w`` by FRF kind (modes outside the band; see modal_refine).
#: ``scattering`` (S-parameters, dimensionless): a constant and a slope (the background).
DEFAULT_RESIDUALS = {"mobility": (-1, 0, 1), "receptance": (-2, 0), "accelerance": (0, 2),
                     "transmissibility": (0, 2), "scattering": (0, 1)}

BACKGROUNDS = (None, "linear", "linear+delay")


class FitInputError(_InputError, ValueError):
    """Bad input to a fit: a ``ValueError`` to library callers, exit code 2 from the command line."""


InputError = FitInputError

#: BLAS threads inside a fit (see :func:`fit_modes`; ``threadpoolctl`` sets them and restores them after).
FIT_BLAS_THREADS = 1

#: A misfit above this many times the noise level is a warning (and lowers ``quality``).
MISFIT_WARN = 2.0


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
    given: bool = False              # frequency chosen by hand (poles_hz), not fitted
    in_band: bool = True             # False: a pole fitted outside the band (a mode outside, seen by its tail)

    def to_dict(self, locations: Sequence[str]) -> dict[str, Any]:
        return {"freq_hz": self.freq_hz, "freq_hz_std": self.freq_hz_std,
                "damping_ratio": self.damping_ratio, "damping_ratio_std": self.damping_ratio_std,
                "dominant_location": self.dominant_location, "given": self.given, "in_band": self.in_band,
                "amplitude": {loc: [float(a.real), float(a.imag)] for loc, a in zip(locations, self.amplitude)},
                "amplitude_std": dict(zip(locations, map(float, self.amplitude_std))),
                "peak": dict(zip(locations, map(float, self.peak)))}


@dataclass
class ModalFit:
    """The result of :func:`fit_modes`.

    ``quality`` is the smallest over locations of ``1 - nrmse^2``, lowered to
    ``(MISFIT_WARN / misfit_to_noise)^2`` where the misfit is more than
    :data:`MISFIT_WARN` times the noise level estimated from the data: a fit
    that leaves structure in its residual never reads as good.
    """

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
    quality: float                            # see the class docstring
    dominant_mode: dict[str, int]             # per location, index into modes
    stabilisation: Stabilisation | None = None
    covariance: np.ndarray | None = None
    converged: bool = True
    warnings: list[str] = field(default_factory=list)
    misfit_to_noise: dict[str, float] = field(default_factory=dict)
    delay_s: float = 0.0                      # line delay: the model is multiplied by exp(-j w delay_s)
    background: str | None = None

    def model(self, freq_hz: Any, location: int | str = 0) -> np.ndarray:
        """The fitted FRF at ``freq_hz`` for a location (index or name)."""
        k = self.locations.index(location) if isinstance(location, str) else int(location)
        return self._models(np.asarray(freq_hz, dtype=float), [k])[0]

    def _models(self, freq_hz: np.ndarray, ks: Sequence[int]) -> list[np.ndarray]:
        """The fitted FRFs of locations ``ks`` at the same lines (the basis computed once)."""
        lam = modal_to_pole(np.array([m.freq_hz for m in self.modes]),
                            np.array([m.damping_ratio for m in self.modes]))
        w = 2 * np.pi * freq_hz
        B = basis(w, lam, self.residual_powers)
        out = []
        for k in ks:
            p = [v for m in self.modes for v in (m.amplitude[k].real, m.amplitude[k].imag)]
            p += [v for c in self.residual_terms[k] for v in (c.real, c.imag)]
            h = B @ np.asarray(p, dtype=float)
            out.append(h * np.exp(-1j * w * self.delay_s) if self.delay_s else h)
        return out

    def fitted(self) -> list[np.ndarray]:
        """Each location's fitted FRF at its own lines (the basis once when they share them)."""
        f0 = self.freq_hz[0]
        if all(f is f0 or (f.shape == f0.shape and np.array_equal(f, f0)) for f in self.freq_hz):
            return self._models(f0, range(len(self.locations)))
        return [self.model(f, k) for k, f in enumerate(self.freq_hz)]

    def shapes(self) -> np.ndarray:
        """Mode shapes: complex residues, ``(modes, locations)`` (see :mod:`labkit.analysis.modal.shapes`)."""
        return np.array([m.amplitude for m in self.modes]).reshape(len(self.modes), len(self.locations))

    def summary(self) -> dict[str, Any]:
        """A JSON-able summary."""
        return {"method": self.method, "kind": self.kind, "band_hz": list(self.band_hz),
                "locations": self.locations, "n_modes": len(self.modes), "quality": self.quality,
                "nrmse": self.nrmse, "misfit_to_noise": self.misfit_to_noise, "converged": self.converged,
                "dominant_mode": self.dominant_mode, "warnings": self.warnings,
                "residual_powers": list(self.residual_powers), "background": self.background,
                "delay_s": self.delay_s,
                "modes": [m.to_dict(self.locations) for m in self.modes],
                "mac": self.mac().tolist() if len(self.locations) > 1 and self.modes else None,
                "stabilisation": None if self.stabilisation is None else self.stabilisation.to_dict()}

    def mac(self, other: ModalFit | None = None) -> np.ndarray:
        """MAC between this fit's mode shapes (and ``other``'s; see :mod:`labkit.analysis.modal.shapes`)."""
        from labkit.analysis.modal.shapes import mac

        return mac(self, other)


# ---------------------------------------------------------------------------------------------
def _channels(freq_hz: Any, frf: Any, locations: Sequence[str] | None, weights: Any,
              band_hz: tuple[float, float] | None) -> tuple[list[Channel], tuple[float, float]]:
    if isinstance(frf, Mapping):
        names = [str(k) for k in frf]
        frfs = [frf[k] for k in frf]
    else:
        arr = frf if isinstance(frf, (list, tuple)) else np.asarray(frf)
        if isinstance(arr, (list, tuple)) and len(arr) and all(np.ndim(x) == 0 for x in arr):
            arr = np.asarray(arr)               # a list of numbers is one FRF, not one location per number
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
        if f.size == 0 or h.size == 0:
            raise InputError(f"location {name!r}: empty freq_hz or frf", expected="1-D arrays of frequency lines")
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
        dup = f[1:][np.diff(f) == 0]
        if dup.size:
            raise InputError(f"location {name!r}: frequency {dup[0]:g} appears more than once ({dup.size} "
                             "repeated lines)", expected="distinct lines (average repeated measurements first)")
        rms = float(np.sqrt(np.mean(np.abs(h) ** 2)))
        if rms == 0:
            raise InputError(f"location {name!r}: the FRF is zero everywhere", expected="a response")
        if float(np.max(np.abs(h - h.mean()))) <= 1e-9 * rms:
            raise InputError(f"location {name!r}: the FRF is constant ({complex(h[0]):.6g}) over the band",
                             expected="an FRF with a resonance")
        chans.append(Channel(name, 2 * np.pi * f, h, wt / rms))
    return chans, band


@dataclass
class _Ctx:
    """What every step of one fit needs: normalised data, options, the unit for messages."""

    chans: list[Channel]              # w in units of 2 pi f_ref (normalised), H de-embedded of the delay
    band: tuple[float, float]         # normalised
    powers: tuple[int, ...]
    f_ref: float                      # Hz per normalised unit (messages, rescaling)
    covariance: str
    warnings: list[str]
    noise_cache: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: modes added at a peak of |H| that the band's fit cannot hold: (frequency, its variance and
    #: the damping ratio's, from a fit of the lines around the peak alone); held in every later refinement
    held: list[tuple[float, float, float]] = field(default_factory=list)

    def hz(self, f: float) -> str:
        return f"{f * self.f_ref:.5g} Hz"

    def noise(self, c: Channel) -> np.ndarray:
        """A location's noise variance (:func:`noise_variance`), computed once per FRF."""
        hit = self.noise_cache.get(id(c))
        if hit is None or hit[0] is not c.H:
            hit = (c.H, noise_variance(c.H))
            self.noise_cache[id(c)] = hit
        return hit[1]

    def models(self, lam: np.ndarray, lins: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Each location's model for poles ``lam`` and linear parameters ``lins`` (the basis once
        when the locations share their lines)."""
        shared = basis(self.chans[0].w, lam, self.powers) if _same_grid(self.chans) else None
        return [(basis(c.w, lam, self.powers) if shared is None else shared) @ p for c, p in zip(self.chans, lins)]


def fit_modes(freq_hz: Any, frf: Any, n_modes: int | None = None, band_hz: tuple[float, float] | None = None,
              method: str = "lscf", *, locations: Sequence[str] | None = None, weights: Any = None,
              kind: str = "mobility", residual_powers: Sequence[int] | None = None,
              covariance: str = "sandwich", n_max: int | None = None, n_boot: int = 100,
              seed: int = 0, poles_hz: Sequence[float | tuple[float, float]] | None = None,
              background: str | None = None) -> ModalFit:
    """Fit modes (common poles) to one or several FRFs.

    Parameters
    ----------
    freq_hz:
        Frequency lines, one array shared by every location or a list with one
        per location (any unit works; results come in the same unit).
    frf:
        Complex FRF: ``(lines,)``, ``(locations, lines)``, a list, or a dict
        ``{location: frf}``.
    n_modes:
        Number of modes: exactly that many are returned (or
        :class:`InputError`); ``None`` chooses from the stabilisation diagram
        and the misfit against the noise (``"lscf"``) or from peak prominence
        (``"peak"``, ``"circle"``).
    band_hz:
        ``(low, high)``: only lines inside are fitted.
    method:
        ``"lscf"``, ``"peak"`` or ``"circle"`` (see the module docstring).
    locations:
        Names when ``frf`` is not a dict.
    weights:
        Optional per-line weights (>= 0; 0 drops a line), same layout as ``frf``.
    kind:
        ``"mobility"``, ``"receptance"``, ``"accelerance"``, ``"transmissibility"``
        (robot over base velocity) or ``"scattering"`` (S-parameters); sets the
        residual terms and the form the single-mode methods work on.
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
    poles_hz:
        Poles chosen by hand: frequencies (held; damping fitted) or
        ``(freq, damping_ratio)`` pairs (both held); residues fitted.
    background:
        ``None``, ``"linear"`` (constant + slope added to the residual terms) or
        ``"linear+delay"`` (also a line delay, for reflection data).

    Raises
    ------
    InputError
        Mismatched lengths, NaN or infinite values, frequencies <= 0, fewer than
        12 lines in the band, an unknown method, kind or background, ``n_modes``
        modes that cannot be found, a circle fit that ends at its bounds.
    """
    from threadpoolctl import threadpool_limits

    # One BLAS thread: the fit's matrices are small (lines x tens of columns) and many; thread start-up
    # and contention cost more than they save (3x slower with 2 threads on 2 cores, 10x on a busy machine).
    with threadpool_limits(limits=FIT_BLAS_THREADS, user_api="blas"):
        return _fit_modes(freq_hz, frf, n_modes, band_hz, method, locations=locations, weights=weights, kind=kind,
                          residual_powers=residual_powers, covariance=covariance, n_max=n_max, n_boot=n_boot,
                          seed=seed, poles_hz=poles_hz, background=background)


def _fit_modes(freq_hz: Any, frf: Any, n_modes: int | None, band_hz: tuple[float, float] | None,
               method: str, *, locations: Sequence[str] | None, weights: Any, kind: str,
               residual_powers: Sequence[int] | None, covariance: str, n_max: int | None, n_boot: int,
               seed: int, poles_hz: Sequence[float | tuple[float, float]] | None,
               background: str | None) -> ModalFit:
    """:func:`fit_modes` with the BLAS threads already limited."""
    if method not in METHODS:
        raise InputError(f"method = {method!r}", expected=f"one of {', '.join(METHODS)}")
    if kind not in DEFAULT_RESIDUALS:
        raise InputError(f"kind = {kind!r}", expected=f"one of {', '.join(DEFAULT_RESIDUALS)}")
    if covariance not in ("residual", "sandwich"):
        raise InputError(f"covariance = {covariance!r}", expected="'residual' or 'sandwich'")
    if n_modes is not None and (int(n_modes) != n_modes or n_modes < 1):
        raise InputError(f"n_modes = {n_modes!r}", expected="an integer >= 1 or None")
    if background not in BACKGROUNDS:
        raise InputError(f"background = {background!r}", expected="None, 'linear' or 'linear+delay'")
    chans, band = _channels(freq_hz, frf, locations, weights, band_hz)
    powers = tuple(DEFAULT_RESIDUALS[kind] if residual_powers is None else residual_powers)
    if background is not None:
        powers = tuple(sorted(set(powers) | {0, 1}))
    given = _given_poles(poles_hz, band) if poles_hz is not None else None
    # Normalise: frequency in units of the band's centre (whatever the user's unit).
    f_ref = 0.5 * (band[0] + band[1])
    orig = [(c.w / (2 * np.pi), c.H) for c in chans]
    delay = _delay(chans) if background == "linear+delay" else 0.0
    nchans = [Channel(c.name, c.w / f_ref, c.H * np.exp(1j * c.w * delay), c.weight.copy()) for c in chans]
    ctx = _Ctx(nchans, (band[0] / f_ref, band[1] / f_ref), powers, f_ref, covariance, [])
    if given is not None:
        fit = _fit_given(ctx, given[0] / f_ref, given[1], method, kind)
    elif method == "lscf":
        fit = _fit_lscf(ctx, n_modes, n_max, kind)
    else:
        fit = _fit_sdof(ctx, n_modes, method, kind, n_boot, seed, background is not None)
    if background == "linear+delay":
        # Alternate: the delay with the poles held, then poles and residues with the delay held,
        # until the delay settles.  A delay and the background's slope are the same to first order
        # (the misfit grows only as the 4th power of the delay's error near the optimum), so the
        # delay is loosely determined and matters little to the modes.
        for _ in range(20):
            new = _polish_delay(ctx, fit, delay)
            moved = abs(new - delay)
            delay = new
            if moved * _span_w(ctx) < 1e-7:
                break
        _delay_uncertainty(ctx, fit, delay)
    fit = _rescale(fit, f_ref, band, orig, delay)
    if given is not None:                      # exactly the values given, not their round trip through f_ref
        o = np.argsort(given[0])
        for m, fg, zg in zip(fit.modes, given[0][o], given[1][o]):
            m.freq_hz = float(fg)
            if not np.isnan(zg):
                m.damping_ratio = float(zg)
    fit.background = background
    _judge(fit)
    return fit


# ---------------------------------------------------------------------------------------------
def _given_poles(poles: Sequence[float | tuple[float, float]], band: tuple[float, float]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(freq, damping or NaN)`` of poles chosen by hand, checked."""
    fz = []
    for p in poles:
        pair: tuple[Any, ...] = (p, np.nan) if np.ndim(p) == 0 else (tuple(p) + (np.nan,))[:2]  # type: ignore[arg-type]
        try:
            f, z = float(pair[0]), float(pair[1])
        except (TypeError, ValueError):
            raise InputError(f"bad pole {p!r}", key="poles_hz", expected="a frequency or (frequency, zeta)") from None
        if not band[0] < f < band[1]:
            raise InputError(f"pole at {f:g} outside the band {band[0]:g}-{band[1]:g}", key="poles_hz",
                             expected="frequencies inside the fitted band")
        if not (np.isnan(z) or 0 < z < 1):
            raise InputError(f"damping ratio {z:g} of the pole at {f:g}", key="poles_hz", expected="0 < zeta < 1")
        fz.append((f, z))
    if not fz:
        raise InputError("no pole given", key="poles_hz", expected="at least one frequency")
    a = np.array(fz, dtype=float)
    return a[:, 0], a[:, 1]


def _max_order(chans: list[Channel]) -> int:
    """The highest LSCF order the lines support (the model's coefficients must stay well determined)."""
    return int(max(2, (min(c.w.size for c in chans) - 4) // 2))


def _default_n_max(chans: list[Channel], n_modes: int | None) -> int:
    """The first order of the diagram: 24 (grown from there without ``n_modes``), or enough for ``n_modes``."""
    cap = 24 if n_modes is None else min(40, max(16, 2 * n_modes + 10))
    return int(min(cap, _max_order(chans)))


def _grow_order(data: list[tuple[np.ndarray, np.ndarray, np.ndarray]], band: tuple[float, float], n0: int,
                limit: int) -> tuple[Stabilisation, np.ndarray]:
    """The stabilisation diagram, its order grown by a third until it shows no new stable poles.

    No fixed cap: the diagram at order ``n`` and at ``n + max(8, n // 3)`` are compared and the
    order grows while the larger finds more stable poles (more modes than a given order can hold
    appear only above it); only the number of lines (``limit``) stops it otherwise.
    """
    stab = stabilisation(data, n0, band)
    lam = choose_poles(stab, None, band_hz=band)
    n = n0
    while n < limit:
        n_next = min(limit, n + max(8, n // 3))
        stab_next = stabilisation(data, n_next, band, previous=stab)
        lam_next = choose_poles(stab_next, None, band_hz=band)
        if lam_next.size <= lam.size:
            break
        n, stab, lam = n_next, stab_next, lam_next
    return stab, lam


def _fit_lscf(ctx: _Ctx, n_modes: int | None, n_max: int | None, kind: str) -> ModalFit:
    chans, band, warnings = ctx.chans, ctx.band, ctx.warnings
    data = [(c.w, c.H, c.weight) for c in chans]
    if n_max is None and n_modes is None:
        stab, lam0 = _grow_order(data, band, _default_n_max(chans, None), _max_order(chans))
    else:
        stab = stabilisation(data, _default_n_max(chans, n_modes) if n_max is None else n_max, band)
        lam0 = choose_poles(stab, n_modes, band_hz=band)
    stab.chosen_hz = pole_to_modal(lam0)[0]
    if len(chans) > 1:
        _noise_weights(chans)
    if n_modes is not None:
        if lam0.size < n_modes:
            warnings.append(f"the stabilisation diagram offers {lam0.size} of the {n_modes} modes asked for; "
                            "the others were started where the residual is largest")
            lam0 = _grow_to(ctx, lam0, n_modes)
        _check_size(chans, lam0.size, ctx.powers)
        ref = refine(chans, lam0, ctx.powers, band_hz=band, covariance=ctx.covariance)
        keep, why = _credible(chans, ref, ctx.f_ref)
        for i in np.flatnonzero(~keep):
            warnings.append(f"kept the mode at {ctx.hz(ref.freq_hz[i])} because n_modes = {n_modes} was asked "
                            f"for, although {why[i]}")
    else:
        if lam0.size == 0:
            lam0 = _grow_to(ctx, lam0, 1, quiet=True)
            if lam0.size:
                warnings.append("the stabilisation diagram holds no stable pole; started one mode where the "
                                "FRF is largest")
        if lam0.size == 0:
            raise InputError("no stable mode found in the band", expected="an FRF with a resonance")
        _check_size(chans, lam0.size, ctx.powers)
        ref = refine(chans, lam0, ctx.powers, band_hz=band, covariance=ctx.covariance)
        ref = _prune(ctx, ref)
        ref = _grow_while_misfit(ctx, ref)
    ref = _honest_covariance(ctx, ref)
    if not ref.success:
        warnings.append("nonlinear refinement did not converge")
    fit = _from_refined(ctx, ref, "lscf", kind, stab)
    _warn_outside(fit, ctx)
    _warn_narrow(fit, ctx)
    return fit


def _poles(ref: Refined) -> np.ndarray:
    return modal_to_pole(ref.freq_hz, ref.damping_ratio)


def _prune(ctx: _Ctx, ref: Refined) -> Refined:
    """Drop modes that are not credible (and say so), refitting the rest; never drops the last one.

    One at a time, the least significant first: two poles sharing one mode are both uncertain
    together, and dropping one makes the other credible.
    """
    while ref.freq_hz.size > 1:
        snr: list[float] = []
        keep, why = _credible(ctx.chans, ref, ctx.f_ref, snr=snr)
        if keep.all():
            break
        bad = np.flatnonzero(~keep)
        i = int(bad[np.argmin(np.asarray(snr)[bad])])
        ctx.warnings.append(f"dropped a pole at {ctx.hz(ref.freq_hz[i])}: {why[i]}")
        keep = np.arange(ref.freq_hz.size) != i
        ref = refine(ctx.chans, modal_to_pole(ref.freq_hz[keep], ref.damping_ratio[keep]), ctx.powers,
                     band_hz=ctx.band, covariance=ctx.covariance)
    keep, why = _credible(ctx.chans, ref, ctx.f_ref)
    if not keep.all():
        ctx.warnings.append(f"kept the only mode left at {ctx.hz(ref.freq_hz[0])} although {why[0]}")
    return ref


def _misfits(ctx: _Ctx, ref: Refined) -> np.ndarray:
    """Per location, the misfit against the noise and the model's own variance (see misfit_to_noise).

    The model's variance only lowers the ratio, so it is computed (a pass over the Jacobian) only
    when a location's ratio against the noise alone is above :data:`MISFIT_WARN`.
    """
    lam = _poles(ref)
    models = ctx.models(lam, ref.lin)
    n_par = [p.size + 2 * lam.size / len(ctx.chans) for p in ref.lin]
    out = np.array([misfit_to_noise(c.H, mod, n, noise_var=ctx.noise(c))
                    for c, mod, n in zip(ctx.chans, models, n_par)])
    if out.max() > MISFIT_WARN:
        out = np.array([misfit_to_noise(c.H, mod, n, model_var=mv, noise_var=ctx.noise(c))
                        for c, mod, n, mv in zip(ctx.chans, models, n_par, _model_variance(ctx, ref))])
    return out


def _model_variance(ctx: _Ctx, ref: Refined) -> list[np.ndarray]:
    """Per location, the fitted model's variance at each line from the noise."""
    return model_variance(ctx.chans, ref, ctx.powers, [ctx.noise(c) for c in ctx.chans])


#: Lags over which correlated residuals are looked for (a fraction of the lines, at most this many).
MAX_LAG = 50


def _correlation_factor(ctx: _Ctx, ref: Refined) -> float:
    """How much correlated residuals inflate the variance of the fitted parameters (>= 1).

    A model that misses something leaves a smooth residual: neighbouring lines err together and
    carry less independent information than the covariance assumes.  Per location, the residual
    normalised by its expected size (noise plus the model's variance) gives autocorrelations
    ``rho_k`` over the lines; ``1 + 2 sum rho_k`` (summed while positive: Geyer's initial positive
    sequence) is the variance inflation of a mean over correlated samples; the largest over the
    locations is returned.
    """
    lam = _poles(ref)
    worst = 1.0
    for c, p, mv in zip(ctx.chans, ref.lin, _model_variance(ctx, ref)):
        u = (basis(c.w, lam, ctx.powers) @ p - c.H) / np.sqrt(ctx.noise(c) + mv)
        u = u - u.mean()
        norm = float(np.sum(np.abs(u) ** 2))
        tau = 1.0
        for k in range(1, min(MAX_LAG, u.size // 4)):
            rho = float(np.real(np.sum(u[k:] * np.conj(u[:-k])))) / norm
            if rho <= 0:
                break
            tau += 2 * rho
        worst = max(worst, tau)
    return worst


def _honest_covariance(ctx: _Ctx, ref: Refined) -> Refined:
    """Where the misfit is above :data:`MISFIT_WARN` times the noise (the model is not the whole
    story), the covariance times :func:`_correlation_factor`, and said."""
    mis = _misfits(ctx, ref)
    ref.misfit = mis
    if mis.max() <= MISFIT_WARN:
        return ref
    tau = _correlation_factor(ctx, ref)
    if tau > 1.0:
        ref.cov = ref.cov * tau
        ctx.warnings.append(f"the residual is correlated from line to line (misfit {mis.max():.3g} times the "
                            f"noise): the uncertainties are scaled up by {np.sqrt(tau):.3g} for it")
    return ref


def _residual_peak(ctx: _Ctx, lam: np.ndarray) -> tuple[float, float] | None:
    """Frequency and damping guess where the residual of a fit with poles ``lam`` stands out most
    from the noise (summed over locations), or None."""
    peaks = _residual_peaks(ctx, lam, 1)
    return peaks[0] if peaks else None


def _residual_peaks(ctx: _Ctx, lam: np.ndarray, n_peaks: int) -> list[tuple[float, float]]:
    """Up to ``n_peaks`` (frequency, damping) guesses where the residual stands out most, each from
    a separate hump of the residual (largest first)."""
    f_grid = np.unique(np.concatenate([c.w for c in ctx.chans]))
    e = np.zeros(f_grid.size)
    for c in ctx.chans:
        if lam.size or ctx.powers:
            p = residues_ls([c], lam, ctx.powers)[0]
            r = basis(c.w, lam, ctx.powers) @ p - c.H
        else:
            r = -c.H
        v = ctx.noise(c)
        e += np.interp(f_grid, c.w, np.abs(r) ** 2 / v)
    if e.size < 5:
        return []
    es = np.convolve(e, np.ones(3) / 3, mode="same")
    # Not at the band's edges: there the residual terms stand in for modes outside.
    n = es.size
    lo, hi = max(1, n // 50), min(n - 1, n - n // 50)
    out: list[tuple[float, float]] = []
    free = np.zeros(n, dtype=bool)
    free[lo:hi] = True
    while len(out) < n_peaks and free.any():
        k = int(np.flatnonzero(free)[np.argmax(es[free])])
        half = es[k] / 2
        i, j = k, k
        while i > 0 and es[i] > half:
            i -= 1
        while j < n - 1 and es[j] > half:
            j += 1
        free[i:j + 1] = False
        fk = f_grid[k] / (2 * np.pi)
        width = (f_grid[j] - f_grid[i]) / (2 * np.pi)
        out.append((float(fk), float(np.clip(width / (2 * fk) if width > 0 else 0.01, 1e-4, 0.3))))
    return out


def _grow_to(ctx: _Ctx, lam: np.ndarray, n: int, *, quiet: bool = False) -> np.ndarray:
    """Add poles where the residual is largest until there are ``n`` (or raise)."""
    lam = np.asarray(lam, dtype=complex)
    while lam.size < n:
        pk = _residual_peak(ctx, lam)
        if pk is None:
            if quiet:
                return lam
            raise InputError(f"cannot place {n} modes in the band: found {lam.size}",
                             key="n_modes", expected="fewer modes or a wider band")
        lam = np.sort_complex(np.append(lam, modal_to_pole(np.array([pk[0]]), np.array([pk[1]]))))
    return lam


def _grow_while_misfit(ctx: _Ctx, ref: Refined) -> Refined:
    """While the misfit is above :data:`MISFIT_WARN` times the noise, try one more mode; keep it when
    it is credible and lowers the worst misfit by a fifth (no fixed number: only the lines available
    or a mode that does not help stop it).

    Candidates: where the residual is largest inside the band, and just outside either edge (a
    strong mode outside bends the FRF near the edge more than the residual terms can follow); the
    one that lowers the misfit most with the poles held is refined first.  A pole that settles
    outside the band is kept and reported as such (:func:`_warn_outside`).
    """
    while True:
        mis = _misfits(ctx, ref)
        if mis.max() <= MISFIT_WARN:
            break
        lam = _poles(ref)
        try:
            _check_size(ctx.chans, lam.size + 1, ctx.powers)
        except InputError:
            break
        for new, inside_only, peak in _candidates(ctx, lam, mis.max()):
            trial = (_try_peak(ctx, ref, new, mis.max()) if peak
                     else _try_mode(ctx, lam, new, mis.max(), inside_only))
            if trial is not None:
                where = "" if ctx.band[0] < trial.freq_hz[-1] < ctx.band[1] else " (outside the band)"
                ctx.warnings.append(f"added a mode at {ctx.hz(trial.freq_hz[-1])}{where}: the stabilisation "
                                    f"diagram's modes left a misfit {mis.max():.3g} times the noise level")
                ref = trial
                break
        else:
            break
    return _with_held_variances(ctx, ref)


def _screen(ctx: _Ctx, lam: np.ndarray) -> float:
    """The worst misfit with poles ``lam`` held and only the residues fitted (linear, cheap)."""
    lin = residues_ls(ctx.chans, lam, ctx.powers)
    return max(misfit_to_noise(c.H, mod, p.size + 2 * lam.size / len(ctx.chans), noise_var=ctx.noise(c))
               for c, p, mod in zip(ctx.chans, lin, ctx.models(lam, lin)))


def _candidates(ctx: _Ctx, lam: np.ndarray, worst: float) -> list[tuple[complex, bool, bool]]:
    """Poles worth a trial: ``(pole, must stay inside the band, at an unexplained peak of |H|)``; the
    peaks of |H| no pole explains first, then the others best first by their screened misfit."""
    out: list[tuple[float, complex, bool]] = []
    lo, hi = ctx.band
    guesses = [(fk, zk, True) for fk, zk in _residual_peaks(ctx, lam, 3)]
    peaks = [complex(modal_to_pole(np.array([fk]), np.array([zk]))[0]) for fk, zk in _unfitted_peaks(ctx, lam)]
    guesses += [(edge, z, False) for edge in (hi * 1.01, hi * 1.04, hi * 1.1, lo * 0.99, lo * 0.96, lo * 0.9)
                for z in (0.005, 0.02)]
    for f0, z0, inside_only in guesses:
        new = complex(modal_to_pole(np.array([f0]), np.array([z0]))[0])
        sc = _screen(ctx, np.append(lam, new))
        if sc <= 0.95 * worst:
            out.append((sc, new, inside_only))
    out.sort(key=lambda t: t[0])
    seen_edges: set[bool] = set()
    picked: list[tuple[complex, bool, bool]] = [(new, True, True) for new in peaks]
    for _, new, inside_only in out:             # every inside guess, the best one above and below
        above = abs(new) > 2 * np.pi * hi
        if inside_only:
            picked.append((new, inside_only, False))
        elif above not in seen_edges:
            seen_edges.add(above)
            picked.append((new, inside_only, False))
    return picked


#: A peak of |H| counts (as in peak picking) when log |H| stands out by this much (a factor e).
PEAK_PROMINENCE = 1.0


def _unfitted_peaks(ctx: _Ctx, lam: np.ndarray) -> list[tuple[float, float]]:
    """(frequency, damping) guesses at the peaks of |H| inside the band that no pole of ``lam`` explains:
    local maxima of log |H| (any location) standing out by :data:`PEAK_PROMINENCE`, with no pole
    within the peak's half-power band.  A weak mode next to strong ones can leave a residual far
    below the misfit of the quiet lines elsewhere; its own peak still shows where it is."""
    from scipy.signal import find_peaks
    f_poles = pole_to_modal(lam)[0] if lam.size else np.zeros(0)
    out: list[tuple[float, float]] = []
    for c in ctx.chans:
        fk, a = c.w / (2 * np.pi), np.abs(c.H)
        for k in find_peaks(np.log(a + 1e-300), prominence=PEAK_PROMINENCE)[0]:
            i, j = k, k
            while i > 0 and a[i - 1] > a[k] / np.sqrt(2):
                i -= 1
            while j < a.size - 1 and a[j + 1] > a[k] / np.sqrt(2):
                j += 1
            lo, hi = fk[max(i - 1, 0)], fk[min(j + 1, a.size - 1)]
            if np.any((f_poles > lo) & (f_poles < hi)) or any(lo < f < hi for f, _ in out):
                continue
            out.append((float(fk[k]), float(np.clip((hi - lo) / (2 * fk[k]), 1e-4, 0.3))))
    return out


def _try_mode(ctx: _Ctx, lam: np.ndarray, new: complex, worst: float, inside_only: bool) -> Refined | None:
    """The fit with one more pole started at ``new``, or None when it does not settle, is not
    credible, leaves the band (``inside_only``) or lowers the worst misfit by less than a fifth."""
    trial = _trial_fit(ctx, lam, new, at_peak=False)
    if trial is None:
        return None
    keep, _ = _credible(ctx.chans, trial, ctx.f_ref, check_width=True)
    lo, hi = ctx.band
    inside = bool(lo < trial.freq_hz[-1] < hi) or not inside_only
    if not (keep.all() and inside) or _misfits(ctx, trial).max() > 0.8 * worst:
        return None
    return trial


def _try_peak(ctx: _Ctx, ref: Refined, new: complex, worst: float) -> Refined | None:
    """The fit ``ref`` with one more pole started at ``new``, an unexplained peak of |H|, or None.

    The peak itself shows the mode, so the new mode is judged neither by its width nor by its
    residue's significance (a weak mode beside strong ones is uncertain under the sandwich
    covariance, whose leverage correction grows at a sharp peak), but by the misfit it removes: kept
    when it lowers the misfit by a fifth over the peak's neighbourhood (its half-power band, three
    times widened) without raising the worst one, stays in the band and leaves the other modes credible.
    When the band's fit pulls the new pole away from its peak (a weak mode where far stronger ones
    dominate the least squares), the mode is fitted from the lines around the peak alone
    (:func:`_local_pole`, kept when it lowers their misfit by a fifth) and held in the band's fit.
    """
    near = 3 * abs(new.real) / (2 * np.pi)
    f0 = abs(new.imag) / (2 * np.pi)
    trial = _trial_fit(ctx, _poles(ref), new, at_peak=True)
    local = None
    if trial is None or abs(trial.freq_hz[-1] - f0) > near:     # pulled away from its peak
        local = _local_pole(ctx, _poles(ref), new)
        if local is None:
            return None
        ctx.held.append((pole_to_modal(np.array([local[0]]))[0][0], local[1], local[2]))
        trial = _trial_fit(ctx, _poles(ref), local[0], at_peak=False)
    keep, _ = _credible(ctx.chans, trial, ctx.f_ref) if trial is not None else (np.zeros(1, bool), [])
    lo, hi = ctx.band
    if (trial is None or not (keep[:-1].all() and lo < trial.freq_hz[-1] < hi)
            or _misfits(ctx, trial).max() > worst
            or (local is None and _local_misfit(ctx, trial, f0, near) > 0.8 * _local_misfit(ctx, ref, f0, near))):
        if local is not None:
            ctx.held.pop()
        return None
    if local is not None:
        ctx.warnings.append(f"the mode at {ctx.hz(trial.freq_hz[-1])} was fitted from the lines within "
                            f"{LOCAL_SPAN:.0%} of its peak alone (the band's fit pulls its pole away): its "
                            "frequency and damping ratio are held there in the band's fit")
    return trial


def _trial_fit(ctx: _Ctx, lam: np.ndarray, new: complex, *, at_peak: bool) -> Refined | None:
    """The refinement with one more pole started at ``new`` (20 iterations: a mode that does not
    settle in them is not kept anyway), or None.  At a peak of |H| the new frequency is first held
    at the peak while the rest settles, so that a weak mode is not pulled away by strong ones.
    The modes in ``ctx.held`` stay held (frequency and damping ratio)."""
    lam1 = np.append(lam, new)
    if at_peak:
        held = _held_mask(ctx, lam1)
        held[-1] = True
        first = refine(ctx.chans, lam1, ctx.powers, band_hz=ctx.band, covariance=ctx.covariance, max_iter=20,
                       fixed_freq=held, fixed_damping=_held_mask(ctx, lam1))
        lam1 = np.append(lam, _poles(first)[-1]) if first.success else lam1
    held = _held_mask(ctx, lam1)
    # a held frequency's mode is one the data show: the rest may take the usual iterations to settle
    trial = refine(ctx.chans, lam1, ctx.powers, band_hz=ctx.band, covariance=ctx.covariance,
                   max_iter=100 if held[-1] else 20, fixed_freq=held, fixed_damping=held)
    return trial if trial.success else None


def _held_mask(ctx: _Ctx, lam: np.ndarray) -> np.ndarray:
    f = pole_to_modal(lam)[0] if lam.size else np.zeros(0)
    return np.array([any(abs(fi - h[0]) <= 1e-9 * h[0] for h in ctx.held) for fi in f], dtype=bool)


#: Half-width of the lines around a peak fitted alone (a fraction of its frequency) when the band's
#: fit pulls the peak's mode away.
LOCAL_SPAN = 0.01


def _local_pole(ctx: _Ctx, lam: np.ndarray, new: complex) -> tuple[complex, float, float] | None:
    """The pole of the peak at ``new`` (and its frequency's and damping ratio's variances) from the lines within
    :data:`LOCAL_SPAN` of it alone, with the poles of ``lam`` among them; None if that fails."""
    f0 = abs(new.imag) / (2 * np.pi)
    lo, hi = f0 * (1 - LOCAL_SPAN), f0 * (1 + LOCAL_SPAN)
    sub = []
    for c in ctx.chans:
        s = (c.w >= 2 * np.pi * lo) & (c.w <= 2 * np.pi * hi)
        sub.append(Channel(c.name, c.w[s], c.H[s], c.weight[s]))
    f_lam = pole_to_modal(lam)[0] if lam.size else np.zeros(0)
    lam1 = np.append(lam[(f_lam > lo) & (f_lam < hi)], new)
    try:
        _check_size(sub, lam1.size, ctx.powers)
    except InputError:
        return None
    loc = refine(sub, lam1, ctx.powers, band_hz=(lo, hi), covariance=ctx.covariance)
    if not (loc.success and lo < loc.freq_hz[-1] < hi):
        return None
    noise = [ctx.noise(c)[(c.w >= 2 * np.pi * lo) & (c.w <= 2 * np.pi * hi)] for c in ctx.chans]
    without = residues_ls(sub, lam1[:-1], ctx.powers)
    before = sum(float(np.sum(np.abs(basis(c.w, lam1[:-1], ctx.powers) @ p - c.H) ** 2 / v))
                 for c, p, v in zip(sub, without, noise))
    after = sum(float(np.sum(np.abs(basis(c.w, _poles(loc), ctx.powers) @ p - c.H) ** 2 / v))
                for c, p, v in zip(sub, loc.lin, noise))
    if after > 0.8 * before:
        return None
    i = 2 * (lam1.size - 1)
    return complex(_poles(loc)[-1]), float(loc.cov[i, i]), float(loc.cov[i + 1, i + 1])


def _with_held_variances(ctx: _Ctx, ref: Refined) -> Refined:
    """``ref`` with the variances of the frequencies in ``ctx.held`` set to their local fits'."""
    for i, fi in enumerate(ref.freq_hz):
        for h, var_f, var_z in ctx.held:
            if abs(fi - h) <= 1e-9 * h:
                ref.cov[2 * i, 2 * i], ref.cov[2 * i + 1, 2 * i + 1] = var_f, var_z
    return ref


def _local_misfit(ctx: _Ctx, ref: Refined, f0: float, half: float) -> float:
    """Mean of ``|model - H|^2 / noise`` over the lines within ``half`` of ``f0`` (normalised units)."""
    models = ctx.models(_poles(ref), ref.lin)
    out = 0.0
    for c, mod in zip(ctx.chans, models):
        s = np.abs(c.w / (2 * np.pi) - f0) <= max(half, 2 * float(np.min(np.diff(c.w))) / (2 * np.pi))
        out += float(np.mean(np.abs(mod[s] - c.H[s]) ** 2 / ctx.noise(c)[s])) if s.any() else 0.0
    return out


def _fit_given(ctx: _Ctx, f_given: np.ndarray, z_given: np.ndarray, method: str, kind: str) -> ModalFit:
    """Residues (and damping ratios not given) on poles chosen by hand."""
    chans = ctx.chans
    z0 = z_given.copy()
    if np.isnan(z0).any():
        f_grid = np.unique(np.concatenate([c.w for c in chans])) / (2 * np.pi)
        mob = _sdof_forms(chans, kind, f_grid, False)
        a = modal_sdof.indicator(mob, [1.0 / np.sqrt(np.mean(np.abs(m) ** 2)) for m in mob])
        for i in np.flatnonzero(np.isnan(z0)):
            k = int(np.argmin(np.abs(f_grid - f_given[i])))
            _, zk = modal_sdof.half_power(f_grid, a, k)
            z0[i] = zk if np.isfinite(zk) and 0 < zk < 0.5 else 0.02
    _check_size(chans, f_given.size, ctx.powers)
    ref = refine(chans, modal_to_pole(f_given, z0), ctx.powers, band_hz=ctx.band, covariance=ctx.covariance,
                 fixed_freq=np.ones(f_given.size, bool), fixed_damping=~np.isnan(z_given))
    held = "frequencies" + ("" if np.isnan(z_given).all() else " (and the damping ratios given)")
    ctx.warnings.append(f"poles chosen by hand: {held} held at the given values (standard uncertainty 0), "
                        "damping ratios and residues fitted")
    fit = _from_refined(ctx, ref, method, kind, None)
    for m, zg in zip(fit.modes, z_given[np.argsort(f_given)]):
        m.given = True
        m.freq_hz_std = 0.0                     # held: exactly the given value
        m.freq_damping_cov = 0.0
        if not np.isnan(zg):
            m.damping_ratio_std = 0.0
    return fit


def _credible(chans: list[Channel], ref: Refined, f_ref: float, *, check_width: bool = False,
              snr: list[float] | None = None) -> tuple[np.ndarray, list[str]]:
    """Which refined modes are real: significantly non-zero (and, with ``check_width``, resolvable).

    A mode whose residue is nowhere larger than 3 standard uncertainties is
    not supported by the data.  With ``check_width`` (modes the fit adds
    itself, not ones the stabilisation diagram shows) a mode narrower than the
    spacing of the lines around it (half-power bandwidth ``2 zeta f`` below
    it) is taken for noise between lines.  Lightly damped modes of real
    impact tests are often that narrow and still well determined in frequency:
    those from the diagram are kept and flagged (:func:`_warn_narrow`).
    Returns the mask and, per mode, why not ("" if credible); ``f_ref``
    converts the normalised frequencies in the messages to Hz; ``snr`` (a list) receives each mode's
    largest residue-to-uncertainty ratio.
    """
    m = ref.freq_hz.size
    n_lin = ref.lin[0].size
    var = np.clip(np.diag(ref.cov), 0, None)
    keep = np.ones(m, dtype=bool)
    why = [""] * m
    for i in range(m):
        f, z = ref.freq_hz[i], ref.damping_ratio[i]
        spacing = np.inf
        best = 0.0
        for k, c in enumerate(chans):
            fk = c.w / (2 * np.pi)
            j = int(np.searchsorted(fk, f))
            near = fk[max(j - 1, 0):j + 1]
            if near.size == 2 and fk[0] <= f <= fk[-1]:
                spacing = min(spacing, float(near[1] - near[0]))
            R = abs(complex(ref.lin[k][2 * i], ref.lin[k][2 * i + 1]))
            sd = np.sqrt(var[2 * m + k * n_lin + 2 * i] + var[2 * m + k * n_lin + 2 * i + 1])
            best = max(best, R / sd if sd > 0 else np.inf)
        if snr is not None:
            snr.append(best)
        if check_width and np.isfinite(spacing) and 2 * z * f < spacing:      # (outside the lines: no spacing)
            keep[i] = False
            why[i] = (f"its half-power bandwidth ({2 * z * f * f_ref:.3g} Hz) is under the line spacing "
                      f"({spacing * f_ref:.3g} Hz)")
        elif best < 3.0:
            keep[i] = False
            why[i] = "its residue is below 3 standard uncertainties at every location"
    return keep, why


def _check_size(chans: list[Channel], m: int, powers: Sequence[int]) -> None:
    n_obs = sum(2 * c.w.size for c in chans)
    n_par = 2 * m + len(chans) * (2 * m + 2 * len(powers))
    if n_obs <= n_par + 2:
        raise InputError(f"{n_obs // 2} lines cannot fit {m} modes with {len(powers)} residual terms",
                         expected="more frequency lines or fewer modes")


def _noise_weights(chans: list[Channel]) -> None:
    """Weight each location by its own noise level estimated from the data (feasible weighted least
    squares: a noisy location does not pull the common poles as hard as a clean one)."""
    for c in chans:
        s = float(np.sqrt(np.median(noise_variance(c.H) * c.weight ** 2)))
        if s > 0:
            c.weight = c.weight / s


def _from_refined(ctx: _Ctx, ref: Refined, method: str, kind: str, stab: Stabilisation | None) -> ModalFit:
    m = ref.freq_hz.size
    misfit = dict(zip([c.name for c in ctx.chans], map(float, _misfits(ctx, ref) if ref.misfit is None
                                                       else ref.misfit)))
    std = np.sqrt(np.clip(np.diag(ref.cov), 0, None))
    n_lin = ref.lin[0].size
    lin_var = [np.clip(np.diag(ref.cov)[2 * m + k * n_lin: 2 * m + (k + 1) * n_lin], 0, None)
               for k in range(len(ctx.chans))]
    fz_cov = np.array([ref.cov[2 * i, 2 * i + 1] for i in range(m)])
    fit = _assemble(ctx.chans, ref.freq_hz, ref.damping_ratio, std[0:2 * m:2], std[1:2 * m:2], ref.lin, lin_var,
                    np.argsort(ref.freq_hz), method, kind, ctx.band, ctx.powers, stab, ref.cov, ref.success,
                    ctx.warnings, fz_cov)
    fit.misfit_to_noise = misfit                 # with the model's own variance (kept by _judge)
    return fit


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
    if cov is not None:
        # Reorder the covariance's pole block with the modes (sorted by frequency).
        n_lin = lin[0].size
        idx = [j for i in order for j in (2 * i, 2 * i + 1)]
        for k in range(len(chans)):
            base = 2 * m + k * n_lin
            idx += [base + j for i in order for j in (2 * i, 2 * i + 1)]
            idx += list(range(base + 2 * m, base + n_lin))
        cov = cov[np.ix_(idx, idx)]
    return ModalFit(modes, names, method, kind, band, tuple(powers), [c.w / (2 * np.pi) for c in chans],
                    [c.H for c in chans], resid_terms, {}, 0.0, {}, stab, cov, converged, warnings)


def _rescale(fit: ModalFit, f_ref: float, band: tuple[float, float],
             orig: list[tuple[np.ndarray, np.ndarray]], delay: float) -> ModalFit:
    """Back from normalised frequency to the caller's unit (residues scale with it, ``c_q`` with its ``-q``)."""
    for md in fit.modes:
        md.freq_hz *= f_ref
        md.freq_hz_std *= f_ref
        md.freq_damping_cov *= f_ref
        md.amplitude = md.amplitude * f_ref
        md.amplitude_std = md.amplitude_std * f_ref
    q = np.asarray(fit.residual_powers, dtype=float)
    fit.residual_terms = [c * f_ref ** (-q) for c in fit.residual_terms]
    if fit.covariance is not None:
        m = len(fit.modes)
        lin_scale = np.concatenate([np.full(2 * m, f_ref), np.repeat(f_ref ** (-q), 2)])
        s = np.concatenate([np.tile([f_ref, 1.0], m), np.tile(lin_scale, len(fit.locations))])
        fit.covariance = fit.covariance * np.outer(s, s)
    if fit.stabilisation is not None:
        st = fit.stabilisation
        st.freq_hz = st.freq_hz * f_ref
        st.chosen_hz = st.chosen_hz * f_ref
        st.band_hz = band
        st.poles_by_order = {k: v * f_ref for k, v in st.poles_by_order.items()}
    fit.band_hz = band
    fit.freq_hz = [f for f, _ in orig]
    fit.frf = [h for _, h in orig]
    fit.delay_s = float(delay)
    return fit


def _judge(fit: ModalFit) -> None:
    """nrmse, misfit against the noise, quality, dominant modes; a warning where the misfit is high."""
    q = []
    m = len(fit.modes)
    n_params = 2 * m / max(len(fit.locations), 1) + 2 * m + 2 * len(fit.residual_powers)
    for k, (loc, model) in enumerate(zip(fit.locations, fit.fitted())):
        H = fit.frf[k]
        r = model - H
        nr = float(np.sqrt(np.sum(np.abs(r) ** 2) / np.sum(np.abs(H) ** 2)))
        fit.nrmse[loc] = nr
        ratio = fit.misfit_to_noise.get(loc)
        if ratio is None:
            ratio = misfit_to_noise(H, model, n_params)
            fit.misfit_to_noise[loc] = ratio
        q.append(min(1 - nr ** 2, 1.0 if ratio <= MISFIT_WARN else (MISFIT_WARN / ratio) ** 2))
        fit.dominant_mode[loc] = int(np.argmax([md.peak[k] for md in fit.modes])) if fit.modes else -1
    fit.quality = float(np.clip(min(q), 0.0, 1.0))
    worst = max(fit.misfit_to_noise, key=lambda k: fit.misfit_to_noise[k])
    if fit.misfit_to_noise[worst] > MISFIT_WARN:
        fit.warnings.append(
            f"the fit's misfit is {fit.misfit_to_noise[worst]:.3g} times the noise level estimated from the data "
            f"at {worst}: a mode may be missing (try n_modes), or a background or delay (background=...); the "
            "uncertainties assume the model is right")


def _warn_outside(fit: ModalFit, ctx: _Ctx) -> None:
    """Flag and report modes fitted outside the band (a mode outside, fitted from its tail in the band)."""
    lo, hi = fit.band_hz
    for md in fit.modes:
        if not (lo <= md.freq_hz <= hi):
            md.in_band = False
            fit.warnings.append(f"mode at {ctx.hz(md.freq_hz)} lies outside the band "
                                f"{lo * ctx.f_ref:g}-{hi * ctx.f_ref:g} Hz (in_band = False): fitted from its "
                                "tail inside the band, so that the modes inside are not biased by it")


# --------------------------------------------------------------------------------------------- delay
def _span_w(ctx: _Ctx) -> float:
    """The band's width in rad/s of the caller's unit (a delay times it is a phase)."""
    return max(float(np.ptp(np.concatenate([c.w for c in ctx.chans]))) * ctx.f_ref, 1e-300)


def _delay(chans: list[Channel]) -> float:
    """A first line delay (s) from the median slope of the unwrapped phase (a resonance bends the
    phase over a few lines only, the median ignores them)."""
    slopes = []
    for c in chans:
        ph = np.unwrap(np.angle(c.H))
        d = np.diff(ph) / np.diff(c.w)
        slopes.append(np.median(d))
    return float(-np.median(slopes))


def _delay_uncertainty(ctx: _Ctx, fit: ModalFit, delay: float) -> None:
    """Add the delay's uncertainty to the modes' (the delay is fitted apart from the poles).

    The delay's variance from the curvature of the profile misfit (poles and
    residues refitted at ``delay +- h``), times the sensitivity of each mode's
    frequency and damping to it, is added to their variances (first order).
    """
    span = _span_w(ctx)
    h = 1e-3 / span                                  # 1 mrad of phase across the band
    lam = modal_to_pole(np.array([m.freq_hz for m in fit.modes]), np.array([m.damping_ratio for m in fit.modes]))
    refs = []
    for t in (delay - h, delay, delay + h):
        chans = [Channel(c.name, c.w, c.H * np.exp(1j * c.w * ctx.f_ref * (t - delay)), c.weight)
                 for c in ctx.chans]
        refs.append(refine(chans, lam, ctx.powers, band_hz=ctx.band, covariance=ctx.covariance))
    ssr = [r.ssr for r in refs]
    curv = (ssr[0] - 2 * ssr[1] + ssr[2]) / h ** 2
    if not curv > 0:
        fit.warnings.append("the line delay is not determined by the data (flat misfit); its uncertainty is "
                            "not in the modes'")
        return
    var_t = 2 * ssr[1] / refs[1].dof / curv
    o = [np.argsort(r.freq_hz) for r in refs]
    df = (refs[2].freq_hz[o[2]] - refs[0].freq_hz[o[0]]) / (2 * h)
    dz = (refs[2].damping_ratio[o[2]] - refs[0].damping_ratio[o[0]]) / (2 * h)
    for m, a, b in zip(fit.modes, df, dz):
        m.freq_hz_std = float(np.hypot(m.freq_hz_std, a * np.sqrt(var_t)))
        m.damping_ratio_std = float(np.hypot(m.damping_ratio_std, b * np.sqrt(var_t)))
        m.freq_damping_cov += float(a * b * var_t)


def _polish_delay(ctx: _Ctx, fit: ModalFit, delay: float) -> float:
    """The delay minimising the misfit with the fitted poles held (residues refitted at each trial).

    The fit's poles and residues are then refitted on the data de-embedded
    with that delay (in ``ctx.chans``, in place).  The delay's own
    uncertainty is added to the modes' afterwards (:func:`_delay_uncertainty`).
    """
    from scipy.optimize import minimize_scalar

    lam = modal_to_pole(np.array([m.freq_hz for m in fit.modes]), np.array([m.damping_ratio for m in fit.modes]))
    # ctx.chans hold H exp(j w delay); a trial delay t multiplies by exp(j w (t - delay)).
    w_hz = [c.w * 2 * np.pi * ctx.f_ref / (2 * np.pi) for c in ctx.chans]   # rad/s in the caller's unit
    span = max(float(np.ptp(np.concatenate(w_hz))), 1e-300)

    def cost(t: float) -> float:
        tot = 0.0
        for c, w in zip(ctx.chans, w_hz):
            h = c.H * np.exp(1j * w * (t - delay))
            ch = Channel(c.name, c.w, h, c.weight)
            p = residues_ls([ch], lam, ctx.powers)[0]
            tot += float(np.sum(np.abs((basis(c.w, lam, ctx.powers) @ p - h) * c.weight) ** 2))
        return tot

    res = minimize_scalar(cost, bounds=(delay - np.pi / span, delay + np.pi / span), method="bounded",
                          options={"xatol": 1e-6 / span})
    best = float(res.x) if res.fun < cost(delay) else delay
    if best != delay:
        for c, w in zip(ctx.chans, w_hz):
            c.H = c.H * np.exp(1j * w * (best - delay))
        ref = refine(ctx.chans, lam, ctx.powers, band_hz=ctx.band, covariance=ctx.covariance)
        new = _from_refined(ctx, ref, fit.method, fit.kind, fit.stabilisation)
        fit.__dict__.update(new.__dict__)
    return best


# ---------------------------------------------------------------------------------------------
def _sdof_forms(chans: list[Channel], kind: str, f_grid: np.ndarray, background: bool) -> list[np.ndarray]:
    """Each location in the form a single-mode estimator works on, on one grid.

    The mobility (velocity over force) for structural FRFs; the FRF itself
    minus its background for S-parameters or when a background is fitted
    (a dip becomes a peak).
    """
    out = []
    for c in chans:
        h = c.H
        if background or kind == "scattering":
            h = h - _edge_background(c.w, h)
        if kind == "transmissibility":
            h = (h - 1.0) * (1j * c.w) ** (1 - KINDS["accelerance"])
        elif kind in KINDS:
            h = h * (1j * c.w) ** (1 - KINDS[kind])
        fg = f_grid * 2 * np.pi
        out.append(np.interp(fg, c.w, h.real) + 1j * np.interp(fg, c.w, h.imag))
    return out


def _edge_background(w: np.ndarray, H: np.ndarray, frac: float = 0.1) -> np.ndarray:
    """A straight line (complex) through the outer ``frac`` of the lines on each side."""
    n = w.size
    k = max(2, int(frac * n))
    idx = np.r_[0:k, n - k:n]
    A = np.column_stack([np.ones(idx.size), w[idx]])
    cr = np.linalg.lstsq(A, H[idx].real, rcond=None)[0]
    ci = np.linalg.lstsq(A, H[idx].imag, rcond=None)[0]
    return (cr[0] + cr[1] * w) + 1j * (ci[0] + ci[1] * w)


class _AtBound(ValueError):
    """A circle fit ended at one of its optimiser's bounds: not a result."""


def _sdof_poles(chans: list[Channel], n_modes: int | None, method: str, kind: str,
                f_grid: np.ndarray, background: bool) -> np.ndarray:
    mob = _sdof_forms(chans, kind, f_grid, background)
    wts = [1.0 / np.sqrt(np.mean(np.abs(m) ** 2)) for m in mob]
    a = modal_sdof.indicator(mob, wts)
    # Noise of the indicator: each location's own noise level, weighted as in the indicator.
    noise = np.sqrt(sum(wt ** 2 * np.median(noise_variance(m)) for m, wt in zip(mob, wts)))
    peaks = modal_sdof.pick_peaks(f_grid, a, n_modes, floor=5 * noise)
    fz = []
    for k in peaks:
        fn, z = modal_sdof.half_power(f_grid, a, int(k))
        if not np.isfinite(z) or z <= 0:
            continue
        if method == "circle":
            best = int(np.argmax([wt * abs(m[k]) for m, wt in zip(mob, wts)]))
            try:
                fn, z = modal_sdof.circle_fit(f_grid, mob[best], fn, z)
            except modal_sdof.CircleAtBound as exc:
                raise _AtBound(str(exc)) from None
            except (ValueError, np.linalg.LinAlgError):
                pass
        if z >= 0.95:
            raise _AtBound(f"the half-power damping of the peak near {fn:.6g} is {z:.3g} (no resonance there)")
        fz.append((fn, z))
    if not fz:
        return np.zeros(0, complex)
    fz_a = np.array(fz)
    return modal_to_pole(fz_a[:, 0], fz_a[:, 1])


def _fit_sdof(ctx: _Ctx, n_modes: int | None, method: str, kind: str, n_boot: int, seed: int,
              background: bool) -> ModalFit:
    chans, powers, warnings = ctx.chans, ctx.powers, ctx.warnings
    f_grid = np.unique(np.concatenate([c.w / (2 * np.pi) for c in chans]))
    try:
        lam = _sdof_poles(chans, n_modes, method, kind, f_grid, background)
    except _AtBound as exc:
        raise InputError(f"{method} fit: {_in_hz(str(exc), ctx)}; that is the optimiser's limit, not a mode",
                         expected="method 'lscf' (or a band around one clear resonance)") from None
    if lam.size == 0:
        raise InputError("no resonance peak found in the band" + (
            "" if background else " (a resonance seen as a dip over a background? background='linear')"),
            expected="an FRF with a resonance")
    if n_modes is not None and lam.size < n_modes:
        raise InputError(f"{method}: found {lam.size} resonance peaks, {n_modes} asked for", key="n_modes",
                         expected=f"at most {lam.size} modes with this method, or method 'lscf'")
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
        try:
            lb = _sdof_poles(bc, lam.size, method, kind, f_grid, background)
        except _AtBound:
            continue
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
    fit = _assemble(chans, f0, z0, f_std, z_std, lin, lin_var, order, method, kind, ctx.band, powers, None,
                    None, True, warnings, fz_cov)
    _warn_interference(fit, ctx, modes_only=background or kind == "scattering")
    _warn_unresolved(fit, ctx, f_grid)
    return fit


def _in_hz(text: str, ctx: _Ctx) -> str:
    """Messages of the single-mode estimators carry normalised frequencies: convert ``near X``."""
    import re

    return re.sub(r"near ([0-9.eE+-]+)", lambda m: f"near {ctx.hz(float(m.group(1)))}", text)


def _warn_narrow(fit: ModalFit, ctx: _Ctx) -> None:
    """Modes narrower than the line spacing: their frequencies hold, their damping rests on a few lines."""
    narrow, spacings = [], []
    for m in fit.modes:
        spacing = np.inf
        for f in fit.freq_hz:
            j = int(np.searchsorted(f, m.freq_hz))
            if 0 < j < f.size:
                spacing = min(spacing, float(f[j] - f[j - 1]))
        if np.isfinite(spacing) and 2 * m.damping_ratio * m.freq_hz < spacing:
            narrow.append(m)
            spacings.append(spacing)
    if narrow:
        fit.warnings.append(
            "mode(s) at " + ", ".join(ctx.hz(m.freq_hz) for m in narrow) + ": half-power bandwidth "
            + ", ".join(f"{2 * m.damping_ratio * m.freq_hz * ctx.f_ref:.3g}" for m in narrow)
            + f" Hz, under the line spacing ({max(spacings) * ctx.f_ref:.3g} Hz): kept (the frequency is well "
            "determined), but the damping rests on the lines next to the peak and is biased by leakage or "
            "windowing: measure finer lines to trust it")


def _warn_unresolved(fit: ModalFit, ctx: _Ctx, f_grid: np.ndarray) -> None:
    """Single-mode estimates of a mode narrower than the line spacing are not measurements."""
    for m in fit.modes:
        j = int(np.clip(np.searchsorted(f_grid, m.freq_hz), 1, f_grid.size - 1))
        spacing = float(f_grid[j] - f_grid[j - 1])
        if 2 * m.damping_ratio * m.freq_hz < 2 * spacing:
            fit.warnings.append(
                f"mode at {ctx.hz(m.freq_hz)}: half-power bandwidth {2 * m.damping_ratio * m.freq_hz * ctx.f_ref:.3g} "
                f"Hz is under two line spacings ({spacing * ctx.f_ref:.3g} Hz): the {fit.method} method cannot resolve "
                "it (frequency and damping are biased; the damping is at best an upper bound): measure finer "
                "lines or use method 'lscf'")


def _warn_interference(fit: ModalFit, ctx: _Ctx, limit: float = 0.03, *, modes_only: bool = False) -> None:
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
        if modes_only:                      # a fitted background is not a neighbouring mode
            c = fit.residual_terms[k]
            rest -= complex(sum(ci * (jw ** q) for ci, q in zip(c, fit.residual_powers)))
        ratio = abs(rest) / max(abs(own), 1e-300)
        if ratio > limit:
            fit.warnings.append(f"mode at {ctx.hz(m.freq_hz)}: neighbouring modes add {ratio:.0%} of its peak "
                                f"at {m.dominant_location}; single-mode estimates are biased there (the "
                                "bootstrap uncertainty covers noise, not that bias): use method 'lscf'")
