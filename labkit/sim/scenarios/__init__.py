"""Named scenarios: the paper's behaviours as runs with a figure, numbers and pass/fail checks.

Modules:

* :mod:`~labkit.sim.scenarios.base` -- the registry (:data:`SCENARIOS`),
  :func:`run_scenario`, :class:`RunOptions` and the typed :class:`ScenarioResult`;
* :mod:`~labkit.sim.scenarios.paper` -- ``paper-fig8``, ``paper-patterns``,
  ``paper-ablations``, ``paper-payload``: the observations of
  :mod:`labkit.sim.paper` on the paper's shaker law, one pass/fail line each;
* :mod:`~labkit.sim.scenarios.classic` -- ``shaker-speed``, ``leg-patterns``,
  ``ablations``, ``pzt-payload``, ``pzt-frequency``, ``adhesion`` (constant
  25 um tray, coarse checks);
* :mod:`~labkit.sim.scenarios.metrics`, :mod:`~labkit.sim.scenarios.plots`,
  :mod:`~labkit.sim.scenarios.io`, :mod:`~labkit.sim.scenarios.runs` -- the
  measures, figures, files and the point runner they share.

Ablations are :func:`labkit.sim.core.ablate` (re-exported here; one function).
"""
from labkit.sim.core import ABLATIONS, ablate
from labkit.sim.scenarios import classic, paper  # noqa: F401  (registers the scenarios)
from labkit.sim.scenarios.base import (
    SCENARIOS,
    RunOptions,
    Scenario,
    ScenarioResult,
    describe,
    run_scenario,
    scenario_names,
)
from labkit.sim.scenarios.metrics import aperiodicity, fig8_checks, foot_rise_um, leg_motion_um, run_info

__all__ = ["SCENARIOS", "Scenario", "ScenarioResult", "RunOptions", "run_scenario", "scenario_names", "describe",
           "ablate", "ABLATIONS", "aperiodicity", "fig8_checks", "foot_rise_um", "leg_motion_um", "run_info"]
