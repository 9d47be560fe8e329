"""The paper's observations (``observations.toml``) and their pass/fail tests.

Each :class:`Observation` names the scenario that measures it, the metric
(a number the scenario reports) and a pass band ``[low, high]`` (either side
may be open), and optionally the regime it is about (``when``: a metric of the
same scenario that is 1 when the full model is in that regime, e.g. in partial
contact or moving, and 0 when not). :func:`check` turns a scenario's metrics
into one :class:`ObservationCheck` per observation of that scenario, in one of
three states: :data:`MET`, :data:`NOT_MET` or :data:`NOT_APPLICABLE` (the run is
not in the claim's regime: it neither meets nor fails the claim, and never
counts as met); :func:`violation` is the normalised distance outside the band,
the calibration's residual.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, TypedDict

from labkit.errors import ConfigError

#: The bundled table.
TABLE_PATH = Path(__file__).with_name("observations.toml")
BASES = ("number", "range", "sign", "order")
WHO = ("experiment", "simulation", "both")
#: The three states of an observation on a run.
MET, NOT_MET, NOT_APPLICABLE = "met", "not met", "not applicable"
STATES = (MET, NOT_MET, NOT_APPLICABLE)


@dataclass(frozen=True)
class Observation:
    """One claim of the paper, as a test on one scenario metric."""

    id: str
    scenario: str
    metric: str
    source: str
    quote: str
    basis: str
    tolerance: str
    who: str
    low: float | None = None
    high: float | None = None
    paper_value: float | None = None
    #: The regime metric: the claim applies only where ``metrics[when] > 0.5`` (None: always).
    when: str | None = None

    def applies(self, metrics: Mapping[str, Any]) -> bool:
        """Whether a scenario's metrics put the run in the claim's regime (always without ``when``)."""
        if self.when is None:
            return True
        raw = metrics.get(self.when)
        return raw is not None and math.isfinite(float(raw)) and float(raw) > 0.5

    @property
    def band(self) -> str:
        """The pass band in words, e.g. ``"2 <= x <= 6"``, ``"x < 0.1"``."""
        if self.low is not None and self.high is not None:
            return f"{self.low:g} <= {self.metric} <= {self.high:g}"
        if self.low is not None:
            return f"{self.metric} > {self.low:g}"
        return f"{self.metric} < {self.high:g}"

    def passes(self, value: float | None) -> bool:
        """Whether a metric value is inside the band (NaN/None never passes)."""
        return violation(self, value) == 0.0

    def scale(self) -> float:
        """The unit of distance outside the band: the band's width, or its bound's size, or 1."""
        if self.low is not None and self.high is not None and self.high > self.low:
            return self.high - self.low
        bound = self.low if self.low is not None else self.high
        return max(abs(bound or 0.0), 0.1)


def violation(obs: Observation, value: float | None, margin: float = 0.0) -> float:
    """Distance of ``value`` outside the band in units of :meth:`Observation.scale`; 0 inside.

    One-sided sign tests (``> 0``) pass only strictly; a missing value (NaN)
    counts as 3 units. ``margin`` (in the same units) narrows the band on each
    bounded side first: the calibration's objective uses it so that its search
    does not stop on a band's edge (:data:`labkit.sim.paper.fit.OBJECTIVE_MARGIN`);
    whether an observation is met is always decided with ``margin = 0``.
    """
    if value is None or not math.isfinite(float(value)):
        return 3.0
    v = float(value)
    s = obs.scale()
    d = margin * s
    if obs.low is not None:
        lo = obs.low + d
        if obs.high is None and v <= obs.low:      # one-sided: strictly above
            return max((lo - v) / s, 1e-3)
        if v < lo:
            return (lo - v) / s
    if obs.high is not None:
        hi = obs.high - d
        if obs.low is None and v >= obs.high:      # one-sided: strictly below
            return max((v - hi) / s, 1e-3)
        if v > hi:
            return (v - hi) / s
    return 0.0


@dataclass(frozen=True)
class ObservationCheck:
    """One observation evaluated on one scenario result.

    ``state`` is :data:`MET`, :data:`NOT_MET` or :data:`NOT_APPLICABLE`; ``passed``
    is ``state == MET`` (so not applicable is never passed); ``violation`` is NaN
    when not applicable.
    """

    id: str
    metric: str
    value: float | None
    passed: bool
    band: str
    source: str
    violation: float
    state: str = ""
    when: str | None = None

    def __post_init__(self) -> None:
        if not self.state:
            object.__setattr__(self, "state", MET if self.passed else NOT_MET)
        if self.state not in STATES or self.passed != (self.state == MET):
            raise ValueError(f"inconsistent observation state {self.state!r} / passed={self.passed}")

    @property
    def applicable(self) -> bool:
        return self.state != NOT_APPLICABLE

    def line(self) -> str:
        """The PASS / FAIL / N/A line the scenarios print."""
        v = "n/a" if self.value is None or not math.isfinite(self.value) else f"{self.value:.4g}"
        verdict = {MET: "PASS", NOT_MET: "FAIL", NOT_APPLICABLE: "N/A "}[self.state]
        regime = f" [not applicable: {self.when} = 0]" if self.state == NOT_APPLICABLE else ""
        return f"{verdict}  {self.id}: {self.metric} = {v}  (paper: {self.band}; {self.source}){regime}"

    def to_dict(self) -> ObservationCheckJSON:
        viol = self.violation if math.isfinite(self.violation) else None
        return ObservationCheckJSON(id=self.id, metric=self.metric, value=self.value, passed=self.passed,
                                    state=self.state, band=self.band, source=self.source, violation=viol,
                                    when=self.when)


class ObservationCheckJSON(TypedDict):
    """:meth:`ObservationCheck.to_dict` (JSON in scenario results)."""

    id: str
    metric: str
    value: float | None
    passed: bool
    state: str
    band: str
    source: str
    violation: float | None
    when: str | None


def tally(checks: Sequence[ObservationCheck]) -> dict[str, int]:
    """Counts of the three states: ``{"met": n, "not met": n, "not applicable": n}``."""
    return {s: sum(c.state == s for c in checks) for s in STATES}


def _num(row: Mapping[str, Any], key: str, where: str, file: str | Path = TABLE_PATH) -> float | None:
    if key not in row:
        return None
    v = row[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise ConfigError(f"not a finite number: {v!r}", file=str(file), key=f"{where}.{key}",
                          expected="a number")
    return float(v)


def parse(table: Mapping[str, Any], *, file: str | Path = TABLE_PATH) -> list[Observation]:
    """Observations from a parsed TOML table; ConfigError names the file and the entry's key."""
    rows = table.get("observation")
    if not isinstance(rows, list) or not rows:
        raise ConfigError("no [[observation]] entries", file=str(file), key="observation",
                          expected="an array of tables")
    out: list[Observation] = []
    seen: set[str] = set()
    text_keys = ("id", "scenario", "metric", "source", "quote", "basis", "tolerance", "who")
    for i, row in enumerate(rows):
        where = f"observation[{i}]"
        for k in text_keys:
            if not isinstance(row.get(k), str) or not row[k]:
                raise ConfigError("missing or not text", file=str(file), key=f"{where}.{k}", expected="a string")
        unknown = set(row) - set(text_keys) - {"low", "high", "paper_value", "when"}
        if unknown:
            raise ConfigError(f"unknown key(s) {sorted(unknown)}", file=str(file), key=where,
                              expected=", ".join(text_keys + ("low", "high", "paper_value", "when")))
        if "when" in row and (not isinstance(row["when"], str) or not row["when"]):
            raise ConfigError("not a metric name", file=str(file), key=f"{where}.when", expected="a string")
        if row["basis"] not in BASES:
            raise ConfigError(f"unknown basis {row['basis']!r}", file=str(file), key=f"{where}.basis",
                              expected=" | ".join(BASES))
        if row["who"] not in WHO:
            raise ConfigError(f"unknown {row['who']!r}", file=str(file), key=f"{where}.who", expected=" | ".join(WHO))
        low, high = _num(row, "low", where, file), _num(row, "high", where, file)
        if low is None and high is None:
            raise ConfigError("no pass band", file=str(file), key=where, expected="low and/or high")
        if low is not None and high is not None and not low < high:
            raise ConfigError(f"low {low} >= high {high}", file=str(file), key=where, expected="low < high")
        if row["id"] in seen:
            raise ConfigError("duplicate id", file=str(file), key=f"{where}.id", expected="unique ids")
        seen.add(row["id"])
        out.append(Observation(id=row["id"], scenario=row["scenario"], metric=row["metric"], source=row["source"],
                               quote=row["quote"], basis=row["basis"], tolerance=row["tolerance"], who=row["who"],
                               low=low, high=high, paper_value=_num(row, "paper_value", where, file),
                               when=row.get("when")))
    return out


