"""``labkit simulate``: run the bundled hybrid simulator (single runs, sweeps, named scenarios).

Examples
--------
::

    labkit simulate shaker --freq-hz 240 --amp-um 25 --duration-s 2 --json
    labkit simulate pzt --freq-hz 1800 --voltage-v 20 --mass-mg 1.0
    labkit simulate sweep shaker --freq-hz 150:2000:40 --amp-um 25 --draws 10 --out f8.h5
    labkit simulate sweep pzt --mass-mg 0.33:2.5:10 --freq-hz 1800 --voltage-v 20
    labkit simulate scenario shaker-speed --out results/
    labkit simulate modes --params paper --json
    labkit simulate shaker --freq-hz 240 --amp-um 25 --edges
    labkit simulate regime-map shaker --freq-hz 100:400:7 --amp-um 5:40:8 --out map.h5 --figure map.png

A range is ``start:stop:count`` (``count`` evenly spaced values, both ends
included) or a comma list ``a,b,c``; exactly one option of a sweep is a range.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from labkit.errors import InputError
from labkit.outputs import atomic_output, check_output_dir, check_outputs

if TYPE_CHECKING:
    from labkit.sim.core import DtCheck
    from labkit.sim.regime import EdgeReport, Regime
    from labkit.sim.result import SimResult
    from labkit.sim.sweep import SweepResult

NAME = "simulate"
HELP = "run the hybrid microrobot simulator: shaker or PZT runs, sweeps with Monte Carlo, named scenarios"

#: Options that may be swept, per scenario type: (option, scenario field, unit text).
SWEEPABLE = {
    "shaker": [("--freq-hz", "freq_hz", "Hz"), ("--amp-um", "amp_um", "um"), ("--mass-mg", "mass_mg", "mg")],
    "pzt": [("--freq-hz", "freq_hz", "Hz"), ("--voltage-v", "voltage_v", "V"), ("--mass-mg", "mass_mg", "mg")],
}
DEFAULTS = {"shaker": {"freq_hz": 240.0, "amp_um": 25.0}, "pzt": {"freq_hz": 1800.0, "voltage_v": 20.0}}
ABLATIONS = ("none", "no_adhesion", "no_squeeze_film")
H5_SUFFIXES = (".h5", ".hdf5")
#: The named scenarios (labkit.sim.scenarios.SCENARIOS; listed here so that
#: ``labkit --help`` does not import the simulator). A test keeps them equal.
SCENARIO_NAMES = {
    "shaker-speed": "speed vs shaker frequency at 25 um (paper Fig. 8)",
    "leg-patterns": "foot patterns as the shaker amplitude grows (Fig. 9-11)",
    "ablations": "full model vs no adhesion vs no squeeze film (Fig. 12)",
    "pzt-payload": "speed vs total mass, PZT 1.8 kHz tripod (Fig. 13)",
    "pzt-frequency": "speed vs PZT frequency near 438 Hz at 20 V (Fig. 14)",
    "adhesion": "speed vs the adhesion magnitude (what the shaker behaviour hinges on)",
    "paper-fig8": "the paper's Fig. 8 observations on its shaker law (pass/fail per observation)",
    "paper-patterns": "the paper's 2-8 V leg patterns, Fig. 9-11 (pass/fail per observation)",
    "paper-ablations": "the paper's Fig. 12 ablations in partial contact (pass/fail/n-a per observation)",
    "paper-payload": "the paper's Fig. 13 PZT payload limit (pass/fail per observation)",
    "paper-fig14": "the paper's Fig. 14 PZT speed near 438 Hz (pass/fail per observation)",
    "paper-spectrum": "the paper's Fig. 6 out-of-chip spectrum, stepped sine (pass/fail per observation)",
}


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    pclass = type(parser)  # keep the CLI's one-line, exit-2 usage errors in nested parsers
    sub = parser.add_subparsers(dest="sim_command", metavar="WHAT", parser_class=pclass)
    sub.required = True

    run_opts = pclass(add_help=False)
    run_opts.add_argument("--params", metavar="NAME|FILE",
                          help="robot parameters: a preset (published, paper) or a TOML file; default: paper")
    run_opts.add_argument("--duration-s", default="2.0", metavar="S", help="simulated time per run, s (default 2)")
    run_opts.add_argument("--seed", default="0", metavar="N", help="random seed (default 0)")
    run_opts.add_argument("--ablate", choices=ABLATIONS, default="none",
                          help="switch a small-scale force off (paper Fig. 12)")
    run_opts.add_argument("--out", metavar="FILE.h5", help="write the result as HDF5 (its folder must exist)")
    run_opts.add_argument("--force", action="store_true", help="replace --out if it exists")
    single_opts = pclass(add_help=False)
    single_opts.add_argument("--start-height-um", default=None, metavar="UM",
                             help="start at rest in the air, the body's underside UM above its resting "
                                  "gap (drop tests, free flight); default: resting on the feet")
    single_opts.add_argument("--dt-s", default=None, metavar="S",
                             help="integration step, s, used as given: the run does not check it "
                                  "(default: 32 steps per period of the fastest leg mode, halved until two "
                                  "steps agree; PZT: rounded down to a whole number of steps per half drive "
                                  "period)")
    single_opts.add_argument("--dt-check", action="store_true",
                             help="also run 4 seeds at the default step and at a quarter of it; report "
                                  "the difference of the mean speeds and whether the run is chaotic")
    single_opts.add_argument("--edges", action="store_true",
                             help="also find, per uncertain parameter, the smallest change (2-20 %%) that "
                                  "changes the gait regime or the speed by > 30 %% (many more runs)")
    single_opts.add_argument("--edge-params", default=None, metavar="LIST",
                             help="with --edges: the parameters to perturb, comma-separated (drive = tray "
                                  "amplitude or PZT voltage; default: drive, the Monte Carlo table's keys "
                                  "and modal_participation)")

    shaker = sub.add_parser("shaker", parents=[common, run_opts, single_opts],
                            help="one run on a vertically vibrating tray")
    shaker.add_argument("--freq-hz", default="240", metavar="HZ", help="tray frequency, Hz (default 240)")
    shaker.add_argument("--amp-um", default="25", metavar="UM", help="tray amplitude, um (default 25)")

    pzt = sub.add_parser("pzt", parents=[common, run_opts, single_opts],
                         help="one run driven by the on-board PZT (tripod gait)")
    pzt.add_argument("--freq-hz", default="1800", metavar="HZ", help="drive frequency, Hz (default 1800)")
    pzt.add_argument("--voltage-v", default="20", metavar="V", help="square-wave amplitude, V (default 20)")
    pzt.add_argument("--mass-mg", default=None, metavar="MG", help="total robot mass with payload, mg")

    sw = sub.add_parser("sweep", parents=[common], help="sweep one quantity, with Monte Carlo draws")
    swsub = sw.add_subparsers(dest="sweep_kind", metavar="KIND", parser_class=pclass)
    swsub.required = True
    sweep_opts = pclass(add_help=False)
    sweep_opts.add_argument("--draws", default="0", metavar="N",
                            help="Monte Carlo draws per point (0: nominal robot only; n: nominal + n-1 drawn)")
    sweep_opts.add_argument("--scheduler", default=None, metavar="URL",
                            help="Dask scheduler tcp://HOST:PORT (default: local processes)")
    sweep_opts.add_argument("--workers", default=None, metavar="N",
                            help="local worker processes (default: one per core)")
    sweep_opts.add_argument("--step-fraction", default="1", metavar="F",
                            help="run at this fraction of the default step (0 < F <= 1; default 1), where "
                                 "--dt-check says the default step is not converged")
    sweep_opts.add_argument("--dt-check", action="store_true",
                            help="also run the nominal robot at every point at a quarter of the step and "
                                 "report whether each point's speed is converged")
    for kind, opts in SWEEPABLE.items():
        p = swsub.add_parser(kind, parents=[common, run_opts, sweep_opts],
                             help=f"sweep a {kind} run over one of {', '.join(o for o, _, _ in opts)}")
        if kind == "shaker":
            p.add_argument("--accel-limit-g", default=None, metavar="G",
                           help="cap the tray's peak acceleration (g) by cutting the amplitude, as a "
                                "force-limited shaker does at high frequency (default: no cap)")
        for opt, field, unit in opts:
            default = DEFAULTS[kind].get(field)
            p.add_argument(opt, default=None if default is None else str(default), metavar="X|A:B:N",
                           help=f"{field} in {unit}: a value or a range start:stop:count"
                                + (f" (default {default:g})" if default is not None else ""))

    md = sub.add_parser("modes", parents=[common],
                        help="modes of the robot standing on pinned feet, beside the paper's Fig. 6 spectrum")
    md.add_argument("--params", metavar="NAME|FILE",
                    help="robot parameters: a preset (published, paper) or a TOML file; default: paper")
    md.add_argument("--max-hz", default="5000", metavar="HZ", help="highest frequency listed (default 5000)")

    from labkit.commands.simulate_regime import add_regime_map

    add_regime_map(sub, common, pclass)

    sc = sub.add_parser("scenario", parents=[common], help="run a named scenario of the paper (makes a figure)")
    sc.add_argument("name", choices=list(SCENARIO_NAMES),
                    help="; ".join(f"{k}: {v}" for k, v in SCENARIO_NAMES.items()))
    sc.add_argument("--out", default=".", metavar="DIR", help="folder for the figure and data (default .)")
    sc.add_argument("--force", action="store_true", help="replace sim_NAME.h5 / .png already in --out")
    sc.add_argument("--params", metavar="NAME|FILE",
                    help="robot parameters: a preset (published, paper) or a TOML file; default: paper")
    sc.add_argument("--quick", action="store_true", help="few points, short runs (a smoke test, not the result)")
    sc.add_argument("--draws", default=None, metavar="N", help="override the scenario's Monte Carlo draws")
    sc.add_argument("--duration-s", default=None, metavar="S", help="override the scenario's run duration")
    sc.add_argument("--seed", default="0", metavar="N", help="random seed (default 0)")
    sc.add_argument("--scheduler", default=None, metavar="URL", help="Dask scheduler tcp://HOST:PORT")
    sc.add_argument("--workers", default=None, metavar="N", help="local worker processes")


# --------------------------------------------------------------------------- parsing helpers

def number(text: str | None, option: str, *, positive: bool = False, minimum: float | None = None) -> float:
    """A finite float from an option's text, or InputError naming the option."""
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"not a number: {text!r}", key=option, expected="a number") from None
    if not math.isfinite(value):
        raise InputError(f"not a finite number: {text!r}", key=option, expected="a finite number")
    if positive and not value > 0:
        raise InputError(f"must be > 0, got {text}", key=option, expected="a number > 0")
    if minimum is not None and value < minimum:
        raise InputError(f"must be >= {minimum:g}, got {text}", key=option, expected=f"a number >= {minimum:g}")
    return value


