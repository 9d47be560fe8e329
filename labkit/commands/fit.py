"""``labkit fit RUN.h5 [RUN2.h5 ...] --out robot.toml``: resonance fits into a robot parameter file.

The work is :func:`labkit.analysis.modal.fit_robot` (the same call a notebook
or the demo makes); this module parses the options, prints and writes.
Besides run files it reads UFF 58 (``.uff``, ``.unv``), CSV (``--columns``)
and Touchstone (``.s1p``, ``.s2p``) files; ``--uff`` also writes the fitted
modes as UFF 55 and the fitted FRFs as UFF 58.

In-chip run files (the tethered robot; every location of every in-chip file
fitted with common poles) and shaker run files (the released robot's
transmissibility, fitted separately: different boundary conditions, different
poles) are fitted with standard uncertainties; the fitted modes are listed
with numbers, and the assignment of fitted modes to the simulator's modes 1-3
is explicit (``--assign``; see ``labkit.analysis.modal.assign`` for the default
rule). Writes the parameter file (modal stiffness ``k = (2 pi f)^2`` and
damping ``b = 2 zeta (2 pi f)`` of assigned modes, the rest from ``--base``),
with a ``[provenance]`` table, and beside it ``<out>.fit.h5`` and PNG figures.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING

from labkit.errors import InputError

if TYPE_CHECKING:
    from labkit.analysis.modal.robot import FitResult

NAME = "fit"
HELP = ("fit resonances (with uncertainties) of in-chip / shaker run files (or UFF 58, CSV, Touchstone FRFs) "
        "into a robot parameter file")

METHODS = ("lscf", "peak", "circle")


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", metavar="FILE",
                        help="in-chip and/or shaker run files (.h5), or FRFs as UFF 58 (.uff/.unv), CSV (.csv/.txt) "
                             "or Touchstone (.s1p/.s2p)")
    parser.add_argument("--out", required=True, metavar="robot.toml",
                        help="robot parameter file to write (FRF files that are not labkit runs, without --assign: "
                             "the fitted modes only, as [[modes]])")
    parser.add_argument("--assign", metavar="SPEC",
                        help="fitted -> simulator modes: '1=438,2=#3,3=keep' (Hz, #listed number, keep) or "
                             "'none'; default: nearest within 15%% of the base file's modes")
    parser.add_argument("--n-modes", type=int, metavar="N", help="exactly N modes per fit (default: from the "
                        "stabilisation diagram and the misfit against the noise)")
    parser.add_argument("--poles", metavar="F1,F2,...", help="poles chosen by hand: frequencies in Hz (held; damping "
                        "and residues fitted), or F:ZETA pairs (both held), e.g. 438,1200 or 438:0.25,1200")
    parser.add_argument("--band-hz", metavar="LO:HI", help="fit only lines in this band")
    parser.add_argument("--method", choices=METHODS, default="lscf",
                        help="lscf (multi-mode, default), peak (half power) or circle")
    parser.add_argument("--covariance", choices=("sandwich", "residual"), default="sandwich",
                        help="uncertainty of the lscf fit: sandwich (robust to line-to-line noise changes, "
                             "default) or residual (s^2 (J^T J)^-1); peak and circle use a bootstrap")
    parser.add_argument("--background", choices=("linear", "linear+delay"),
                        help="fit a constant + slope under the modes (a resonance over a background or seen as a "
                             "dip); linear+delay also a line delay (reflection data)")
    parser.add_argument("--kind", choices=("mobility", "receptance", "accelerance", "transmissibility", "scattering"),
                        help="FRF kind of UFF/CSV/Touchstone files (default: from the file; CSV: mobility)")
    parser.add_argument("--columns", metavar="SPEC",
                        help="CSV columns: 'f=freq_hz,re=H_re,im=H_im' or 'f=1,mag=2,deg=3' (names or 1-based "
                             "numbers; db= for dB, rad= for radians); Touchstone: which S-parameters, e.g. S21")
    parser.add_argument("--base", metavar="robot.toml", help="parameter file for everything not fitted "
                        "(default: the paper's values)")
    parser.add_argument("--min-quality", type=float, default=0.0, metavar="Q",
                        help="drop lines whose quality (sine-fit R^2 or coherence) is below Q (default 0)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--uff", action="store_true", help="also write <out>.fit.uff: the modes as UFF 55, the fitted "
                        "FRFs as UFF 58")
    parser.add_argument("--force", action="store_true", help="overwrite --out and the files written beside it")


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


def _poles(text: str | None) -> list[float | tuple[float, float]] | None:
    if text is None:
        return None
    out: list[float | tuple[float, float]] = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        try:
            if ":" in item:
                f, z = (float(x) for x in item.split(":"))
                out.append((f, z))
            else:
                out.append(float(item))
        except ValueError:
            raise InputError(f"bad pole {item!r}", key="--poles",
                             expected="frequencies in Hz, or F:ZETA pairs, comma-separated (438,1200)") from None
    if not out:
        raise InputError("no pole given", key="--poles", expected="e.g. 438,1200")
    return out


def run(args: argparse.Namespace) -> FitResult:
    from labkit.analysis.modal.robot import fit_robot, output_paths
    from labkit.cli import require_file
    from labkit.outputs import check_outputs

    band = _band(args.band_hz)
    poles = _poles(args.poles)
    if args.n_modes is not None and args.n_modes < 1:
        raise InputError(f"{args.n_modes}", key="--n-modes", expected="an integer >= 1")
    if poles is not None and args.n_modes is not None:
        raise InputError("--poles and --n-modes together", key="--poles", expected="one of them")
    if not (0.0 <= args.min_quality <= 1.0):
        raise InputError(f"{args.min_quality}", key="--min-quality", expected="a number in 0..1")
    # Outputs checked before any work (figures: one per group that may be fitted).
    paths = output_paths(args.out, figures=not args.no_figures, groups=("inchip", "shaker", "frf"),
                         uff=args.uff)
    check_outputs(paths.all(), force=args.force)
    for r in args.runs:
        require_file(r, "input file")
    rf = fit_robot(args.runs, base=args.base, assign=args.assign, n_modes=args.n_modes, band_hz=band,
                   method=args.method, covariance=args.covariance, min_quality=args.min_quality,
                   poles_hz=poles, background=args.background, frf_kind=args.kind, columns=args.columns)
    written = rf.write(args.out, figures=not args.no_figures, force=args.force, uff=args.uff)
    for w in rf.warnings:
        print(f"labkit fit: warning: {w}", file=sys.stderr)
    summary: FitResult = {**written, **rf.summary()}
    if not args.json:
        _print(summary)
    return summary


def _print(s: FitResult) -> None:
    from labkit.analysis.modal.fit import MISFIT_WARN

    print(f"{'#':>3} {'group':7} {'freq_hz':>12} {'+-':>9} {'zeta':>9} {'+-':>9}  dominant  -> sim mode")
    for m in s["fitted_modes"]:
        print(f"{m['index']:>3} {m['group']:7} {m['freq_hz']:12.8g} {m['freq_hz_std']:9.2g} "
              f"{m['damping_ratio']:9.4g} {m['damping_ratio_std']:9.2g}  {m['dominant_location']:8} "
              f"-> {m['assigned_to'] if m['assigned_to'] else '-'}")
    for g, ratio in s["misfit_to_noise"].items():
        worst = max(ratio.values()) if ratio else float("nan")
        flag = "  <- WARNING: well above the noise (see the warnings)" if worst > MISFIT_WARN else ""
        print(f"{g}: quality {s['quality'][g]:.4g}, misfit {worst:.3g} x noise{flag}")
    for g, mac in s.get("mac", {}).items():
        first = next(m["index"] for m in s["fitted_modes"] if m["group"] == g)
        print(f"{g}: MAC between its modes (1 = same shape over the locations):")
        for i, row in enumerate(mac):
            print(f"  #{first + i:<3}" + " ".join(f"{v:5.2f}" for v in row))
    if s.get("modes_only"):
        print(f"wrote the fitted modes only to {s['out']} (no labkit run among the inputs; --assign 1=#K,... "
              f"writes a robot parameter file), and {s['fit_file']}")
        return
    print(f"assignment: {s['assignment_rule']}")
    print("simulator modes: " + ", ".join(f"{f:.5g} Hz (zeta {z:.3g})"
                                          for f, z in zip(s["modal_freq_hz"], s["modal_damping_ratio"])))
    extra = [x for x in (s.get("uff_file"),) if x]
    print(f"wrote {s['out']}, {s['fit_file']}" + "".join(f", {x}" for x in extra)
          + (f" and {len(s['figures'])} figures" if s["figures"] else ""))
