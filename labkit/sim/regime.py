"""Gait regimes of whole runs, regime maps over the drive, and the distance to a regime's edge.

One classifier (:func:`classify_regime`) labels a run ``still``, ``firm``, ``partial`` or
``jumping`` from its per-foot patterns (:func:`labkit.sim.result.classify_pattern`, the paper's
Sec. 5.2 definitions made operational) and its speed; ``aperiodic`` and ``chaotic`` are flags
beside the label. :func:`regime_map` runs it over a frequency x amplitude grid (shaker) or
frequency x voltage grid (PZT) through :func:`labkit.executor.map_tasks`; :func:`find_edges`
searches, for each uncertain parameter, the smallest relative change that changes the regime
or moves the speed by more than :data:`SPEED_CHANGE_REL`. Thresholds and their reasons:
docs/simulator.md, "Regimes and their edges".
"""
from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from labkit.errors import ConfigError, InputError
from labkit.jsonutil import Json
from labkit.sim.result import FLIGHT_MIN_UM

if TYPE_CHECKING:
    from labkit.sim.excitation import PZT, Shaker
    from labkit.sim.params import RobotParams
    from labkit.sim.result import SimResult

#: The run's regimes, from the least to the most lifted.
REGIMES = ("still", "firm", "partial", "jumping")
#: Per-foot pattern -> the robot's regime it stands for.
_OF_PATTERN = {"firm_contact": "firm", "partial_contact": "partial", "jumping": "jumping"}
#: A robot whose feet all stay in firm contact is ``still`` below this |speed| (mm/s): the
#: level :func:`labkit.sim.scenarios.metrics.fig8_checks` calls "no motion" (Fig. 8 above 500 Hz) ...
STILL_SPEED_MM_S = 0.1
#: ... and when its body moves less than this relative to the tray (peak to peak over the last half
#: of the run, um): the resolution at which a foot "follows the tray" (result.FLIGHT_MIN_UM).
STILL_MOTION_UM = FLIGHT_MIN_UM
#: The robot's regime is the most lifted foot pattern at least this many of the six feet reach
#: (the upper median foot): one foot that lets go does not make a partial-contact robot.
MIN_FEET = 3
#: A perturbed run is "across an edge" when its regime differs or its speed moved by more than
#: this fraction of the base run's speed ...
SPEED_CHANGE_REL = 0.30
#: ... and by more than this (mm/s), so that a robot at rest is not on an edge by round-off.
SPEED_CHANGE_ABS_MM_S = STILL_SPEED_MM_S
#: Relative changes tried outward, in order, before a bisection narrows the bracket.
EDGE_STEPS = (0.02, 0.05, 0.10, 0.20)
#: Bisection rounds inside the first bracket that crosses an edge.
EDGE_BISECTIONS = 2
#: Other seeds the base run is repeated with, to tell an edge from the run's own spread.
SEED_CHECKS = 2
#: The drive's own edge key: the tray amplitude (shaker) or the PZT voltage.
DRIVE_KEY = "drive"
#: Short names for the edge lines.
LABELS = {"c_ad_n": "adhesion", "c_ad_t_n_s": "adhesion rate", "c_r": "restitution (feet)",
          "c_r_body": "restitution (body)", "b_g_body_n_m2_s": "body film", "b_g_foot_n_m2_s": "foot film",
          "a_drag_n_s2_m2": "air drag", "body_mass_mg": "body mass", "leg_mass_mg": "leg mass",
          "foot_pad_um": "foot pad", "film_gap_nm": "film gap", "k_per_s2": "leg stiffness",
          "b_per_s": "leg damping", "modal_participation": "participation"}


# --------------------------------------------------------------------------- one run

