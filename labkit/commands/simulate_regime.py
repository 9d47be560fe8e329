"""``labkit simulate regime-map`` and ``labkit simulate shaker|pzt --edges``: the thin command side of
:mod:`labkit.sim.regime` (a helper module of :mod:`labkit.commands.simulate`, not a command of its own).
"""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from labkit.errors import InputError
from labkit.jsonutil import Json
from labkit.outputs import atomic_outputs, check_outputs

if TYPE_CHECKING:
    from labkit.sim.regime import EdgeReport, Regime, RegimeMap, RunTask
    from labkit.sim.result import SimResult

MAP_SUFFIXES = (".h5", ".hdf5", ".csv")
FIGURE_SUFFIXES = (".png", ".svg")
#: The grid's level axis per drive: (option, field, unit, default).
LEVELS = {"shaker": ("--amp-um", "amp_um", "um", "5:40:8"), "pzt": ("--voltage-v", "voltage_v", "V", "2:20:4")}


def add_regime_map(sub: Any, common: argparse.ArgumentParser, pclass: type) -> None:
    """The ``regime-map`` subcommand's parser."""
    rm = sub.add_parser("regime-map", parents=[common],
                        help="gait regime (still / firm / partial / jumping) over frequency x amplitude or voltage")
    rm.add_argument("kind", choices=("shaker", "pzt"), help="shaker: frequency x tray amplitude; pzt: x voltage")
    rm.add_argument("--freq-hz", default=None, metavar="A:B:N",
                    help="frequencies, Hz: start:stop:count or a comma list (default 100:400:7 shaker, "
                         "1000:2600:5 pzt)")
    for kind, (opt, field, unit, default) in LEVELS.items():
        rm.add_argument(opt, default=None, metavar="A:B:N",
                        help=f"{kind} only: {field} in {unit}, start:stop:count or a comma list (default {default})")
    rm.add_argument("--mass-mg", default=None, metavar="MG", help="pzt only: total robot mass with payload, mg")
    rm.add_argument("--params", metavar="NAME|FILE",
                    help="robot parameters: a preset (published, paper) or a TOML file; default: published")
    rm.add_argument("--duration-s", default="0.5", metavar="S", help="simulated time per point, s (default 0.5)")
    rm.add_argument("--seed", default="0", metavar="N", help="random seed (default 0)")
    rm.add_argument("--out", metavar="FILE.h5|FILE.csv", help="write the map (HDF5 or CSV)")
    rm.add_argument("--figure", metavar="FILE.png|FILE.svg", help="draw the map")
    rm.add_argument("--force", action="store_true", help="replace --out / --figure if they exist")
    rm.add_argument("--scheduler", default=None, metavar="URL", help="Dask scheduler tcp://HOST:PORT")
    rm.add_argument("--workers", default=None, metavar="N", help="local worker processes (default: one per core)")


def _axis(text: str | None, default: str, option: str) -> list[float]:
    from labkit.commands.simulate import is_range, number, parse_range

    text = default if text is None else text
    return parse_range(text, option) if is_range(text) else [number(text, option, positive=True)]