@lru_cache(maxsize=1)
def _load_bundled() -> tuple[Observation, ...]:
    import tomllib

    with open(TABLE_PATH, "rb") as fh:
        return tuple(parse(tomllib.load(fh)))


def observations(scenario: str | None = None) -> list[Observation]:
    """The bundled observations (of one scenario, if given), in the table's order."""
    return [o for o in _load_bundled() if scenario is None or o.scenario == scenario]


def check_one(o: Observation, metrics: Mapping[str, Any]) -> ObservationCheck:
    """One observation on a scenario's metrics: not applicable outside its regime, else met or not
    (a missing metric is not met)."""
    raw = metrics.get(o.metric)
    value = None if raw is None else float(raw)
    if not o.applies(metrics):
        return ObservationCheck(id=o.id, metric=o.metric, value=value, passed=False, band=o.band, source=o.source,
                                violation=float("nan"), state=NOT_APPLICABLE, when=o.when)
    viol = violation(o, value)
    return ObservationCheck(id=o.id, metric=o.metric, value=value, passed=viol == 0.0, band=o.band,
                            source=o.source, violation=viol, when=o.when)


def check(scenario: str, metrics: Mapping[str, Any]) -> list[ObservationCheck]:
    """Every observation of ``scenario`` evaluated on its metrics (:func:`check_one`)."""
    return [check_one(o, metrics) for o in observations(scenario)]