@dataclass(frozen=True)
class RunFeatures:
    """What the classifier reads of a run (small and picklable: what a map's task returns).

    ``patterns``: the six per-foot labels of :func:`labkit.sim.result.classify_pattern`;
    ``body_motion_um``: the body's motion relative to the tray, peak to peak over the last half of
    the run (:func:`body_motion_um`; ``None``: not known, the robot then counts as moving);
    ``foot_periods``: 1 or 2 when a foot's motion repeats after that many drive periods, 0 when
    not (``None``: not known); ``chaotic``: :class:`labkit.sim.result.Validity`'s probe (``None``:
    not probed); ``flags``: the run's validity flags.
    """

    speed_mm_s: float
    patterns: tuple[str, ...]
    body_motion_um: float | None = None
    foot_periods: tuple[int, ...] | None = None
    max_height_um: tuple[float, ...] | None = None
    chaotic: bool | None = None
    flags: tuple[str, ...] = ()

    @classmethod
    def of(cls, r: SimResult) -> RunFeatures:
        """The features of a :class:`~labkit.sim.result.SimResult`."""
        v = r.validity
        return cls(speed_mm_s=float(r.mean_speed_mm_s), patterns=tuple(str(p) for p in r.patterns),
                   body_motion_um=body_motion_um(r.t_s, r.body_z_um, r.ground_z_um),
                   foot_periods=None if r.foot_periods is None else tuple(int(k) for k in r.foot_periods),
                   max_height_um=None if r.max_height_um is None else tuple(float(h) for h in r.max_height_um),
                   chaotic=None if v is None else v.chaotic, flags=() if v is None else tuple(v.flags))

    @classmethod
    def from_summary(cls, s: Mapping[str, Json], body_motion: float | None = None) -> RunFeatures:
        """The features of a run's summary as JSON (a sim_result file's ``summary``, the
        :meth:`~labkit.sim.result.SimResult.summary` of a run) and its body motion (:func:`body_motion_um`)."""
        v = s.get("validity")
        v = v if isinstance(v, dict) else {}
        periods, heights, chaotic = s.get("foot_periods"), s.get("max_height_um"), v.get("chaotic")
        return cls(speed_mm_s=_num(s.get("mean_speed_mm_s")),
                   patterns=tuple(str(p) for p in _seq(s.get("patterns"))),
                   body_motion_um=None if body_motion is None else float(body_motion),
                   foot_periods=None if periods is None else tuple(int(_num(k)) for k in _seq(periods)),
                   max_height_um=None if heights is None else tuple(_num(h) for h in _seq(heights)),
                   chaotic=chaotic if isinstance(chaotic, bool) else None,
                   flags=tuple(str(f) for f in _seq(v.get("flags"))))


def _num(value: Json) -> float:
    """A JSON number as a float (NaN for anything else: ``null`` is how JSON writes NaN)."""
    return float(value) if isinstance(value, (int, float)) else float("nan")


def _seq(value: Json) -> list[Json]:
    """A JSON array (``[]`` for anything else)."""
    return value if isinstance(value, list) else []


def body_motion_um(t_s: np.ndarray, body_z_um: np.ndarray, ground_z_um: np.ndarray) -> float:
    """Peak-to-peak motion of the body's underside relative to the tray over the last half of a run, um."""
    t = np.asarray(t_s, float)
    late = t >= t[0] + 0.5 * (t[-1] - t[0])
    rel = np.asarray(body_z_um, float)[late] - np.asarray(ground_z_um, float)[late]
    return float(np.ptp(rel)) if rel.size else 0.0


class RegimeDict(TypedDict):
    """:meth:`Regime.to_dict` (``labkit simulate shaker --json``'s ``regime``, a run file's ``regime_json``)."""

    regime: str
    speed_mm_s: float
    feet: dict[str, int]
    body_motion_um: float | None
    aperiodic: bool
    chaotic: bool | None
    flags: list[str]


