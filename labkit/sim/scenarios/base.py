"""The scenario registry, its options and its typed result."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypedDict

from labkit.errors import InputError
from labkit.sim.paper.observations import ObservationCheck
from labkit.sim.params import RobotParams
from labkit.sim.scenarios.plots import Plot, save_figure

#: Run sizes: ``quick`` few points and short runs (for the paper scenarios: the
#: calibration's size), ``full`` the scenario's documented size.
SIZES = ("quick", "full")


class ExecutorKw(TypedDict):
    """Where a scenario's runs go: keywords of :func:`labkit.sim.sweep` and :func:`run_points`."""

    scheduler: str | None
    workers: int | None
    seed: int
    quiet: bool


@dataclass(frozen=True)
class RunOptions:
    """How big and where a scenario runs."""

    size: str = "full"
    draws: int | None = None
    duration_s: float | None = None
    seed: int = 0
    scheduler: str | None = None
    workers: int | None = None
    quiet: bool = False
    #: The tray amplitude law of the shaker scenarios (``ShakerLaw`` or ``TableLaw``); None: the paper's.
    tray_law: Any = None

    @property
    def quick(self) -> bool:
        return self.size == "quick"

    def executor_kw(self) -> ExecutorKw:
        """``scheduler``, ``workers``, ``seed``, ``quiet`` as keywords of :func:`labkit.sim.sweep`."""
        return {"scheduler": self.scheduler, "workers": self.workers, "seed": self.seed, "quiet": self.quiet}

    def pick(self, full: Any, small: Any, override: Any = None) -> Any:
        """The scenario's value for this size; an override wins (capped at ``small`` for quick counts)."""
        if override is not None:
            return override if not self.quick or not isinstance(override, int) else min(override, small)
        return small if self.quick else full


@dataclass
class Outcome:
    """What a scenario function returns: its numbers, checks, figure and data writers."""

    finding: str
    checks: dict[str, bool]
    numbers: dict[str, object]
    observations: list[ObservationCheck] = field(default_factory=list)
    plot: Plot | None = None
    write_data: Callable[[Path], Any] | None = None
    figure_size_in: tuple[float, float] = (7.0, 4.6)


@dataclass
class ScenarioResult:
    """The result of :func:`run_scenario`.

    ``checks``: the scenario's pass/fail tests by name; ``observations``: one
    :class:`~labkit.sim.paper.observations.ObservationCheck` per paper
    observation the scenario measures (paper scenarios); ``numbers``: the
    scenario's measured values (JSON-able); ``figure``/``data``: the files
    written (None when nothing was written).
    """

    name: str
    title: str
    expectation: str
    size: str
    finding: str
    checks: dict[str, bool]
    numbers: dict[str, object]
    observations: list[ObservationCheck] = field(default_factory=list)
    figure: str | None = None
    data: str | None = None

    @property
    def quick(self) -> bool:
        return self.size == "quick"

    @property
    def passed(self) -> list[str]:
        return [c.id for c in self.observations if c.passed]

    @property
    def failed(self) -> list[str]:
        """Observations not met (in their regime and outside their band)."""
        return [c.id for c in self.observations if c.applicable and not c.passed]

    @property
    def not_applicable(self) -> list[str]:
        """Observations whose regime the run is not in (neither met nor failed)."""
        return [c.id for c in self.observations if not c.applicable]

    def lines(self) -> list[str]:
        """The pass/fail line of every observation."""
        return [c.line() for c in self.observations]

    def summary(self) -> dict[str, object]:
        """A JSON-able dict: name, title, expectation, size, finding, checks, the numbers, observations, files."""
        out: dict[str, object] = {"name": self.name, "title": self.title, "expectation": self.expectation,
                                "quick": self.quick, "size": self.size, "finding": self.finding,
                                "checks": dict(self.checks)}
        for k, v in self.numbers.items():
            out.setdefault(k, v)
        if self.observations:
            out["observations"] = [c.to_dict() for c in self.observations]
            out["observation_states"] = {"met": len(self.passed), "not met": len(self.failed),
                                         "not applicable": len(self.not_applicable)}
        for k in ("figure", "data"):
            v = getattr(self, k)
            if v is not None:
                out[k] = v
        return out


