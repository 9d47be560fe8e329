"""The gait regime of each simulated run and its distance to the nearest edge, for the report.

The regime is recomputed from the run's stored summary by :func:`labkit.sim.regime.classify_regime`
(the classifier the simulator's commands use); the edges are read from the file when it was written
by ``labkit simulate shaker|pzt --edges --out RUN.h5`` (the search takes many runs: the report does
not repeat it).
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from labkit.analysis.report.inputs import SimRunData

#: Lines shown per run: the seeds' spread, then the edges nearest first.
MAX_EDGE_LINES = 5


def regime_rows(results: list[SimRunData]) -> tuple[list[list[Any]], list[str]]:
    """Table rows (file, drive, regime, speed, flags, nearest edges) and the files without edges."""
    from labkit.sim.regime import RunFeatures, body_motion_um, classify_regime

    rows, no_edges = [], []
    for s in results:
        summary = s.summary
        if not isinstance(summary, dict) or "patterns" not in summary:
            continue
        motion = body_motion_um(s.t_s, s.body_z_um, s.ground_z_um) if s.body_z_um is not None else None
        reg = classify_regime(RunFeatures.from_summary(summary, motion))
        sc = s.scenario
        drive = ", ".join(f"{sc[k]:.4g} {u}" for k, u in (("freq_hz", "Hz"), ("amp_um", "um"), ("voltage_v", "V"))
                          if k in sc)
        edges = s.edges
        if isinstance(edges, dict):
            lines = edges.get("lines", [])
            near = "; ".join(lines[:MAX_EDGE_LINES]) or "none found"
        else:
            near = "not searched"
            no_edges.append(Path(s.file).name)
        rows.append([Path(s.file).name, drive, reg.regime, f"{reg.speed_mm_s:.3g}", ", ".join(reg.flags), near])
    return rows, no_edges


def regime_html(results: list[SimRunData], msgs: list[str]) -> list[str]:
    """The regime table of the simulated runs (empty without any); a note in ``msgs`` for runs whose
    edges were not searched."""
    from labkit.analysis.report import html as rh

    rows, no_edges = regime_rows(results)
    if not rows:
        return []
    if no_edges:
        msgs.append(f"Edges not searched for {', '.join(no_edges)} (write the run with labkit simulate "
                    "shaker|pzt ... --edges --out RUN.h5).")
    return ["<p>Gait regime of each simulated run (still / firm / partial / jumping, "
            "labkit.sim.regime.classify_regime) and the smallest change of a parameter that changes it "
            "or moves the speed by more than 30 %:</p>",
            rh.table(["file", "drive", "regime", "speed (mm/s)", "flags", "nearest edges"], rows, num_cols={3})]