@dataclass(frozen=True)
class Regime:
    """A run's gait regime (:data:`REGIMES`) and the flags beside it.

    ``feet``: how many feet showed each pattern; ``aperiodic``: most feet that leave the tray do not
    repeat after 1 or 2 drive periods; ``chaotic``: from the run's chaos probe (``None``: not probed).
    """

    regime: str
    speed_mm_s: float
    feet: dict[str, int]
    aperiodic: bool
    chaotic: bool | None
    body_motion_um: float | None = None

    @property
    def flags(self) -> list[str]:
        return [name for name, on in (("aperiodic", self.aperiodic), ("chaotic", self.chaotic)) if on]

    def text(self) -> str:
        feet = ", ".join(f"{n} {p}" for p, n in self.feet.items() if n)
        extra = f" [{', '.join(self.flags)}]" if self.flags else ""
        return f"{self.regime} ({feet}; {self.speed_mm_s:.3g} mm/s){extra}"

    def to_dict(self) -> RegimeDict:
        return {"regime": self.regime, "speed_mm_s": float(self.speed_mm_s), "feet": dict(self.feet),
                "body_motion_um": self.body_motion_um,
                "aperiodic": bool(self.aperiodic), "chaotic": self.chaotic, "flags": self.flags}


def classify_regime(x: RunFeatures | SimResult) -> Regime:
    """The gait regime of a run: the most lifted foot pattern at least :data:`MIN_FEET` feet reach;
    a robot whose feet stay in firm contact is ``still`` when it neither progresses (|speed| <
    :data:`STILL_SPEED_MM_S`) nor moves on its legs (body motion relative to the tray below
    :data:`STILL_MOTION_UM`), else ``firm``."""
    f = x if isinstance(x, RunFeatures) else RunFeatures.of(x)
    feet = {p: sum(q == p for q in f.patterns) for p in _OF_PATTERN}
    regime = "firm"
    if feet["jumping"] >= MIN_FEET:
        regime = "jumping"
    elif feet["jumping"] + feet["partial_contact"] >= MIN_FEET:
        regime = "partial"
    elif abs(f.speed_mm_s) < STILL_SPEED_MM_S and f.body_motion_um is not None \
            and f.body_motion_um < STILL_MOTION_UM:
        regime = "still"
    lifted = [j for j, p in enumerate(f.patterns) if p != "firm_contact"]
    aperiodic = bool(f.foot_periods is not None and lifted
                     and 2 * sum(f.foot_periods[j] == 0 for j in lifted) > len(lifted))
    chaotic = f.chaotic if f.chaotic is not None else ("chaotic" in f.flags or None)
    return Regime(regime, float(f.speed_mm_s), feet, aperiodic, chaotic, f.body_motion_um)


def changed(base: Regime, other: Regime) -> bool:
    """Is ``other`` across an edge from ``base``: another regime, or the speed moved by more than
    :data:`SPEED_CHANGE_REL` of the base speed and :data:`SPEED_CHANGE_ABS_MM_S`?"""
    dv = abs(other.speed_mm_s - base.speed_mm_s)
    return other.regime != base.regime or dv > max(SPEED_CHANGE_REL * abs(base.speed_mm_s), SPEED_CHANGE_ABS_MM_S)


@dataclass(frozen=True)
class RunTask:
    """One simulation a map or an edge search asks for (picklable)."""

    params: RobotParams
    scenario: Shaker | PZT
    duration_s: float
    seed: int


@dataclass(frozen=True)
class Runs:
    """How every run of a map or an edge search is made, and where the runs go.

    ``scheduler``, ``workers`` and ``quiet`` are passed to :func:`labkit.executor.map_tasks`
    (local processes, ``"serial"`` or Dask); ``bound_keys`` names the fields in the bounds'
    messages (:func:`labkit.sim.core.check_run`).
    """

    duration_s: float = 0.5
    seed: int = 0
    scheduler: str | None = None
    workers: int | None = None
    quiet: bool = True
    bound_keys: dict[str, str] | None = None

    def task(self, params: RobotParams, scenario: Shaker | PZT, seed_offset: int = 0) -> RunTask:
        return RunTask(params, scenario, float(self.duration_s), int(self.seed) + seed_offset)

    def check(self, params: RobotParams, scenario: Shaker | PZT) -> None:
        """Refuse a run the simulator would refuse (InputError naming the bound), before any starts."""
        from labkit.sim.core import check_run

        check_run(params, scenario, self.duration_s, keys=self.bound_keys)

    def run_all(self, tasks: list[RunTask], desc: str) -> list[Regime]:
        from labkit.executor import map_tasks

        feats = map_tasks(run_features, tasks, scheduler=self.scheduler, workers=self.workers, desc=desc,
                          quiet=self.quiet)
        return [classify_regime(f) for f in feats]