def integer(text: str | None, option: str, minimum: int = 0) -> int:
    """An integer >= minimum, or InputError naming the option."""
    try:
        value = int(str(text))
    except ValueError:
        raise InputError(f"not an integer: {text!r}", key=option, expected=f"an integer >= {minimum}") from None
    if value < minimum:
        raise InputError(f"must be >= {minimum}, got {value}", key=option, expected=f"an integer >= {minimum}")
    return value


def is_range(text: str | None) -> bool:
    return text is not None and (":" in text or "," in text)


def parse_range(text: str, option: str) -> list[float]:
    """``start:stop:count`` (evenly spaced, ends included) or ``a,b,c``; all values > 0."""
    import numpy as np

    expected = "start:stop:count (e.g. 150:2000:40) or a comma list, values > 0"
    if "," in text:
        values = [number(t, option, positive=True) for t in text.split(",") if t.strip()]
        if not values:
            raise InputError(f"empty list {text!r}", key=option, expected=expected)
        return values
    parts = text.split(":")
    if len(parts) != 3:
        raise InputError(f"bad range {text!r}", key=option, expected=expected)
    try:
        start, stop = float(parts[0]), float(parts[1])
        count = int(parts[2])
    except ValueError:
        raise InputError(f"bad range {text!r}", key=option, expected=expected) from None
    if not (math.isfinite(start) and math.isfinite(stop)) or start <= 0 or stop <= 0 or count < 1:
        raise InputError(f"bad range {text!r}", key=option, expected=expected)
    if count == 1 and start != stop:
        raise InputError(f"bad range {text!r}: one point needs start == stop", key=option, expected=expected)
    return [float(v) for v in np.linspace(start, stop, count)]


