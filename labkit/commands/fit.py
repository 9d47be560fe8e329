"""``labkit fit RUN.h5 [RUN2.h5 ...] --out robot.toml``: resonance fits into a robot parameter file.

In-chip run files (the tethered robot; every location of every in-chip file
fitted with common poles) and shaker run files (the released robot's
transmissibility, fitted separately: different boundary conditions, different
poles) are fitted with standard uncertainties; the fitted modes are listed
with numbers, and the assignment of fitted modes to the simulator's modes 1-3
is explicit (``--assign``; see ``analysis.modal_assign`` for the default
rule). Writes the parameter file (modal stiffness ``k = (2 pi f)^2`` and
damping ``b = 2 zeta (2 pi f)`` of assigned modes, the rest from ``--base``),
with a ``[provenance]`` table, and beside it ``<out>.fit.h5`` and PNG figures.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from labkit.errors import InputError

NAME = "fit"
HELP = "fit resonances (with uncertainties) of in-chip / shaker run files into a robot parameter file"

METHODS = ("lscf", "peak", "circle")


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", metavar="RUN.h5", help="in-chip and/or shaker run files")
    parser.add_argument("--out", required=True, metavar="robot.toml", help="robot parameter file to write")
    parser.add_argument("--assign", metavar="SPEC",
                        help="fitted -> simulator modes: '1=438,2=#3,3=keep' (Hz, #listed number, keep) or "
                             "'none'; default: nearest within 15%% of the base file's modes")
    parser.add_argument("--n-modes", type=int, metavar="N", help="modes per fit (default: from the "
                        "stabilisation diagram)")
    parser.add_argument("--band-hz", metavar="LO:HI", help="fit only lines in this band")
    parser.add_argument("--method", choices=METHODS, default="lscf",
                        help="lscf (multi-mode, default), peak (half power) or circle")
    parser.add_argument("--covariance", choices=("sandwich", "residual"), default="sandwich",
                        help="uncertainty of the lscf fit: sandwich (robust to line-to-line noise changes, "
                             "default) or residual (s^2 (J^T J)^-1); peak and circle use a bootstrap")
    parser.add_argument("--base", metavar="robot.toml", help="parameter file for everything not fitted "
                        "(default: the paper's values)")
    parser.add_argument("--min-quality", type=float, default=0.0, metavar="Q",
                        help="drop lines whose quality (sine-fit R^2 or coherence) is below Q (default 0)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--force", action="store_true", help="overwrite --out and the fit file")


def _band(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(x) for x in text.split(":"))
    except ValueError:
        raise InputError(f"bad band {text!r}", key="--band-hz", expected="LO:HI in Hz, e.g. 200:5000") from None
    if not (0 < lo < hi and math.isfinite(hi)):
        raise InputError(f"bad band {text!r}", key="--band-hz", expected="0 < LO < HI")
    return lo, hi


def run(args: argparse.Namespace) -> dict[str, Any]:
    from analysis import modal_assign as ma
    from analysis.modal import fit_modes
    from analysis.modal_io import read_run, runs_json, write_fit_h5
    from labkit.cli import require_file
    from labkit.h5io import utc_now
    from labkit.sim import RobotParams

    band = _band(args.band_hz)
    if args.n_modes is not None and args.n_modes < 1:
        raise InputError(f"{args.n_modes}", key="--n-modes", expected="an integer >= 1")
    if not (0.0 <= args.min_quality <= 1.0):
        raise InputError(f"{args.min_quality}", key="--min-quality", expected="a number in 0..1")
    spec = ma.parse_assign(args.assign)
    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise InputError("not a .toml path", file=out, key="--out", expected="robot.toml")
    stem = out.with_suffix("")
    fit_path = Path(f"{stem}.fit.h5")
    for p in (out, fit_path):
        if p.exists() and not args.force:
            raise InputError("already exists (use --force to overwrite)", file=p, key="--out")
    if not out.parent.is_dir():
        raise InputError("folder does not exist", file=out.parent, key="--out")
    for r in args.runs:
        require_file(r, "run file")
    base = RobotParams.from_toml(args.base) if args.base else RobotParams()

    runs = [read_run(r, min_quality=args.min_quality) for r in args.runs]
    warnings = [w for r in runs for w in r.warnings]
    groups: dict[str, list] = {}
    for r in runs:
        groups.setdefault(r.group, []).append(r)
    fits = {}
    for group, rs in groups.items():
        names, freqs, frfs = [], [], []
        multi = len(rs) > 1
        for r in rs:
            for n, f, h in zip(r.names, r.freq_hz, r.frf):
                names.append(f"{Path(r.path).stem}:{n}" if multi else n)
                freqs.append(f)
                frfs.append(h)
        if len(set(names)) != len(names):
            raise InputError(f"two {group} runs share a file name and location", key="runs",
                             expected="distinct run file names")
        try:
            fit = fit_modes(freqs, frfs, n_modes=args.n_modes, band_hz=band, method=args.method,
                            locations=names, kind="mobility" if group == "inchip" else "transmissibility",
                            covariance=args.covariance)
        except InputError as exc:
            files = ", ".join(r.path for r in rs)
            raise InputError(f"{group} fit: {exc.message}", file=files, key=exc.key,
                             expected=exc.expected) from None
        fits[group] = fit
        warnings += [f"{group}: {w}" for w in fit.warnings]

    fitted: list[ma.FittedMode] = []
    for group in ("inchip", "shaker"):
        if group in fits:
            for m in fits[group].modes:
                fitted.append(ma.FittedMode(len(fitted) + 1, group, m.freq_hz, m.damping_ratio))
    mapping = ma.assign(fitted, base.modal_freq_hz, spec)
    if all(v is None for v in mapping.values()):
        warnings.append("no fitted mode assigned to the simulator: every mode keeps the base value "
                        "(use --assign, e.g. --assign 1=#1)")

    listing = []
    for fm in fitted:
        m = fits[fm.group].modes[[x.freq_hz for x in fits[fm.group].modes].index(fm.freq_hz)]
        listing.append({"index": fm.index, "group": fm.group, "freq_hz": m.freq_hz, "freq_hz_std": m.freq_hz_std,
                        "damping_ratio": m.damping_ratio, "damping_ratio_std": m.damping_ratio_std,
                        "dominant_location": m.dominant_location,
                        "assigned_to": next((s for s, v in mapping.items() if v is not None and v.index == fm.index),
                                            None)})
    new_f = list(base.modal_freq_hz)
    new_z = list(base.modal_damping_ratio)
    modes_prov: dict[str, Any] = {}
    for sim in (1, 2, 3):
        fm = mapping[sim]
        if fm is None:
            modes_prov[str(sim)] = {"source": "base", "base": args.base or "RobotParams() defaults",
                                    "freq_hz": new_f[sim - 1], "damping_ratio": new_z[sim - 1]}
            continue
        item = listing[fm.index - 1]
        fit = fits[fm.group]
        new_f[sim - 1], new_z[sim - 1] = item["freq_hz"], item["damping_ratio"]
        modes_prov[str(sim)] = _mode_provenance(item, fit, groups[fm.group])
    params = base.with_modes(freq_hz=tuple(new_f), damping_ratio=tuple(new_z))
    provenance = {
        "source": "labkit fit", "created_utc": utc_now(),
        "runs": [r.path for r in runs], "fit_file": fit_path.name,
        "method": args.method, "covariance": args.covariance,
        "band_hz": list(band) if band else "full", "n_modes": args.n_modes if args.n_modes else "auto",
        "min_quality": args.min_quality,
        "assignment_rule": ma.describe(args.assign),
        "assignment": {k: ("base (not fitted)" if v is None else f"#{v.index} {v.group} {v.freq_hz:.6g} Hz")
                       for k, v in {str(s): mapping[s] for s in (1, 2, 3)}.items()},
        "quality": {g: f.quality for g, f in fits.items()},
        "nrmse": {g: f.nrmse for g, f in fits.items()},
        "fitted_modes": [{k: v for k, v in it.items() if v is not None} for it in listing],
        "modes": modes_prov,
        "uncertainty": ("standard uncertainties (1 sigma) from the nonlinear refinement's covariance "
                        f"({args.covariance})" if args.method == "lscf" else
                        "standard uncertainties (1 sigma) from a wild bootstrap of the single-mode estimator "
                        "(noise only, not the bias from neighbouring modes)")
        + "; k and b propagated with the f-zeta covariance",
    }
    params.to_toml(out, provenance=provenance)

    summary_fit = {g: f.summary() for g, f in fits.items()}
    write_fit_h5(fit_path, fits, runs_json(runs), ma.as_dict(mapping), summary_fit)
    figures: list[str] = []
    if not args.no_figures:
        from analysis.fitplots import plot_frf_fit, plot_stabilisation

        for g, f in fits.items():
            units = "(mm/s)/V" if g == "inchip" else ""
            figures.append(str(plot_frf_fit(f, f"{stem}.fit.{g}.frf.png", units=units,
                                            title=f"{g}: {', '.join(Path(r.path).name for r in groups[g])}")))
            if f.stabilisation is not None:
                figures.append(str(plot_stabilisation(f.stabilisation, f"{stem}.fit.{g}.stabilisation.png",
                                                      fit=f)))
    for w in warnings:
        print(f"labkit fit: warning: {w}", file=sys.stderr)
    summary = {"out": str(out), "fit_file": str(fit_path), "figures": figures,
               "fitted_modes": listing,
               "assignment": {str(s): (None if v is None else v.index) for s, v in mapping.items()},
               "assignment_rule": ma.describe(args.assign),
               "modal_freq_hz": list(params.modal_freq_hz),
               "modal_damping_ratio": list(params.modal_damping_ratio),
               "quality": {g: f.quality for g, f in fits.items()},
               "nrmse": {g: f.nrmse for g, f in fits.items()},
               "dominant_mode": {g: f.dominant_mode for g, f in fits.items()},
               "warnings": warnings}
    if not args.json:
        _print(summary)
    return summary


def _mode_provenance(item: dict[str, Any], fit: Any, runs: list) -> dict[str, Any]:
    """The provenance of one simulator mode taken from a fit, with k and b and their uncertainties."""
    f, sf = item["freq_hz"], item["freq_hz_std"]
    z, sz = item["damping_ratio"], item["damping_ratio_std"]
    i = [m.freq_hz for m in fit.modes].index(f)
    cfz = fit.modes[i].freq_damping_cov
    cfz = 0.0 if not math.isfinite(cfz) else cfz
    w = 2 * math.pi * f
    k = w * w
    b = 2 * z * w
    sk = 2 * k * sf / f if f > 0 else float("nan")
    # b = 4 pi zeta f: var = (4 pi f)^2 var(zeta) + (4 pi zeta)^2 var(f) + 2 (4 pi)^2 f zeta cov(f, zeta)
    vb = (4 * math.pi * f * sz) ** 2 + (4 * math.pi * z * sf) ** 2 + 2 * (4 * math.pi) ** 2 * f * z * cfz
    return {"source": "fit", "fitted_index": item["index"], "group": item["group"],
            "runs": [r.path for r in runs], "locations": fit.locations, "method": fit.method,
            "freq_hz": f, "freq_hz_std": sf, "damping_ratio": z, "damping_ratio_std": sz,
            "k_per_s2": k, "k_per_s2_std": sk, "b_per_s": b, "b_per_s_std": math.sqrt(max(vb, 0.0)),
            "dominant_location": item["dominant_location"], "fit_quality": fit.quality}


def _print(s: dict[str, Any]) -> None:
    print(f"{'#':>3} {'group':7} {'freq_hz':>12} {'+-':>9} {'zeta':>9} {'+-':>9}  dominant  -> sim mode")
    for m in s["fitted_modes"]:
        print(f"{m['index']:>3} {m['group']:7} {m['freq_hz']:12.5g} {m['freq_hz_std']:9.2g} "
              f"{m['damping_ratio']:9.4g} {m['damping_ratio_std']:9.2g}  {m['dominant_location']:8} "
              f"-> {m['assigned_to'] if m['assigned_to'] else '-'}")
    print(f"assignment: {s['assignment_rule']}")
    print("simulator modes: " + ", ".join(f"{f:.5g} Hz (zeta {z:.3g})"
                                          for f, z in zip(s["modal_freq_hz"], s["modal_damping_ratio"])))
    print(f"wrote {s['out']}, {s['fit_file']}" + (f" and {len(s['figures'])} figures" if s["figures"] else ""))
