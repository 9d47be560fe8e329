"""The demo (the whole chain on the virtual lab) and the sample data it generates.

:func:`run_demo` (in :mod:`~labkit.demo.run`); the configs it writes are in
:mod:`~labkit.demo.configs`, its headline figures in :mod:`~labkit.demo.results`,
and ``labkit sample-data`` in :mod:`~labkit.demo.sampledata`.
"""
from __future__ import annotations

from labkit.demo.run import run_demo

__all__ = ["run_demo"]