def load_params(path: str | None):
    """The robot parameters: a preset by name, a file's (ConfigError names file and key), or (None) the
    default preset (:data:`labkit.sim.presets.DEFAULT_PRESET`)."""
    from labkit.sim.presets import DEFAULT_PRESET, load

    return load(path or DEFAULT_PRESET)


def _announce(args: argparse.Namespace) -> None:
    """The run's first line names its parameter set (with --json: the summary's ``parameter_set``)."""
    from labkit.sim.presets import DEFAULT_PRESET, describe

    args.params = args.params or DEFAULT_PRESET
    args.parameter_set = describe(args.params, load_params(args.params))
    if not args.json:
        print(args.parameter_set, flush=True)


# --------------------------------------------------------------------------- run

def run(args: argparse.Namespace) -> dict[str, object]:
    _announce(args)
    out: dict[str, object]
    if args.sim_command in ("shaker", "pzt"):
        out = dict(_run_single(args))
    elif args.sim_command == "sweep":
        out = dict(_run_sweep(args))
    elif args.sim_command == "modes":
        out = dict(_run_modes(args))
    elif args.sim_command == "regime-map":
        from labkit.commands.simulate_regime import run_regime_map

        out = dict(run_regime_map(args))
    else:
        out = dict(_run_scenario(args))
    out.setdefault("params", args.params)
    out["parameter_set"] = args.parameter_set
    return out