ScenarioFn = Callable[[RobotParams, RunOptions], Outcome]


@dataclass(frozen=True)
class Scenario:
    """A named scenario: its title, the paper's expectation, and the function that runs it."""

    name: str
    title: str
    expectation: str
    fn: ScenarioFn


SCENARIOS: dict[str, Scenario] = {}


def register(name: str, title: str, expectation: str) -> Callable[[ScenarioFn], ScenarioFn]:
    """Decorator: add a scenario function to :data:`SCENARIOS` under ``name``."""
    def deco(fn: ScenarioFn) -> ScenarioFn:
        SCENARIOS[name] = Scenario(name, title, expectation, fn)
        return fn
    return deco


def run_scenario(name: str, params: RobotParams | None = None, out_dir: str | Path | None = ".", *,
                 quick: bool = False, size: str | None = None, draws: int | None = None,
                 duration_s: float | None = None, seed: int = 0, scheduler: str | None = None,
                 workers: int | None = None, quiet: bool = False, figure: bool = True,
                 tray_law: Any = None) -> ScenarioResult:
    """Run the named scenario; write ``sim_<name>.png`` and ``sim_<name>.h5`` in ``out_dir``.

    Parameters
    ----------
    name:
        One of :data:`SCENARIOS` (``_`` and ``-`` are the same).
    params:
        The robot (default ``RobotParams()``, the published set).
    out_dir:
        Folder for the figure and the data (created); ``None`` writes nothing.
    quick, size:
        ``quick=True`` is ``size="quick"`` (few points, short runs; for the
        paper scenarios the size the calibration uses); default ``"full"``.
    draws, duration_s:
        Override the scenario's Monte Carlo draws and run duration.
    seed, scheduler, workers, quiet:
        As for :func:`labkit.sim.sweep`.
    figure:
        Make the figure (needs ``out_dir``).
    tray_law:
        The paper scenarios' tray amplitude law: a :class:`labkit.sim.paper.shaker.TableLaw`
        (``load_tray_law(file)``) or ``ShakerLaw``; default the paper's shaker law. The result
        records which (``numbers["tray_law"]``).
    """
    from labkit.outputs import atomic_output

    key = name.replace("_", "-")
    if key not in SCENARIOS:
        raise InputError(f"unknown scenario {name!r}", key="scenario", expected=", ".join(SCENARIOS))
    size = size or ("quick" if quick else "full")
    if size not in SIZES:
        raise InputError(f"unknown size {size!r}", key="size", expected=", ".join(SIZES))
    sc = SCENARIOS[key]
    params = RobotParams() if params is None else params
    opts = RunOptions(size=size, draws=draws, duration_s=duration_s, seed=seed, scheduler=scheduler,
                      workers=workers, quiet=quiet, tray_law=tray_law)
    o = sc.fn(params, opts)
    result = ScenarioResult(name=key, title=sc.title, expectation=sc.expectation, size=size, finding=o.finding,
                            checks=o.checks, numbers=o.numbers, observations=o.observations)
    if out_dir is None:
        return result
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if o.write_data is not None:
        with atomic_output(out / f"sim_{key}.h5") as tmp:     # an old file survives a failed write
            o.write_data(tmp)
        result = replace(result, data=str(out / f"sim_{key}.h5"))
    if figure and o.plot is not None:
        plot = o.plot
        with atomic_output(out / f"sim_{key}.png") as tmp:
            save_figure(plot, tmp, o.figure_size_in)
        result = replace(result, figure=str(out / f"sim_{key}.png"))
    return result


def scenario_names() -> list[str]:
    """The registered scenario names."""
    return list(SCENARIOS)


def describe() -> str:
    """One line per scenario (for help texts and docs)."""
    return "\n".join(f"{k}: {v.title}" for k, v in SCENARIOS.items())