@dataclass(frozen=True)
class Grid:
    """A regime map's grid: ``kind`` ``"shaker"`` (level = tray amplitude, um) or ``"pzt"`` (level =
    square-wave voltage, V; ``mass_mg`` the robot's total mass with payload, ``None``: its own)."""

    kind: str
    freq_hz: Sequence[float]
    level: Sequence[float]
    mass_mg: float | None = None


@dataclass(frozen=True)
class EdgeSearch:
    """What an edge search perturbs and how finely (see :func:`find_edges`)."""

    keys: Sequence[str] | None = None
    steps: Sequence[float] = EDGE_STEPS
    bisections: int = EDGE_BISECTIONS
    seed_checks: int = SEED_CHECKS


def run_features(task: RunTask) -> RunFeatures:
    """Simulate one task and keep its features (module level: the executor pickles it by reference)."""
    from labkit.sim import simulate

    return RunFeatures.of(simulate(task.params, task.scenario, duration_s=task.duration_s, seed=task.seed))




# --------------------------------------------------------------------------- regime map

@dataclass
class RegimeMap:
    """Regimes over a drive grid: ``regimes[i, j]`` at ``freq_hz[i]`` and ``level[j]``.

    ``level_name`` is ``amp_um`` (shaker) or ``voltage_v`` (PZT); ``speeds_mm_s`` the runs'
    speeds; ``flags`` the regime flags per point, comma-joined ("" for none); ``meta`` the
    duration, seed, parameter source and thresholds.
    """

    kind: str
    level_name: str
    freq_hz: np.ndarray
    level: np.ndarray
    regimes: np.ndarray
    speeds_mm_s: np.ndarray
    flags: np.ndarray
    params_toml: str = ""
    meta: dict[str, Json] = field(default_factory=dict)

    def counts(self) -> dict[str, int]:
        """How many points fell in each regime."""
        return {r: int(np.count_nonzero(self.regimes == r)) for r in REGIMES}

    def summary(self) -> dict[str, Json]:
        """JSON-able: the grid (the level under its name, ``amp_um`` or ``voltage_v``), regimes, speeds,
        flags, counts and meta."""
        return {"kind": self.kind, "freq_hz": [float(f) for f in self.freq_hz],
                self.level_name: [float(v) for v in self.level], "regimes": self.regimes.tolist(),
                "speeds_mm_s": self.speeds_mm_s.tolist(), "flags": self.flags.tolist(),
                "counts": dict(self.counts()), "meta": self.meta}

    def to_h5(self, path: str | Path) -> Path:
        """Write kind ``sim_regime_map``: the grid, regimes, speeds and flags with their units."""
        import h5py

        from labkit.h5io import put, put_json, stamp
        from labkit.sim.sweep import units_of

        path = Path(path)
        with h5py.File(path, "w") as f:
            stamp(f, "sim_regime_map")
            f.attrs["params_toml"] = self.params_toml
            f.attrs["kind_of_drive"] = self.kind
            put_json(f, "meta_json", self.meta)
            put(f, "freq_hz", self.freq_hz, "Hz")
            put(f, self.level_name, self.level, units_of(self.level_name))
            put(f, "regime", self.regimes.astype("S8"), "label", axes=f"freq_hz, {self.level_name}",
                labels=",".join(REGIMES))
            put(f, "speed_mm_s", self.speeds_mm_s, "mm/s", axes=f"freq_hz, {self.level_name}")
            put(f, "flags", self.flags.astype("S32"), "label", axes=f"freq_hz, {self.level_name}")
        return path

    def to_csv(self, path: str | Path) -> Path:
        """One row per grid point: freq_hz, level, regime, speed_mm_s, flags."""
        path = Path(path)
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["freq_hz", self.level_name, "regime", "speed_mm_s", "flags"])
            for i, f in enumerate(self.freq_hz):
                for j, v in enumerate(self.level):
                    w.writerow([f"{f:g}", f"{v:g}", self.regimes[i, j], f"{self.speeds_mm_s[i, j]:.6g}",
                                self.flags[i, j]])
        return path

    def to_figure(self, path: str | Path) -> Path:
        """The map as an image (PNG or SVG by suffix): one colour per regime, the speed written in
        each cell, and for a shaker the rigid robot's lift-off line (2 pi f)^2 A = g."""
        from labkit.sim.scenarios.plots import save_figure

        return save_figure(self._draw, Path(path))

    def _draw(self, fig: Any) -> None:
        from matplotlib.colors import ListedColormap
        from matplotlib.patches import Patch

        ax = fig.add_subplot(1, 1, 1)
        code = np.vectorize(REGIMES.index)(self.regimes) if self.regimes.size else self.regimes
        colours = ListedColormap(["0.85", "#4c72b0", "#dd8452", "#c44e52"])
        xi, yi = np.arange(len(self.freq_hz)), np.arange(len(self.level))
        ax.pcolormesh(xi, yi, code.T, cmap=colours, vmin=-0.5, vmax=3.5, shading="nearest")
        for i in xi:
            for j in yi:
                v = float(self.speeds_mm_s[i, j])
                ax.text(i, j, "0" if abs(v) < 0.005 else f"{v:.2g}", ha="center", va="center", fontsize=7)
        ax.set_xticks(xi, [f"{f:g}" for f in self.freq_hz], rotation=90 if len(xi) > 10 else 0)
        ax.set_yticks(yi, [f"{v:g}" for v in self.level])
        ax.set_xlabel("drive frequency (Hz)")
        ax.set_ylabel("tray amplitude (um)" if self.kind == "shaker" else "PZT voltage (V)")
        if self.kind == "shaker" and len(yi) > 1:
            g = _num(self.meta.get("g_m_s2", 9.81))
            lift = g / (2 * np.pi * self.freq_hz) ** 2 * 1e6
            ax.plot(xi, np.interp(lift, self.level, yi, left=np.nan, right=np.nan), "k--", lw=1,
                    label="(2 pi f)^2 A = g")
            ax.legend(loc="upper left", fontsize=7)
        handles = [Patch(color=colours(k), label=r) for k, r in enumerate(REGIMES)]
        fig.legend(handles=handles, loc="upper right", ncol=4, fontsize=7)
        ax.set_title("gait regime (cells: mean speed, mm/s)", fontsize=9, loc="left")