def _run_modes(args: argparse.Namespace) -> dict[str, object]:
    from labkit.sim.modes import PAPER_FIG6, pinned_modes

    max_hz = number(args.max_hz, "--max-hz", positive=True)
    pm = pinned_modes(load_params(args.params), max_hz=max_hz)
    summary: dict[str, object] = {"params": args.params, **pm.to_dict()}
    if not args.json:
        print(f"modes on pinned feet ({args.params}); legs clamped at "
              + ", ".join(f"{f:.0f}" for f in pm.leg_modes_hz) + " Hz")
        ky, kz = pm.foot_stiffness_n_m
        print(f"  one leg at its foot (body held): {ky:.3g} N/m lateral, {kz:.3g} N/m vertical; the rigid body "
              f"on six: heave {pm.heave_on_springs_hz:.0f} Hz")
        for m in pm.modes:
            print(f"  {m.freq_hz:8.1f} Hz  zeta {m.damping_ratio:.3f}  body {m.body_share:4.2f}  {m.kind}")
        print("  paper Fig. 6 (out-of-chip): " + "; ".join(f"{f:.0f} Hz {w}" for f, w in PAPER_FIG6))
    return summary


def _scenario_from(kind: str, values: dict[str, float]):
    from labkit.sim import PZT, Shaker

    if kind == "shaker":
        return Shaker(freq_hz=values["freq_hz"], amp_um=values["amp_um"])
    return PZT(freq_hz=values["freq_hz"], voltage_v=values["voltage_v"], mass_mg=values.get("mass_mg"))


