"""labkit: the vibration lab's toolkit for thin-film PZT microrobots.

``labkit.open(path)`` opens any file labkit writes (run files, tracks, fits, simulations,
robot parameter files, videos) as a typed object; see :mod:`labkit.files` and docs/python-api.md.
"""
from __future__ import annotations

import signal as _signal
import sys as _sys

#: stop signals that arrived while the ``labkit`` command was starting (before its handlers)
_EARLY_SIGNALS: list[int] = []


def _note_early_signals() -> None:
    """In the ``labkit`` command's process only (``labkit ...``, ``python -m labkit ...``), note
    SIGINT/SIGTERM/SIGHUP/SIGQUIT from here on instead of dying by them or printing a traceback
    from the middle of an import; first thing in the package, before anything slow is imported."""
    argv0 = _sys.argv[0].rsplit("/", 1)[-1] if _sys.argv and _sys.argv[0] else ""
    if argv0 != "labkit" and list(getattr(_sys, "orig_argv", []))[1:3] != ["-m", "labkit"]:
        return
    for sig in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP, _signal.SIGQUIT):
        _signal.signal(sig, lambda signum, frame: _EARLY_SIGNALS.append(signum))


_note_early_signals()


import os  # noqa: E402 - after the signal hook above, on purpose
from typing import TYPE_CHECKING  # noqa: E402

__version__ = "0.1.0"

if TYPE_CHECKING:  # pragma: no cover
    from labkit.files import LabFile

__all__ = ["__version__", "early_signals", "open"]


def early_signals() -> list[int]:
    """Stop signals noted while the ``labkit`` command started (then cleared).

    :func:`labkit.cli.main` stops with exit 130 if there were any. A library import of
    ``labkit`` changes no signal handler.
    """
    out = list(_EARLY_SIGNALS)
    _EARLY_SIGNALS.clear()
    return out


def open(path: str | os.PathLike[str]) -> LabFile:  # noqa: A001 - labkit.open, as the issue names it
    """Open a file labkit wrote and return its typed object (:func:`labkit.files.open_file`)."""
    from labkit.files import open_file

    return open_file(path)