def regime_map(params: RobotParams, grid: Grid, runs: Runs = Runs()) -> RegimeMap:
    """Classify a run at every (frequency, level) point of ``grid``, each made as ``runs`` says.

    Examples
    --------
    >>> m = regime_map(RobotParams(), Grid("shaker", [200, 240], [5, 25]), Runs(duration_s=0.2))  # doctest: +SKIP
    >>> m.regimes.shape                                                                              # doctest: +SKIP
    (2, 2)
    """
    from labkit.sim.excitation import PZT, Shaker

    kind, freq_hz, level, mass_mg = grid.kind, grid.freq_hz, grid.level, grid.mass_mg
    duration_s, seed = runs.duration_s, runs.seed

    if kind not in ("shaker", "pzt"):
        raise InputError(f"unknown drive {kind!r}", key="kind", expected="shaker or pzt")
    fs, ls = np.asarray(freq_hz, float), np.asarray(level, float)
    if fs.size == 0 or ls.size == 0:
        raise InputError("empty grid", key="freq_hz" if fs.size == 0 else "level", expected="at least one value")
    level_name = "amp_um" if kind == "shaker" else "voltage_v"

    def scenario(f: float, v: float) -> Shaker | PZT:
        return Shaker(freq_hz=f, amp_um=v) if kind == "shaker" else PZT(freq_hz=f, voltage_v=v, mass_mg=mass_mg)

    tasks = [runs.task(params, scenario(float(f), float(v))) for f in fs for v in ls]
    for t in tasks:
        runs.check(t.params, t.scenario)          # every point, before any process starts
    regs = runs.run_all(tasks, "regime map")
    shape = (fs.size, ls.size)
    meta: dict[str, Json] = {"duration_s": float(duration_s), "seed": int(seed), "mass_mg": mass_mg,
            "g_m_s2": float(params.g_m_s2),
            "still_speed_mm_s": STILL_SPEED_MM_S, "still_motion_um": STILL_MOTION_UM, "min_feet": MIN_FEET,
            "classifier": "labkit.sim.regime.classify_regime"}
    return RegimeMap(kind=kind, level_name=level_name, freq_hz=fs, level=ls,
                     regimes=np.array([r.regime for r in regs], dtype=object).reshape(shape).astype(str),
                     speeds_mm_s=np.array([r.speed_mm_s for r in regs]).reshape(shape),
                     flags=np.array([",".join(r.flags) for r in regs], dtype=object).reshape(shape).astype(str),
                     params_toml=params.to_toml_text(), meta=meta)