def _run_single(args: argparse.Namespace) -> dict[str, object]:
    from labkit.sim import simulate
    from labkit.sim.core import ablate

    kind = args.sim_command
    values = {"freq_hz": number(args.freq_hz, "--freq-hz", positive=True)}
    if kind == "shaker":
        values["amp_um"] = number(args.amp_um, "--amp-um", minimum=0.0)
    else:
        values["voltage_v"] = number(args.voltage_v, "--voltage-v", minimum=0.0)
        if args.mass_mg is not None:
            values["mass_mg"] = number(args.mass_mg, "--mass-mg", positive=True)
    duration_s = number(args.duration_s, "--duration-s", positive=True)
    seed = integer(args.seed, "--seed")
    params = ablate(load_params(args.params), args.ablate)
    height = getattr(args, "start_height_um", None)
    height_um = None if height is None else number(height, "--start-height-um", positive=True)
    check_outputs([args.out], force=args.force, suffixes=H5_SUFFIXES)       # before simulating
    scenario = _scenario_from(kind, values)
    from labkit.commands.simulate_regime import add_regime, edge_keys_of
    from labkit.sim.regime import RunTask

    edge_keys = edge_keys_of(args, params, scenario)                        # before simulating
    dt_s = None
    if getattr(args, "dt_s", None) is not None:
        from labkit.sim.core import align_dt

        dt_s = align_dt(number(args.dt_s, "--dt-s", positive=True), scenario)
    with _StepProgress(args.quiet) as bar:
        # a step the user set is the step used: the run is then not checked (its status says "unchecked")
        r = simulate(params, scenario, duration_s=duration_s, seed=seed, start_height_um=height_um, dt_s=dt_s,
                     progress=bar.update, keys=OPTION_KEYS)
    check = None
    if getattr(args, "dt_check", False):
        from labkit.sim.core import dt_check

        check = dt_check(params, scenario, duration_s, seed=seed, start_height_um=height_um)
        if r.validity is not None:
            r.validity.chaotic = bool(check["chaotic"])
    summary: dict[str, object] = {"kind": kind, **values, "duration_s": duration_s, "ablate": args.ablate,
                                  "seed": seed, "start_height_um": height_um}
    for key, value in _result_summary(r).items():
        summary.setdefault(key, value)
    if check is not None:
        summary["dt_check"] = check
    reg, edges = add_regime(summary, r, RunTask(params, scenario, duration_s, seed), args, edge_keys)
    if args.out:
        with atomic_output(args.out) as tmp:
            r.to_h5(tmp)
            _write_regime(tmp, reg, edges)
        summary["out"] = str(args.out)
    if not args.json:
        _print_single(SingleRun(kind, duration_s, r, reg, edges, check, args.out))
    return summary


#: The options that set a run's fields (for the bounds' messages, labkit.sim.core.check_run).
OPTION_KEYS = {"freq_hz": "--freq-hz", "amp_um": "--amp-um", "voltage_v": "--voltage-v", "duration_s": "--duration-s"}


