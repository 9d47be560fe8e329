"""The paper's observations against parameter sets; prints ONE JSON object (or the docs' table).

    python bench/paper_table.py [--markdown] [--figures DIR] [--workers N]

Runs the four paper scenarios (``paper-fig8``, ``paper-patterns``, ``paper-ablations``,
``paper-payload``) for the ``published`` set at the quick size, and the ``paper`` set at
the quick size (the calibration's) and with 3 draws x 1 s: the table "Observation ->
paper -> published -> paper" of docs/simulator.md, with its count of observations met.
``--figures DIR`` keeps the ``paper`` set's quick figures (``sim_<scenario>_paper.png``).
"""
from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

from labkit.sim import RobotParams
from labkit.sim.scenarios import run_scenario

SCENARIOS = ("paper-fig8", "paper-patterns", "paper-ablations", "paper-payload")
COLUMNS = (("`published`, quick", "published", dict(quick=True)), ("`paper`, quick", "paper", dict(quick=True)),
           ("`paper`, 3 draws x 1 s", "paper", dict(draws=3, duration_s=1.0)))


def _fmt(v: float | None) -> str:
    if v is None or v != v:
        return "n/a"
    return f"{v:.3g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="store_true", help="print the docs/simulator.md table")
    ap.add_argument("--figures", help="folder for the paper set's quick figures")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    cols: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, preset, kw in COLUMNS:
            t0 = time.perf_counter()
            rows: dict[str, dict] = {}
            for name in SCENARIOS:
                out = Path(tmp) / f"{preset}_{len(cols)}_{name}"
                r = run_scenario(name, RobotParams.preset(preset), out, workers=args.workers, quiet=True, **kw)
                for o in r.observations:
                    rows[o.id] = {"value": o.value, "passed": bool(o.passed), "band": o.band, "source": o.source,
                                 "metric": o.metric}
                if args.figures and preset == "paper" and kw.get("quick") and r.figure:
                    Path(args.figures).mkdir(parents=True, exist_ok=True)
                    shutil.copy(r.figure, Path(args.figures) / f"sim_{name}_paper.png")
            cols[label] = {"observations": rows, "met": sum(v["passed"] for v in rows.values()), "of": len(rows),
                           "wall_s": round(time.perf_counter() - t0, 1)}
    if not args.markdown:
        print(json.dumps(cols))
        return
    ids = list(cols[COLUMNS[0][0]]["observations"])
    print("| observation | source | paper (pass band) | " + " | ".join(c[0] for c in COLUMNS) + " |")
    print("|---|---|---|" + "---|" * len(COLUMNS))
    for i in ids:
        first = cols[COLUMNS[0][0]]["observations"][i]
        band = first["band"].replace(first["metric"], "x")
        cells = []
        for label, _, _ in COLUMNS:
            o = cols[label]["observations"][i]
            cells.append(f"{_fmt(o['value'])} " + ("**pass**" if o["passed"] else "fail"))
        print(f"| `{i}` | {first['source']} | {band} | " + " | ".join(cells) + " |")
    print()
    print("| | " + " | ".join(c[0] for c in COLUMNS) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    print("| observations met | " + " | ".join(f"{cols[c[0]]['met']} / {cols[c[0]]['of']}" for c in COLUMNS) + " |")


if __name__ == "__main__":
    main()
