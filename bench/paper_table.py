"""The paper's observations over the Monte Carlo ensemble; prints ONE JSON object (or the docs' table).

    nice -n 5 python bench/paper_table.py [--params paper] [--draws 6] [--duration-s 2] [--seeds 0,1,2]
        [--size quick] [--scenarios paper-fig8,...] [--workers N] [--markdown | --members] [--save-runs FILE]
        [--load-runs FILE]

Scores every observation of labkit/sim/paper/observations.toml with
:func:`labkit.sim.paper.ensemble.score_ensemble`: the nominal robot of the set and
``draws`` robots drawn from the Monte Carlo table for each seed (default 6 x 2 s x
seeds 0, 1, 2, the scenarios' quick point grids; ``--scenarios`` runs only some scenarios and
scores only their observations), one executor call per seed.
Per observation: the paper's value and band, the nominal robot's value and state, the
pooled ensemble's value and state (the verdict: met / not met / not applicable), the
robots' mean +- sd, median and share met, each seed's state. ``--markdown`` prints the
table of docs/simulator.md with the command that made it; ``cpu_s`` is the
simulations' CPU time; ``--members`` adds every metric of each drawn robot to the JSON.
``--save-runs`` keeps the raw runs (a pickle, for this machine only) so ``--load-runs`` can
re-score them without simulating.
"""
from __future__ import annotations

import argparse
import json
import pickle
import shlex
import sys
from dataclasses import replace

from labkit.sim.paper.ensemble import (
    EnsembleScore,
    EnsembleSpec,
    ObservationScore,
    merge_runs,
    run_ensemble,
    score_runs,
)


def _fmt(v: float | None) -> str:
    return "n/a" if v is None or v != v else f"{v:.3g}"


def _state(state: str, bold: bool = False) -> str:
    word = {"met": "met", "not met": "not met", "not applicable": "n/a"}[state]
    return f"**{word}**" if bold and state == "met" else word


def _row(s: ObservationScore) -> str:
    paper = s.band.replace(s.metric, "x") + (f" (paper {s.paper_value:g})" if s.paper_value is not None else "")
    robots = "n/a" if s.mean is None else (
        f"{_fmt(s.mean)} ± {_fmt(s.spread)} (median {_fmt(s.median)}, n {s.robots}"
        + (f", {100 * s.met_share:.0f} % met)" if s.met_share is not None else ", all n/a)"))
    seeds = " / ".join(_state(st) for st in s.per_seed_states)
    return (f"| `{s.id}` | {s.source} | {paper} | {_fmt(s.nominal)} {_state(s.nominal_state)} | "
            f"{_fmt(s.ensemble)} | {robots} | {_state(s.state, True)} | {seeds} |")


def markdown(e: EnsembleScore, command: str) -> str:
    """The docs/simulator.md table of an ensemble score, with its command and totals."""
    st = e.settings
    lines = [f"Made by `{command}` ({st.robots} drawn robots: {st.draws} per seed x seeds "
             f"{', '.join(map(str, st.seeds))}, {st.duration_s:g} s runs, {st.size} point grids; "
             f"{e.runs} runs, {e.cpu_s:.0f} CPU s, {e.wall_s:.0f} s wall).", "",
             "| observation | source | paper (pass band) | nominal robot | ensemble (pooled) | "
             "robots: mean ± sd | ensemble verdict | per seed |", "|---|---|---|---|---|---|---|---|"]
    lines += [_row(s) for s in e.scores]
    ens, nom = e.count("ensemble"), e.count("nominal")
    lines += ["", "| | met | not met | not applicable |", "|---|---|---|---|",
              f"| ensemble (pooled) | {ens['met']} | {ens['not met']} | {ens['not applicable']} |",
              f"| nominal robot | {nom['met']} | {nom['not met']} | {nom['not applicable']} |",
              f"| per seed ({', '.join(map(str, st.seeds))}) | {' / '.join(map(str, e.seed_counts()))} | | |"]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="paper", help="a preset or a TOML file (default: paper)")
    ap.add_argument("--draws", type=int, default=6)
    ap.add_argument("--duration-s", type=float, default=2.0)
    ap.add_argument("--seeds", default="0,1,2", help="comma-separated seeds")
    ap.add_argument("--size", default="quick", choices=("quick", "full"))
    ap.add_argument("--scenarios", help="comma-separated paper scenarios (default all): only their observations")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--markdown", action="store_true", help="print the docs/simulator.md table")
    ap.add_argument("--members", action="store_true",
                    help="with the JSON: every metric of each drawn robot, per scenario (seed-major, draws 1..N)")
    ap.add_argument("--save-runs", help="keep the raw runs in this file (pickle; one file per seed: FILE.seedN)")
    ap.add_argument("--load-runs", nargs="+", help="re-score (and merge) runs saved with --save-runs (no simulation)")
    args = ap.parse_args()
    argv = sys.argv[1:]
    keep = [a for i, a in enumerate(argv) if not a.startswith("--save-runs")
            and not (i and argv[i - 1] == "--save-runs")]
    command = "python bench/paper_table.py " + " ".join(shlex.quote(a) for a in keep)
    if args.load_runs:
        parts = []
        for name in args.load_runs:
            with open(name, "rb") as fh:
                parts.append(pickle.load(fh))
        runs = merge_runs(parts)
    else:
        from labkit.sim.presets import load

        params = load(args.params)
        scenarios = [n.strip() for n in args.scenarios.split(",") if n.strip()] if args.scenarios else None
        parts = []
        for seed in [int(s) for s in args.seeds.split(",") if s.strip()]:
            # one executor call per seed, saved as it ends: a long ensemble on a shared machine
            # keeps the seeds it finished
            part = run_ensemble(params, EnsembleSpec(draws=args.draws, duration_s=args.duration_s, seeds=[seed],
                                                     size=args.size, scenarios=scenarios), workers=args.workers)
            part = replace(part, settings=replace(part.settings, params=args.params))
            if args.save_runs:
                with open(f"{args.save_runs}.seed{seed}", "wb") as fh:
                    pickle.dump(part, fh)
            parts.append(part)
        runs = merge_runs(parts)
    e = score_runs(runs)
    if args.markdown:
        print(markdown(e, command))
    else:
        members = {"members": e.member_metrics} if args.members else {}
        print(json.dumps({"command": command, **e.to_dict(), **members}))


if __name__ == "__main__":
    from labkit.errors import InputError

    try:
        main()
    except InputError as e:
        print(f"paper_table: {e}", file=sys.stderr)
        sys.exit(2)
