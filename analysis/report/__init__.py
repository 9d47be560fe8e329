"""Model-against-measurement reports: one self-contained HTML file with figures.

:func:`build_report` (in :mod:`~labkit.analysis.report.build`) reads the
inputs (:mod:`~labkit.analysis.report.inputs`), compares them
(:mod:`labkit.analysis.compare`), draws the figures
(:mod:`~labkit.analysis.report.figures`) and writes the page
(:mod:`~labkit.analysis.report.html`); :func:`compare_reports` puts two reports'
headline numbers side by side.
"""
from __future__ import annotations

from labkit.analysis.report.build import build_report
from labkit.analysis.report.sidebyside import compare_reports

__all__ = ["build_report", "compare_reports"]