# --------------------------------------------------------------------------- edges

def edge_keys(params: RobotParams) -> tuple[str, ...]:
    """The parameters an edge search perturbs by default: the drive (tray amplitude or PZT
    voltage), every key of the Monte Carlo table (:data:`labkit.sim.uncertainty.DEFAULT_TABLE`)
    and the legs' modal participation."""
    from labkit.sim.uncertainty import DEFAULT_TABLE

    return (DRIVE_KEY, *sorted(DEFAULT_TABLE), "modal_participation")


def scaled(params: RobotParams, scenario: Shaker | PZT, key: str,
           factor: float) -> tuple[RobotParams, Shaker | PZT] | None:
    """The run with ``key`` multiplied by ``factor`` (every mode of a per-mode key; the body's or the
    legs' mass with the total following); ``None`` when that leaves the parameter's bounds or the
    parameter is 0 (a change of nothing)."""
    from labkit.sim.uncertainty import BOUNDED, check_table

    if key == DRIVE_KEY:
        name = "amp_um" if hasattr(scenario, "amp_um") else "voltage_v"
        value = float(getattr(scenario, name))
        return None if value == 0 else (params, scenario.with_value(name, value * factor))
    check_table(params, {key: 0.0})          # a key that is neither a field nor derived: ConfigError
    legs = 6 * params.leg_mass_mg
    if key in ("body_mass_mg", "leg_mass_mg"):
        body = params.body_mass_mg * (factor if key == "body_mass_mg" else 1.0)
        legs *= factor if key == "leg_mass_mg" else 1.0
        changes: dict[str, float | tuple[float, ...]] = {"body_mass_mg": body, "mass_mg": body + legs}
    else:
        value = getattr(params, key)
        if isinstance(value, (tuple, list)):
            changes = {key: tuple(float(v) * factor for v in value)}
        else:
            lo, hi = BOUNDED.get(key, (-np.inf, np.inf))
            if float(value) == 0 or not lo <= float(value) * factor <= hi:
                return None
            changes = {key: float(value) * factor}
    try:
        return params.replace(**changes), scenario
    except (ConfigError, InputError, ValueError):
        return None


class EdgeDict(TypedDict):
    """:meth:`Edge.to_dict`."""

    key: str
    direction: int
    within: float | None
    clear: float
    regime: str | None
    speed_mm_s: float | None
    note: str


@dataclass
class Edge:
    """The nearest edge found in one parameter and direction (``direction`` +1 up, -1 down).

    ``within``: the smallest relative change tried that crossed an edge (``None``: none up to the
    largest step); ``clear``: the largest one that did not; ``regime``/``speed_mm_s``: the run
    across the edge; ``note``: ``"bound"`` when the parameter cannot be changed further (or is 0).
    """

    key: str
    direction: int
    within: float | None = None
    clear: float = 0.0
    regime: str | None = None
    speed_mm_s: float | None = None
    note: str = ""

    def to_dict(self) -> EdgeDict:
        return {"key": self.key, "direction": self.direction, "within": self.within, "clear": self.clear,
                "regime": self.regime, "speed_mm_s": self.speed_mm_s, "note": self.note}