class _StepProgress:
    """A progress bar over a run's steps (on a terminal; a run of several pieces reports its start
    and each piece, labkit.sim.core.run_model)."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar: Any = None

    def __enter__(self) -> _StepProgress:
        return self

    def update(self, done: int, total: int) -> None:
        if self.bar is None:
            if done >= total:
                return          # one piece: done before a bar would be worth showing
            from labkit.progress import progress

            self.bar = progress(total, "simulating", quiet=self.quiet, unit="step")
        self.bar.update(done - self.bar.n)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()


def _result_summary(r: SimResult) -> dict[str, object]:
    """mean speed, contact fractions, patterns and impacts of one SimResult, then its summary."""
    out: dict[str, object] = {"mean_speed_mm_s": float(r.mean_speed_mm_s), "contact_fraction": r.contact_fraction,
                              "patterns": [str(p) for p in r.patterns], "impacts": [int(i) for i in r.impacts]}
    for key, value in r.summary().items():
        out.setdefault(key, value)
    return out


def _fraction(text: str) -> float:
    f = number(text, "--step-fraction", positive=True)
    if f > 1.0:
        raise InputError(f"must be <= 1, got {text}", key="--step-fraction", expected="a fraction 0 < F <= 1")
    return f


def _run_sweep(args: argparse.Namespace) -> dict[str, object]:
    """``labkit simulate sweep``: the sweep's summary (:class:`labkit.sim.sweep.SweepSummary`), the
    ablation and the file written."""
    from labkit.sim import sweep
    from labkit.sim.core import ablate

    kind = args.sweep_kind
    ranged = [(opt, field) for opt, field, _ in SWEEPABLE[kind] if is_range(getattr(args, field))]
    if len(ranged) != 1:
        names = ", ".join(o for o, _, _ in SWEEPABLE[kind])
        raise InputError(f"a sweep needs exactly one range option, got {len(ranged)}",
                         key=ranged[1][0] if len(ranged) > 1 else names, expected=f"one of {names} as start:stop:count")
    opt, quantity = ranged[0]
    values = parse_range(getattr(args, quantity), opt)
    fixed: dict[str, float] = {}
    for o, field, _ in SWEEPABLE[kind]:
        text = getattr(args, field)
        if field == quantity or text is None:
            continue
        fixed[field] = number(text, o, positive=field in ("freq_hz", "mass_mg"), minimum=0.0)
    base = {**fixed, quantity: values[0]}
    if kind == "shaker":
        base.pop("mass_mg", None)
    params = ablate(load_params(args.params), args.ablate)
    if kind == "shaker" and "mass_mg" in fixed:
        from labkit.sim.sweep import apply_value

        params, _ = apply_value(params, _scenario_from(kind, base), "mass_mg", fixed["mass_mg"])
    draws = integer(args.draws, "--draws")
    check_outputs([args.out], force=args.force, suffixes=H5_SUFFIXES)       # before simulating
    workers = None if args.workers is None else integer(args.workers, "--workers", minimum=1)
    accel = getattr(args, "accel_limit_g", None)
    s = sweep(params, _scenario_from(kind, base), quantity=quantity, values=values, draws=draws,
              duration_s=number(args.duration_s, "--duration-s", positive=True), scheduler=args.scheduler,
              workers=workers, seed=integer(args.seed, "--seed"), quiet=args.quiet,
              accel_limit_g=None if accel is None else number(accel, "--accel-limit-g", positive=True),
              dt_check=bool(getattr(args, "dt_check", False)),
              step_fraction=_fraction(args.step_fraction), keys=OPTION_KEYS)
    summary: dict[str, object] = {**s.summary(), "ablate": args.ablate}
    if args.out:
        with atomic_output(args.out) as tmp:
            s.to_h5(tmp)
        summary["out"] = str(args.out)
    if not args.json:
        _print_sweep(s, args.out)
    return summary


def _run_scenario(args: argparse.Namespace) -> dict[str, object]:
    from labkit.sim.scenarios import run_scenario

    params = load_params(args.params)
    key = args.name.replace("_", "-")
    check_output_dir(args.out, force=args.force, names=[f"sim_{key}.h5", f"sim_{key}.png"])
    result = run_scenario(
        args.name, params=params, out_dir=args.out, quick=args.quick,
        draws=None if args.draws is None else integer(args.draws, "--draws"),
        duration_s=None if args.duration_s is None else number(args.duration_s, "--duration-s", positive=True),
        seed=integer(args.seed, "--seed"), scheduler=args.scheduler,
        workers=None if args.workers is None else integer(args.workers, "--workers", minimum=1),
        quiet=args.quiet)
    summary = result.summary()
    summary["params"] = args.params
    if not args.json:
        print(f"{args.name}: {result.finding}")
        for line in result.lines():
            print(f"  {line}")
        for key in ("figure", "data"):
            if key in summary:
                print(f"  {key}: {summary[key]}")
    return summary


# --------------------------------------------------------------------------- text output

def _write_regime(path: Any, reg: Regime, edges: EdgeReport | None) -> None:
    """The run's regime (and edges, when searched) as ``regime_json`` / ``edges_json`` in its file."""
    import h5py

    from labkit.commands.simulate_regime import regime_summary
    from labkit.h5io import put_json

    with h5py.File(path, "a") as f:
        put_json(f, "regime_json", regime_summary(reg))
        if edges is not None:
            put_json(f, "edges_json", edges.to_dict())


