"""Run files in, robot parameters out: :func:`fit_robot`, the library behind ``labkit fit``.

>>> rf = fit_robot(["inchip.h5", "shaker.h5"], assign="1=438")
>>> [(m["index"], m["freq_hz"], m["freq_hz_std"]) for m in rf.listing]
>>> rf.params.modal_freq_hz                   # the simulator's modes after the assignment
>>> rf.write("robot.toml")                    # parameter file + robot.fit.h5 + figures

Grouping: the tethered robot (in-chip runs: every location of every in-chip
file, fitted with common poles) and the released robot (shaker runs: the
robot's transmissibility) have different boundary conditions and so different
poles; each group is fitted on its own.  FRFs from other software (UFF 58,
CSV, Touchstone; :func:`labkit.analysis.modal.io.read_frf`) form the group
``"frf"``.  The fitted modes are numbered (in-chip, then shaker, then the
rest), assigned to the simulator's modes 1-3 (:mod:`~labkit.analysis.modal.assign`),
and the parameter file records where each value came from.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict

from labkit.analysis.modal import assign as ma
from labkit.analysis.modal.fit import ModalFit, fit_modes
from labkit.analysis.modal.io import RunChannels, read_frf, runs_json, write_fit_h5
from labkit.errors import InputError
from labkit.jsonutil import Json

__all__ = ["RobotFit", "fit_robot", "GROUP_KIND", "output_paths", "modes_only", "FitSummary", "FitFiles",
           "FitPaths", "FittedModeRow", "FitResult"]

#: FRF kind fitted for each group of run files (``"frf"``: the file's own kind).
GROUP_KIND = {"inchip": "mobility", "shaker": "transmissibility"}
_GROUP_ORDER = ("inchip", "shaker", "frf")


class FittedModeRow(TypedDict):
    """One fitted mode as :attr:`RobotFit.listing` lists it (``labkit fit --json``'s ``fitted_modes``)."""

    index: int
    group: str
    freq_hz: float
    freq_hz_std: float
    damping_ratio: float
    damping_ratio_std: float
    dominant_location: str
    in_band: bool
    assigned_to: int | None


class FitSummary(TypedDict):
    """:meth:`RobotFit.summary`: what ``labkit fit --json`` prints besides the paths written."""

    fitted_modes: list[FittedModeRow]
    assignment: dict[str, int | None]
    assignment_rule: str
    modal_freq_hz: list[float]
    modal_damping_ratio: list[float]
    quality: dict[str, float]
    nrmse: dict[str, dict[str, float]]
    misfit_to_noise: dict[str, dict[str, float]]
    dominant_mode: dict[str, dict[str, int]]
    mac: dict[str, list[list[float]]]
    warnings: list[str]
    modes_only: bool


class FitFiles(TypedDict):
    """The files :meth:`RobotFit.write` wrote (paths as text)."""

    out: str
    fit_file: str
    figures: list[str]
    uff_file: str | None


class FitResult(FitFiles, FitSummary):
    """``labkit fit --json``: the files written and the fit's summary."""


@dataclass(frozen=True)
class FitPaths:
    """The files :meth:`RobotFit.write` writes for a parameter file (:func:`output_paths`)."""

    out: Path
    fit_file: Path
    figures: dict[tuple[str, str], Path]
    uff_file: Path | None

    def all(self) -> list[Path]:
        """Every path, the parameter file first."""
        return [self.out, self.fit_file, *([self.uff_file] if self.uff_file is not None else []),
                *self.figures.values()]


@dataclass(frozen=True)
class FitOptions:
    """How :func:`fit_robot` fitted (kept for :meth:`RobotFit.reassign` and the provenance)."""

    method: str = "lscf"
    covariance: str = "sandwich"
    band_hz: tuple[float, float] | None = None
    n_modes: int | None = None
    min_quality: float = 0.0
    poles_hz: Sequence[float | tuple[float, float]] | None = None
    background: str | None = None
    modes_only: bool = False


@dataclass
class RobotFit:
    """The result of :func:`fit_robot`: fits per group, the numbered listing, the new parameters.

    Attributes
    ----------
    fits:
        ``{group: ModalFit}``.
    runs:
        The channels read, in the order given.
    listing:
        One dict per fitted mode, numbered from 1 as ``--assign`` refers to
        them: index, group, freq_hz, freq_hz_std, damping_ratio,
        damping_ratio_std, dominant_location, assigned_to (simulator mode or None).
    mapping:
        ``{simulator mode: FittedMode or None}`` (None keeps the base value).
    params:
        The robot parameters with the assigned modes replaced (``RobotParams``).
    provenance:
        The ``[provenance]`` table of the parameter file (without the file names,
        which :meth:`write` adds).
    warnings:
        Everything that was not as it should be, run files and fits together.
    modes_only:
        Only FRF files other than labkit runs were fitted and no mapping onto the
        simulator's modes was given: :meth:`write` writes the fitted modes, not a
        robot parameter file.
    """

    fits: dict[str, ModalFit]
    runs: list[RunChannels]
    listing: list[FittedModeRow]
    mapping: dict[int, ma.FittedMode | None]
    params: Any                     # labkit.sim.RobotParams (imported lazily: the simulator is heavy)
    provenance: dict[str, Json]
    assign_text: str | None
    warnings: list[str] = field(default_factory=list)
    modes_only: bool = False
    _base: tuple[Any, str] = field(default=(None, ""), repr=False)
    _options: FitOptions = field(default_factory=FitOptions, repr=False)
    _read_warnings: list[str] = field(default_factory=list, repr=False)

    def reassign(self, assign: str | None) -> RobotFit:
        """The same fits with another assignment to the simulator's modes (no refitting)."""
        return _assign(self.fits, self.runs, self._read_warnings, self._base[0], self._base[1], assign,
                       self._options)

    def groups(self) -> dict[str, list[RunChannels]]:
        """``{group: [runs]}``."""
        out: dict[str, list[RunChannels]] = {}
        for r in self.runs:
            out.setdefault(r.group, []).append(r)
        return out

    def summary(self) -> FitSummary:
        """The JSON-able summary ``labkit fit --json`` prints (without the paths written)."""
        return {"fitted_modes": self.listing,
                "assignment": {str(s): (None if v is None else v.index) for s, v in self.mapping.items()},
                "assignment_rule": ma.describe(self.assign_text),
                "modal_freq_hz": list(self.params.modal_freq_hz),
                "modal_damping_ratio": list(self.params.modal_damping_ratio),
                "quality": {g: f.quality for g, f in self.fits.items()},
                "nrmse": {g: f.nrmse for g, f in self.fits.items()},
                "misfit_to_noise": {g: f.misfit_to_noise for g, f in self.fits.items()},
                "dominant_mode": {g: f.dominant_mode for g, f in self.fits.items()},
                "mac": {g: f.mac().tolist() for g, f in self.fits.items() if len(f.locations) > 1 and f.modes},
                "warnings": list(self.warnings), "modes_only": self.modes_only}

    def write(self, out: str | Path, *, figures: bool = True, force: bool = False,
              uff: bool = False) -> FitFiles:
        """Write the parameter file, ``<stem>.fit.h5``, figures (and ``<stem>.fit.uff`` with ``uff``).

        Every output is checked before anything is written (exit 2 when one
        exists and ``force`` is false) and each is replaced atomically.
        Returns ``{"out", "fit_file", "figures", "uff_file"}``.
        """
        from labkit.h5io import utc_now
        from labkit.outputs import atomic_outputs, check_outputs

        paths = output_paths(out, figures=figures, fits=self.fits, uff=uff)
        check_outputs(paths.all(), force=force)
        prov = dict(self.provenance, created_utc=utc_now(), fit_file=paths.fit_file.name)
        figs = list(paths.figures.items()) if figures else []
        targets = [paths.out, paths.fit_file, *([paths.uff_file] if paths.uff_file is not None else []),
                   *(p for _, p in figs)]
        # every file to a temporary name first, all renamed at the end: a failure leaves every old file
        with atomic_outputs(targets) as temps:
            tmp_out, tmp_fit, rest = temps[0], temps[1], temps[2:]
            if self.modes_only:
                _write_modes_toml(tmp_out, self.listing, prov)
            else:
                self.params.to_toml(tmp_out, provenance=prov)
            write_fit_h5(tmp_fit, self.fits, runs_json(self.runs), ma.as_dict(self.mapping),
                         {g: f.summary() for g, f in self.fits.items()})
            if paths.uff_file is not None:
                from labkit.analysis.modal.io import write_uff

                write_uff(rest.pop(0), self.fits)
            if figs:
                from labkit.analysis.modal.plots import plot_frf_fit, plot_stabilisation

                groups = self.groups()
                for ((g, what), _), tmp in zip(figs, rest):
                    f = self.fits[g]
                    if what == "frf":
                        plot_frf_fit(f, tmp, units=groups[g][0].units,
                                     title=f"{g}: {', '.join(Path(r.path).name for r in groups[g])}")
                    else:
                        assert f.stabilisation is not None
                        plot_stabilisation(f.stabilisation, tmp, fit=f)
        written = [str(p) for _, p in figs]
        return {"out": str(paths.out), "fit_file": str(paths.fit_file), "figures": written,
                "uff_file": None if paths.uff_file is None else str(paths.uff_file)}


def _write_modes_toml(path: str | Path, listing: list[FittedModeRow], provenance: dict[str, Json]) -> None:
    """The fitted modes as a TOML table ``[[modes]]`` (not a robot parameter file)."""
    import tomli_w

    prov = {k: v for k, v in provenance.items() if k not in ("modes", "assignment")}   # no simulator modes
    table = {"modes": [{k: v for k, v in m.items() if v is not None} for m in listing], "provenance": prov}
    head = ("# labkit fitted modes (not a robot parameter file: the input was not a labkit run;\n"
            "# `labkit fit ... --assign 1=#K,...` maps modes onto the simulator's and writes one)\n\n")
    Path(path).write_text(head + tomli_w.dumps(table), encoding="utf-8")


def output_paths(out: str | Path, *, figures: bool, fits: dict[str, ModalFit] | None = None,
                 groups: Sequence[str] = (), uff: bool = False) -> FitPaths:
    """The files :meth:`RobotFit.write` writes for parameter file ``out`` (figures per group)."""
    out = Path(out)
    if out.suffix.lower() != ".toml":
        raise InputError("not a .toml path", file=out, key="--out", expected="robot.toml")
    stem = out.with_suffix("")
    figs: dict[tuple[str, str], Path] = {}
    if figures:
        names = list(fits) if fits is not None else list(groups)
        for g in names:
            figs[(g, "frf")] = Path(f"{stem}.fit.{g}.frf.png")
            if fits is None or fits[g].stabilisation is not None:
                figs[(g, "stabilisation")] = Path(f"{stem}.fit.{g}.stabilisation.png")
    return FitPaths(out, Path(f"{stem}.fit.h5"), figs, Path(f"{stem}.fit.uff") if uff else None)


def fit_robot(runs: Sequence[str | Path | RunChannels], *, base: Any = None, assign: str | None = None,
              n_modes: int | None = None, band_hz: tuple[float, float] | None = None, method: str = "lscf",
              covariance: str = "sandwich", min_quality: float = 0.0,
              poles_hz: Sequence[float | tuple[float, float]] | None = None, background: str | None = None,
              frf_kind: str | None = None, columns: str | None = None) -> RobotFit:
    """Fit the resonances of run files (or other FRF files) and assign them to the simulator's modes.

    Parameters
    ----------
    runs:
        Paths (run files ``.h5``; UFF ``.uff``/``.unv``; ``.csv``/``.txt``; Touchstone
        ``.s1p``/``.s2p``, see :func:`~labkit.analysis.modal.io.read_frf`) or
        already-read :class:`~labkit.analysis.modal.io.RunChannels`.
    base:
        ``RobotParams``, a parameter-file path, or None (the paper's values):
        everything not fitted.
    assign:
        The ``--assign`` text (``"1=438,2=#3,3=keep"``, ``"none"``) or None for
        the default rule (:mod:`~labkit.analysis.modal.assign`).
    n_modes, band_hz, method, covariance, poles_hz, background:
        Passed to :func:`~labkit.analysis.modal.fit.fit_modes` for every group.
    min_quality:
        Lines of run files with a quality below this are dropped.
    frf_kind, columns:
        For files other than run files: the FRF kind (default from the file)
        and the CSV column names (``"freq,re,im"`` or ``"freq,mag,phase_deg"``).

    Raises
    ------
    InputError
        Unreadable or inconsistent files, a group that cannot be fitted, a bad
        ``assign`` text; always naming the files.
    """
    from labkit.sim import RobotParams

    if not (0.0 <= min_quality <= 1.0):
        raise InputError(f"{min_quality}", key="--min-quality", expected="a number in 0..1")
    ma.parse_assign(assign)                      # a bad --assign fails before any file is read
    if base is None:
        base_p, base_name = RobotParams(), "RobotParams() defaults"
    elif isinstance(base, RobotParams):
        base_p, base_name = base, "given RobotParams"
    else:
        base_p, base_name = RobotParams.from_toml(base), str(base)
    if not runs:
        raise InputError("no run file given", key="runs", expected="at least one file")
    chans = [r if isinstance(r, RunChannels) else
             read_frf(r, min_quality=min_quality, kind=frf_kind, columns=columns) for r in runs]
    warnings = [w for r in chans for w in r.warnings]
    groups: dict[str, list[RunChannels]] = {}
    for r in chans:
        groups.setdefault(r.group, []).append(r)
    fits: dict[str, ModalFit] = {}
    for group in sorted(groups, key=lambda g: (_GROUP_ORDER + (g,)).index(g)):
        rs = groups[group]
        kinds = {r.frf_kind for r in rs}
        if len(kinds) > 1:
            raise InputError(f"{group} files hold different FRF kinds {sorted(kinds)}",
                             file=", ".join(r.path for r in rs), expected="one kind per group (use --kind)")
        names, freqs, frfs = [], [], []
        multi = len(rs) > 1
        for r in rs:
            for n, f, h in zip(r.names, r.freq_hz, r.frf):
                names.append(f"{Path(r.path).stem}:{n}" if multi else n)
                freqs.append(f)
                frfs.append(h)
        if len(set(names)) != len(names):
            raise InputError(f"two {group} files share a file name and location", key="runs",
                             expected="distinct file names")
        try:
            fit = fit_modes(freqs, frfs, n_modes=n_modes, band_hz=band_hz, method=method, locations=names,
                            kind=kinds.pop(), covariance=covariance, poles_hz=poles_hz, background=background)
        except InputError as exc:
            raise InputError(f"{group} fit: {exc.message}", file=", ".join(r.path for r in rs), key=exc.key,
                             expected=exc.expected) from None
        fits[group] = fit
        warnings += [f"{group}: {w}" for w in fit.warnings]

    options = FitOptions(method, covariance, band_hz, n_modes, min_quality, poles_hz, background,
                         modes_only(chans, assign))
    return _assign(fits, chans, warnings, base_p, base_name, assign, options)


def modes_only(chans: Sequence[RunChannels], assign: str | None) -> bool:
    """True when no input is a labkit run and no mapping onto the simulator's modes is given: then the
    fit writes the modes only (a robot file from someone else's FRF needs an explicit ``--assign``)."""
    return all(r.group == "frf" for r in chans) and (assign is None or assign.strip().lower() in ("none", "keep"))


def _assign(fits: dict[str, ModalFit], chans: list[RunChannels], read_warnings: list[str], base_p: Any,
            base_name: str, assign: str | None, options: FitOptions) -> RobotFit:
    """Number the fitted modes, assign them to the simulator's, build parameters and provenance."""
    spec = ma.parse_assign(assign)
    warnings = list(read_warnings)
    groups: dict[str, list[RunChannels]] = {}
    for r in chans:
        groups.setdefault(r.group, []).append(r)

    fitted: list[ma.FittedMode] = []
    where: list[tuple[str, int]] = []
    for group, fit in fits.items():
        for i, m in enumerate(fit.modes):
            fitted.append(ma.FittedMode(len(fitted) + 1, group, m.freq_hz, m.damping_ratio))
            where.append((group, i))
    only = options.modes_only
    mapping = ma.assign(fitted, base_p.modal_freq_hz, ma.parse_assign("none") if only else spec)
    if only:
        warnings.append("no labkit run among the inputs and no --assign: wrote the fitted modes only, not a "
                        "robot parameter file (--assign 1=#K,... maps them onto the simulator's modes)")
    elif all(v is None for v in mapping.values()):
        warnings.append("no fitted mode assigned to the simulator: every mode keeps the base value "
                        "(use --assign, e.g. --assign 1=#1)")
    listing: list[FittedModeRow] = []
    for fm, (group, i) in zip(fitted, where):
        m = fits[group].modes[i]
        listing.append({"index": fm.index, "group": group, "freq_hz": m.freq_hz, "freq_hz_std": m.freq_hz_std,
                        "damping_ratio": m.damping_ratio, "damping_ratio_std": m.damping_ratio_std,
                        "dominant_location": m.dominant_location, "in_band": m.in_band,
                        "assigned_to": next((s for s, v in mapping.items() if v is not None and v.index == fm.index),
                                            None)})
    new_f = list(base_p.modal_freq_hz)
    new_z = list(base_p.modal_damping_ratio)
    modes_prov: dict[str, Json] = {}
    for sim in (1, 2, 3):
        fm_or_none = mapping[sim]
        if fm_or_none is None:
            modes_prov[str(sim)] = {"source": "base", "base": base_name,
                                    "freq_hz": new_f[sim - 1], "damping_ratio": new_z[sim - 1]}
            continue
        fm = fm_or_none
        item = listing[fm.index - 1]
        group, i = where[fm.index - 1]
        new_f[sim - 1], new_z[sim - 1] = item["freq_hz"], item["damping_ratio"]
        modes_prov[str(sim)] = _mode_provenance(item, fits[group], i, groups[group])
    params = base_p.with_modes(freq_hz=tuple(new_f), damping_ratio=tuple(new_z))
    method, covariance = options.method, options.covariance
    provenance: dict[str, Json] = {
        "source": "labkit fit",
        "runs": [r.path for r in chans],
        "method": method, "covariance": covariance,
        "band_hz": list(options.band_hz) if options.band_hz else "full",
        "n_modes": options.n_modes if options.n_modes else "auto",
        "min_quality": options.min_quality,
        "assignment_rule": ma.describe(assign),
        "assignment": {str(s): ("base (not fitted)" if v is None else f"#{v.index} {v.group} {v.freq_hz:.6g} Hz")
                       for s, v in mapping.items()},
        "quality": {g: f.quality for g, f in fits.items()},
        "nrmse": {g: _per_location(f.nrmse) for g, f in fits.items()},
        "misfit_to_noise": {g: _per_location(f.misfit_to_noise) for g, f in fits.items()},
        "fitted_modes": [{k: v for k, v in it.items() if isinstance(v, (str, int, float))} for it in listing],
        "modes": modes_prov,
        "uncertainty": ("standard uncertainties (1 sigma) from the nonlinear refinement's covariance "
                        f"({covariance})" if method == "lscf" else
                        "standard uncertainties (1 sigma) from a wild bootstrap of the single-mode estimator "
                        "(noise only, not the bias from neighbouring modes)")
        + "; k and b propagated with the f-zeta covariance",
    }
    if options.poles_hz:
        provenance["poles_hz"] = [p if isinstance(p, (int, float)) else list(p) for p in options.poles_hz]
    if options.background:
        provenance["background"] = options.background
    if only:
        provenance["written"] = "fitted modes only (no labkit run, no --assign)"
    return RobotFit(fits, chans, listing, mapping, params, provenance, assign, warnings, only,
                    _base=(base_p, base_name), _options=options, _read_warnings=list(read_warnings))





def _per_location(values: dict[str, float]) -> dict[str, Json]:
    """A per-location number table as a JSON object."""
    return {loc: v for loc, v in values.items()}


def _mode_provenance(item: FittedModeRow, fit: ModalFit, i: int, runs: list[RunChannels]) -> dict[str, Json]:
    """The provenance of one simulator mode taken from a fit, with k and b and their uncertainties."""
    f, sf = item["freq_hz"], item["freq_hz_std"]
    z, sz = item["damping_ratio"], item["damping_ratio_std"]
    cfz = fit.modes[i].freq_damping_cov
    cfz = 0.0 if not math.isfinite(cfz) else cfz
    w = 2 * math.pi * f
    k = w * w
    b = 2 * z * w
    sk = 2 * k * sf / f if f > 0 else float("nan")
    # b = 4 pi zeta f: var = (4 pi f)^2 var(zeta) + (4 pi zeta)^2 var(f) + 2 (4 pi)^2 f zeta cov(f, zeta)
    vb = (4 * math.pi * f * sz) ** 2 + (4 * math.pi * z * sf) ** 2 + 2 * (4 * math.pi) ** 2 * f * z * cfz
    return {"source": "fit", "fitted_index": item["index"], "group": item["group"],
            "runs": [r.path for r in runs], "locations": [loc for loc in fit.locations], "method": fit.method,
            "freq_hz": f, "freq_hz_std": sf, "damping_ratio": z, "damping_ratio_std": sz,
            "k_per_s2": k, "k_per_s2_std": sk, "b_per_s": b, "b_per_s_std": math.sqrt(max(vb, 0.0)),
            "dominant_location": item["dominant_location"], "fit_quality": fit.quality}