class EdgeReportDict(TypedDict):
    """:meth:`EdgeReport.to_dict` (``labkit simulate shaker --edges --json``'s ``edges``)."""

    base: RegimeDict
    steps: list[float]
    lines: list[str]
    resolved: bool
    seed_runs: list[RegimeDict]
    nearest: dict[str, float | None]
    edges: list[EdgeDict]
    meta: dict[str, Json]


@dataclass
class EdgeReport:
    """A run's regime and its distance to the nearest edge in each parameter (:func:`find_edges`)."""

    base: Regime
    edges: list[Edge]
    steps: tuple[float, ...]
    meta: dict[str, Json] = field(default_factory=dict)
    #: The base run again with other seeds (a slightly different random start, same parameters).
    seed_runs: list[Regime] = field(default_factory=list)

    @property
    def resolved(self) -> bool:
        """Does the base run repeat with other seeds (none of them across an edge from it)? If not,
        an "edge" may be the run's own spread rather than the parameter's."""
        return not any(changed(self.base, r) for r in self.seed_runs)

    def nearest(self) -> dict[str, Edge]:
        """Per parameter, the edge in the nearer direction (parameters without one: absent)."""
        out: dict[str, Edge] = {}
        for e in sorted((e for e in self.edges if e.within is not None), key=lambda e: float(e.within or 0.0)):
            out.setdefault(e.key, e)
        return out

    def seed_line(self) -> str:
        """``seeds: 2 others give -2.21, -2.51 mm/s (base -1.95; spread 28 % of it)``: how far the run's
        own random start moves it, to weigh the speed edges against."""
        speeds = [r.speed_mm_s for r in self.seed_runs]
        spread = max(abs(v - self.base.speed_mm_s) for v in speeds)
        v0 = abs(self.base.speed_mm_s)
        rel = f"{100 * spread / v0:.2g} % of it" if v0 >= SPEED_CHANGE_ABS_MM_S else f"{spread:.2g} mm/s"
        return (f"seeds: {len(speeds)} others give " + ", ".join(f"{v:.3g}" for v in speeds)
                + f" mm/s (base {self.base.speed_mm_s:.3g}; spread {rel})")

    def lines(self) -> list[str]:
        """``edge: 3 % in adhesion (down: jumping, 7.5 mm/s)`` per parameter with an edge, nearest first,
        then the parameters with none within the largest step."""
        near = self.nearest()
        out = [self.seed_line()] if self.seed_runs else []
        out += [] if self.resolved else [
            "base run NOT resolved: other seeds give " + ", ".join(f"{r.regime} {r.speed_mm_s:.3g} mm/s"
                                                                   for r in self.seed_runs)
            + f" (base {self.base.speed_mm_s:.3g} mm/s): edges below may be its own spread; run longer"]
        out += [f"edge: {100 * (e.within or 0.0):.2g} % in {LABELS.get(k, k)} ({'up' if e.direction > 0 else 'down'}: "
               f"{e.regime}, {e.speed_mm_s:.3g} mm/s)" for k, e in near.items()]
        none = sorted({e.key for e in self.edges} - set(near))
        if none:
            out.append(f"no edge within {100 * max(self.steps):.3g} %: " + ", ".join(LABELS.get(k, k) for k in none))
        return out

    def to_dict(self) -> EdgeReportDict:
        return {"base": self.base.to_dict(), "steps": list(self.steps), "lines": self.lines(),
                "resolved": self.resolved, "seed_runs": [r.to_dict() for r in self.seed_runs],
                "nearest": {k: e.within for k, e in self.nearest().items()},
                "edges": [e.to_dict() for e in self.edges], "meta": self.meta}