@dataclass(frozen=True)
class SingleRun:
    """What ``labkit simulate shaker|pzt`` prints: the run, its regime, edges and dt check, the file written."""

    kind: str
    duration_s: float
    result: SimResult
    regime: Regime
    edges: EdgeReport | None = None
    dt_check: DtCheck | None = None
    out: str | None = None


def _print_single(run: SingleRun) -> None:
    from labkit.sim.result import SMALL_ANGLE_RAD

    r = run.result
    print(f"{run.kind} run, {run.duration_s:g} s: mean speed {r.mean_speed_mm_s:.3f} mm/s")
    print(f"  regime: {run.regime.text()}")
    for line in run.edges.lines() if run.edges is not None else []:
        print(f"  {line}")
    print("  patterns: " + ", ".join(str(p) for p in r.patterns))
    print("  impacts:  " + ", ".join(str(int(i)) for i in r.impacts))
    v = r.validity
    if v is not None:
        print("  validity: " + ("within the model's assumptions" if not v.flags else
                                "LEFT the model's assumptions: " + ", ".join(v.flags))
              + f" (tilt {v.max_tilt_rad:.3g} rad, bound {SMALL_ANGLE_RAD:g}; "
                f"highest body gap {v.max_jump_um:.4g} um)")
    c = r.convergence
    if c is not None and c.status != "unchecked":
        how = ("every foot held, far from letting go" if c.basis == "held" else
               "speeds at h, h/2 ...: " + ", ".join(f"{x:.4g}" for x in c.speeds_mm_s))
        # a run found chaotic after halvings has no error estimate: its starts differ at every step tried
        err = f"{c.error_mm_s:.3g} mm/s" if math.isfinite(c.error_mm_s) else "not estimated"
        print(f"  step: {c.status} at {c.dt_s:.3g} s (default {c.default_dt_s:.3g} s), step error "
              f"{err} (tolerance {c.tolerance_mm_s:.3g}; {how}); "
              f"a start 0.05 um apart: {c.seed_spread_mm_s:+.3g} mm/s")
    if run.dt_check is not None:
        d, q, k = run.dt_check["default"], run.dt_check["quarter"], run.dt_check
        print(f"  dt check ({len(k['seeds'])} seeds): default step {k['dt_s']:.3g} s: {d['mean_mm_s']:.3f} "
              f"+- {d['sem_mm_s']:.3f} mm/s; quarter step: {q['mean_mm_s']:.3f} +- {q['sem_mm_s']:.3f} mm/s; "
              f"difference {k['difference_mm_s']:+.3f} mm/s ({'converged' if k['converged'] else 'NOT converged'}"
              f"{', chaotic: ensemble means compared' if k['chaotic'] else ''})")
    if run.out:
        print(f"  wrote {run.out}")


def _print_sweep(s: SweepResult, out: str | None) -> None:
    from labkit.sim.sweep import units_of

    q = s.quantity
    print(f"sweep of {q} [{units_of(q)}], {s.draws} draw(s) per point")
    points = [s.point_summary(i) for i in range(len(s.values))]
    amp = bool(points) and "amp_um" in points[0]
    print(f"  {q:>12}  mean mm/s   std mm/s  pattern" + ("          amp um" if amp else ""))
    for i, p in enumerate(points):
        flags, steps = s.flag_counts(i), s.convergence_counts(i)
        print(f"  {s.values[i]:12.4g}  {s.mean_speed_mm_s[i]:9.3f}  {s.std_speed_mm_s[i]:9.3f}  "
              f"{s.dominant_pattern(i):<15}" + (f"  {p['amp_um']:7.3g}" if amp else "")
              + (f"  quarter step {p['quarter_step_speed_mm_s']:.3f} mm/s"
                 f" ({'converged' if p['dt_converged'] else 'NOT converged'})" if "dt_converged" in p else "")
              + ("  flags: " + ", ".join(f"{k} x{n}" for k, n in flags.items()) if flags else "")
              + ("  step: " + ", ".join(f"{k} x{n}" for k, n in steps.items()) if steps else ""))
    if out:
        print(f"  wrote {out}")
