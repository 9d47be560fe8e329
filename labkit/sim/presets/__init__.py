"""Bundled robot parameter sets, selectable by name (``--params NAME``, ``RobotParams.preset(NAME)``).

====================  ====================================================================
name                  what it is
====================  ====================================================================
``published``         the paper's Tables 1-2 and the documented choices of docs/model.md
                      (``RobotParams()``)
``paper``             ``paper_calibrated`` with its adhesion (3.0 uN) and both squeeze films
                      (0.20 of Tables 1-2) moved together on an ensemble of 18 drawn robots
                      (``paper.toml`` here; its ``[provenance]`` table says how, with which
                      observations met; docs/simulator.md, "The default paper set: adhesion
                      and films moved together"); the default of ``labkit simulate``
                      (:data:`DEFAULT_PRESET`)
``paper_calibrated``  ``published`` with the legs' modal mass at the foot from a uniform
                      cantilever (1/4 of the leg's mass) and the parameters the paper did not
                      measure calibrated to its observations over 4 robots (written by
                      :func:`labkit.sim.paper.fit.calibrate_paper`); the previous
                      default, kept so the numbers measured on it can be reproduced
====================  ====================================================================

A file preset is a plain parameter file (``labkit/sim/presets/<name>.toml``),
read with :meth:`RobotParams.from_toml`.
"""
from __future__ import annotations

from pathlib import Path

from labkit.errors import ConfigError, InputError
from labkit.sim.params import RobotParams

HERE = Path(__file__).parent
#: The set ``labkit simulate`` and ``labkit demo`` use when none is named.
DEFAULT_PRESET = "paper"
#: Provenance of the built-in ``published`` set.
PUBLISHED_PROVENANCE = {"source": "Qu, Choi, Oldham 2017, Tables 1-2, and the choices of docs/model.md",
                        "preset": "published"}


def preset_path(name: str) -> Path:
    """Where the file of a file preset lives (it may not exist)."""
    return HERE / f"{name}.toml"


def preset_names() -> list[str]:
    """The presets available: ``published`` and every bundled file."""
    return ["published"] + sorted(p.stem for p in HERE.glob("*.toml") if p.stem != "published")


def preset(name: str) -> RobotParams:
    """A bundled parameter set by name; ConfigError (key ``preset``) naming the choices otherwise."""
    if name == "published":
        return RobotParams(provenance=dict(PUBLISHED_PROVENANCE))
    path = preset_path(name)
    if not name.isidentifier() or not path.is_file():
        raise ConfigError(f"no parameter preset {name!r}", key="preset", expected=" | ".join(preset_names()))
    return RobotParams.from_toml(path)


def load(text: str | None) -> RobotParams:
    """``--params`` of the commands: a preset name, a parameter file, or (None) the published set.

    An existing file wins over a preset of the same name; neither -> InputError naming ``--params``.
    """
    if text is None:
        return RobotParams()
    if Path(text).is_file():
        return RobotParams.from_toml(text)
    if text in preset_names():
        return preset(text)
    raise InputError("no such parameter file or preset", file=text, key="--params",
                     expected="a TOML file or one of " + ", ".join(preset_names()))


def describe(text: str | None, params: RobotParams) -> str:
    """The line a run starts with: ``parameter set: NAME (what it is)`` (``text`` as given to
    ``--params``; None: the default preset)."""
    name = text or DEFAULT_PRESET
    what = params.provenance.get("summary") or params.provenance.get("source") or "a parameter file"
    if name == "published":
        what = "the paper's Tables 1-2"
    return f"parameter set: {name} ({what})"