def find_edges(params: RobotParams, scenario: Shaker | PZT, runs: Runs = Runs(duration_s=2.0),
               search: EdgeSearch = EdgeSearch(), base: Regime | None = None) -> EdgeReport:
    """The smallest relative change of each parameter that changes the run's regime or moves its
    speed by more than :data:`SPEED_CHANGE_REL` (:func:`changed`).

    Each parameter is changed up and down by each of ``steps`` in turn (all parameters of one step in
    one batch through :func:`labkit.executor.map_tasks`); the first step that crosses is then narrowed
    by ``bisections`` halvings of the bracket. Every run uses the same duration and seed as the base.

    Parameters
    ----------
    params, scenario:
        The run.
    runs:
        Duration and seed of the base run and of every perturbed one, and where they run.
    search:
        ``keys``: parameters to perturb (default :func:`edge_keys`; :data:`DRIVE_KEY` is the tray
        amplitude or the PZT voltage); ``steps``: increasing relative changes (0.02 = 2 %);
        ``bisections``; ``seed_checks``: the base run is repeated with this many other seeds
        (``seed + 1``, ...): when one of them is across an edge from it,
        :attr:`EdgeReport.resolved` is false (the run's own spread).
    base:
        The base run's regime if already known (else it is simulated first).
    """
    duration_s, seed, keys, bisections = runs.duration_s, runs.seed, search.keys, search.bisections
    steps = tuple(float(s) for s in search.steps)
    if not steps or any(not 0 < s < 1 for s in steps) or list(steps) != sorted(steps):
        raise InputError(f"bad steps {steps}", key="steps", expected="increasing relative changes in (0, 1)")
    keys = tuple(edge_keys(params) if keys is None else keys)
    for k in keys:
        if k != DRIVE_KEY:
            scaled(params, scenario, k, 1.0)        # ConfigError naming an unknown key, before any run
    runs.check(params, scenario)
    first = 0 if base is None else 1
    regs = runs.run_all([runs.task(params, scenario, k) for k in range(first, 1 + int(search.seed_checks))],
                        "base run")
    base = regs.pop(0) if base is None else base
    edges = [Edge(k, d) for k in keys for d in (1, -1)]
    at = _Probe(params, scenario, runs, base)
    for step in steps:
        at.probe(edges, [(e, step) for e in edges if e.within is None and not e.note])
    for _ in range(int(bisections)):
        at.probe(edges, [(e, 0.5 * (e.clear + e.within)) for e in edges if e.within is not None])
    meta: dict[str, Json] = {"duration_s": float(duration_s), "seed": int(seed), "scenario": dict(scenario.to_dict()),
            "speed_change_rel": SPEED_CHANGE_REL, "speed_change_abs_mm_s": SPEED_CHANGE_ABS_MM_S,
            "bisections": int(bisections)}
    return EdgeReport(base, edges, steps, meta, seed_runs=regs)


@dataclass(frozen=True)
class _Probe:
    """The base run an edge search perturbs."""

    params: RobotParams
    scenario: Shaker | PZT
    runs: Runs
    base: Regime

    def probe(self, edges: list[Edge], todo: list[tuple[Edge, float]]) -> None:
        """Run every (edge, relative change) of ``todo`` in one batch and move each bracket."""
        tasks, owners = [], []
        for e, x in todo:
            run = scaled(self.params, self.scenario, e.key, 1.0 + e.direction * x)
            if run is None:
                e.note = "bound"
                continue
            try:
                self.runs.check(run[0], run[1])
            except InputError:
                e.note = "bound"          # beyond what the simulator accepts (amplitude, acceleration)
                continue
            tasks.append(self.runs.task(run[0], run[1]))
            owners.append((e, x))
        _move_brackets(owners, self.runs.run_all(tasks, "edges"), self.base)


def _move_brackets(owners: list[tuple[Edge, float]], regs: list[Regime], base: Regime) -> None:
    for (e, x), reg in zip(owners, regs):
        if changed(base, reg):
            e.within, e.regime, e.speed_mm_s = x, reg.regime, reg.speed_mm_s
        else:
            e.clear = x
