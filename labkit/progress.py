"""Progress bars on standard error, hidden when it is not a terminal or with ``--quiet``."""
from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(total: int | None = None, desc: str = "", *, quiet: bool = False,
             unit: str = "pt") -> tqdm:
    """A tqdm bar on stderr with time left; disabled off a terminal or when ``quiet``.

    Use as a context manager and call ``bar.update(n)``.
    """
    disable = quiet or not sys.stderr.isatty()
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=disable,
                leave=False, dynamic_ncols=True)


def track(items: Iterable[T], total: int | None = None, desc: str = "", *,
          quiet: bool = False) -> Iterable[T]:
    """Iterate over ``items`` with a progress bar (see :func:`progress`)."""
    with progress(total, desc, quiet=quiet) as bar:
        for item in items:
            yield item
            bar.update(1)