def run_regime_map(args: argparse.Namespace) -> dict[str, Json]:
    """Check every input, run the map, write its file and figure."""
    from labkit.commands.simulate import OPTION_KEYS, integer, load_params, number
    from labkit.sim.regime import Grid, Runs, regime_map

    kind = args.kind
    other = "pzt" if kind == "shaker" else "shaker"
    if getattr(args, LEVELS[other][1]) is not None or (kind == "shaker" and args.mass_mg is not None):
        opt = LEVELS[other][0] if getattr(args, LEVELS[other][1]) is not None else "--mass-mg"
        raise InputError(f"{opt} is for a {other} map", key=opt, expected=f"{LEVELS[kind][0]} for a {kind} map")
    opt, field, _, default = LEVELS[kind]
    freqs = _axis(args.freq_hz, "100:400:7" if kind == "shaker" else "1000:2600:5", "--freq-hz")
    levels = _axis(getattr(args, field), default, opt)
    mass = None if args.mass_mg is None else number(args.mass_mg, "--mass-mg", positive=True)
    duration_s = number(args.duration_s, "--duration-s", positive=True)
    seed = integer(args.seed, "--seed")
    workers = None if args.workers is None else integer(args.workers, "--workers", minimum=1)
    check_outputs([args.out], force=args.force, suffixes=MAP_SUFFIXES)
    check_outputs([args.figure], force=args.force, key="--figure", suffixes=FIGURE_SUFFIXES)
    params = load_params(args.params)
    m = regime_map(params, Grid(kind, freqs, levels, mass),
                   Runs(duration_s, seed, args.scheduler, workers, args.quiet, OPTION_KEYS))
    m.meta["params"] = args.params or "published"
    summary = m.summary()
    outs = [(p, w) for p, w in ((args.out, m.to_csv if str(args.out).lower().endswith(".csv") else m.to_h5),
                                (args.figure, m.to_figure)) if p]
    with atomic_outputs([p for p, _ in outs]) as temps:
        for tmp, (_, write) in zip(temps, outs):
            write(tmp)
    for key, path in (("out", args.out), ("figure", args.figure)):
        if path:
            summary[key] = str(path)
    if not args.json:
        _print_map(m, [str(p) for p in (args.out, args.figure) if p])
    return summary


def _print_map(m: RegimeMap, written: list[str]) -> None:
    print(f"regime map ({m.kind}, {m.meta['duration_s']:g} s per point): "
          + ", ".join(f"{n} {r}" for r, n in m.counts().items() if n))
    print(f"  {'freq_hz':>8}  " + "  ".join(f"{v:>9.4g}" for v in m.level) + f"   <- {m.level_name}")
    for i, f in enumerate(m.freq_hz):
        print(f"  {f:8.4g}  " + "  ".join(f"{r:>9}" for r in m.regimes[i]))
    for path in written:
        print(f"  wrote {path}")


def edge_keys_of(args: argparse.Namespace, params: Any, scenario: Any) -> list[str] | None:
    """The parameters ``--edge-params`` names (``None``: the default set), checked before any run."""
    from labkit.sim.regime import DRIVE_KEY, scaled

    text = getattr(args, "edge_params", None)
    if text is None:
        return None
    if not getattr(args, "edges", False):
        raise InputError("--edge-params needs --edges", key="--edge-params", expected="--edges as well")
    keys = [k.strip() for k in text.split(",") if k.strip()]
    if not keys:
        raise InputError(f"no parameters in {text!r}", key="--edge-params", expected="a comma list of names")
    for k in keys:
        if k != DRIVE_KEY:
            scaled(params, scenario, k, 1.0)        # ConfigError naming an unknown parameter
    return keys


def regime_summary(reg: Regime) -> dict[str, object]:
    """A run's regime as its JSON shows it (:meth:`~labkit.sim.regime.Regime.to_dict` and the one-line text)."""
    return {**reg.to_dict(), "text": reg.text()}


def add_regime(summary: dict[str, object], r: SimResult, task: RunTask, args: argparse.Namespace,
               keys: list[str] | None = None) -> tuple[Regime, EdgeReport | None]:
    """The run's regime into its summary, and with ``--edges`` its distance to every edge in ``keys``
    (``task``: the run's robot, drive, duration and seed); returns both (edges: None without ``--edges``)."""
    from labkit.sim.regime import EdgeSearch, Runs, classify_regime, find_edges

    reg = classify_regime(r)
    summary["regime"] = regime_summary(reg)
    if not getattr(args, "edges", False):
        return reg, None
    from labkit.commands.simulate import OPTION_KEYS

    # the edge runs start at rest at the default step: a run that did not is re-run that way first
    plain = getattr(args, "dt_s", None) is None and getattr(args, "start_height_um", None) is None
    runs = Runs(task.duration_s, task.seed, quiet=args.quiet, bound_keys=OPTION_KEYS)
    edges = find_edges(task.params, task.scenario, runs, EdgeSearch(keys=keys), base=reg if plain else None)
    summary["edges"] = edges.to_dict()
    return reg, edges
