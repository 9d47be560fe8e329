"""labkit: the vibration lab's toolkit for thin-film PZT microrobots.

``labkit.open(path)`` opens any file labkit writes (run files, tracks, fits, simulations,
robot parameter files, videos) as a typed object; see :mod:`labkit.files` and docs/python-api.md.
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

__version__ = "0.1.0"

if TYPE_CHECKING:  # pragma: no cover
    from labkit.files import LabFile

__all__ = ["__version__", "open"]


def open(path: str | os.PathLike[str]) -> LabFile:  # noqa: A001 - labkit.open, as the issue names it
    """Open a file labkit wrote and return its typed object (:func:`labkit.files.open_file`)."""
    from labkit.files import open_file

    return open_file(path)
