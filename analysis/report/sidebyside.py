"""Two reports' headline numbers side by side (before and after a calibration, two robots, ...).

Reads the ``headline`` of each report's ``agreement.json`` (written by
:func:`~labkit.analysis.report.build.build_report`); nothing is recomputed.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, NotRequired, TypedDict, cast

from labkit.analysis.report.numbers import format_uncertain, format_value
from labkit.errors import InputError

if TYPE_CHECKING:  # pragma: no cover - typing only
    from labkit.analysis.report.build import HeadlineEntry, Verdict
    from labkit.analysis.report.provenance import ReportMeta


class _SectionRecord(TypedDict, total=False):
    verdict: Verdict


class _Agreement(TypedDict, total=False):
    """What this module reads of a report's ``agreement.json``."""

    headline: dict[str, HeadlineEntry]
    sections: dict[str, _SectionRecord]
    meta: ReportMeta


class ComparedNumber(TypedDict):
    """One headline number of both reports (None where a report lacks it)."""

    key: str
    label: str
    units: str
    a: float | int | None
    b: float | int | None
    a_text: str
    b_text: str
    change: float | int | None


class ComparedVerdict(TypedDict):
    section: str
    a: str
    b: str


class ReportStamp(TypedDict):
    created_utc: str | None
    command: str | None


class Comparison(TypedDict):
    """:func:`compare_reports` (``labkit report --compare --json``; ``html`` once the page is written)."""

    a: str
    b: str
    rows: list[ComparedNumber]
    verdicts: list[ComparedVerdict]
    meta: dict[str, ReportStamp]
    html: NotRequired[str]


def load_headline(report_dir: str | Path) -> dict[str, HeadlineEntry]:
    """The ``headline`` table of a report folder (InputError naming the file if absent or unreadable)."""
    return _load(report_dir)["headline"]


def _load(report_dir: str | Path) -> _Agreement:
    path = Path(report_dir) / "agreement.json"
    if not path.is_file():
        raise InputError("no agreement.json: not a labkit report folder", file=path,
                         expected="a folder written by labkit report")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read it ({exc})", file=path) from None
    if not isinstance(data, dict) or not isinstance(data.get("headline"), dict):
        raise InputError("no headline table (a report from an older labkit?)", file=path, key="headline",
                         expected="rerun labkit report")
    return cast("_Agreement", data)     # its headline checked above; the rest is read with defaults


def _text(entry: HeadlineEntry | None) -> str:
    if entry is None:
        return "-"
    v = entry.get("value")
    if "of" in entry:
        return f"{format_value(v)} of {entry['of']}"
    if entry.get("std") is not None:
        return format_uncertain(v, entry["std"], "")
    return format_value(v, int(entry.get("digits", 4)))


def compare_reports(a_dir: str | Path, b_dir: str | Path) -> Comparison:
    """Headline numbers of two reports, row by row.

    Returns
    -------
    Comparison
        ``a``, ``b`` (the folders) and ``rows``: one per headline key in either report, with
        ``key``, ``label``, ``units``, ``a`` and ``b`` (value or None), ``a_text``/``b_text``
        (with uncertainty where the report has one) and ``change`` (b - a, when both are numbers).
    """
    da, db = _load(a_dir), _load(b_dir)
    ha, hb = da["headline"], db["headline"]
    rows: list[ComparedNumber] = []
    for key in list(ha) + [k for k in hb if k not in ha]:
        ea, eb = ha.get(key), hb.get(key)
        va = ea.get("value") if ea else None
        vb = eb.get("value") if eb else None
        any_entry = ea or eb
        rows.append({"key": key, "label": any_entry.get("label", key) if any_entry else key,
                     "units": any_entry.get("units", "") if any_entry else "",
                     "a": va, "b": vb, "a_text": _text(ea), "b_text": _text(eb),
                     "change": (vb - va) if isinstance(va, (int, float)) and isinstance(vb, (int, float))
                     else None})
    verdicts: list[ComparedVerdict] = []
    sa, sb = da.get("sections") or {}, db.get("sections") or {}
    for sid in list(sa) + [k for k in sb if k not in sa]:
        va_, vb_ = (_verdict(x, sid) for x in (sa, sb))
        verdicts.append({"section": sid, "a": va_, "b": vb_})
    meta = {k: _stamp(d) for k, d in (("a", da), ("b", db))}
    return {"a": str(a_dir), "b": str(b_dir), "rows": rows, "verdicts": verdicts, "meta": meta}


def _verdict(sections: dict[str, _SectionRecord], sid: str) -> str:
    """A section's verdict in one report (``-`` when that report lacks the section)."""
    verdict = sections.get(sid, {}).get("verdict")
    return verdict.get("result", "-") if verdict else "-"


def _stamp(data: _Agreement) -> ReportStamp:
    meta = data.get("meta")
    return {"created_utc": meta.get("created_utc") if meta else None, "command": meta.get("command") if meta else None}


def comparison_html(result: Comparison) -> str:
    """The comparison as a self-contained HTML page (the report's style sheet, no scripts)."""
    from labkit.analysis.report import html as rh

    rows = [[r["label"] + (f" ({r['units']})" if r["units"] else ""), r["a_text"], r["b_text"],
             "" if r["change"] is None else f"{r['change']:+.3g}"] for r in result["rows"]]
    verdicts = [[v["section"], ("html", rh.verdict_badge(v["a"])), ("html", rh.verdict_badge(v["b"]))]
                for v in result.get("verdicts", [])]
    meta = result["meta"]
    parts = ['<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
             f"<title>labkit: two reports side by side</title><style>{rh.CSS}</style></head><body>",
             "<h1>Two reports side by side</h1>",
             rh.table(["", "folder", "made", "command"],
                      [[k.upper(), ("html", f'<span class="mono">{rh.e(result[k])}</span>'),
                        meta[k]["created_utc"] or "",
                        ("html", f'<code>{rh.e(meta[k]["command"] or "")}</code>')]
                       for k in ("a", "b")]),
             "<h2>Headline numbers</h2>",
             rh.table(["quantity", "A", "B", "change (B - A)"], rows, num_cols={1, 2, 3})]
    if verdicts:
        parts += ["<h2>Section verdicts</h2>", rh.table(["section", "A", "B"], verdicts)]
    parts.append("</body></html>")
    return "\n".join(parts)


def comparison_lines(result: Comparison) -> list[str]:
    """The comparison as aligned text lines (for a terminal)."""
    rows = result["rows"]
    w0 = max([len(r["label"]) + len(r["units"]) + 3 for r in rows] + [8])
    w1 = max([len(r["a_text"]) for r in rows] + [1, len("A")])
    w2 = max([len(r["b_text"]) for r in rows] + [1, len("B")])
    lines = [f"A: {result['a']}", f"B: {result['b']}",
             f"{'':{w0}s}  {'A':>{w1}s}  {'B':>{w2}s}  change (B - A)"]
    for r in rows:
        name = r["label"] + (f" ({r['units']})" if r["units"] else "")
        ch = "" if r["change"] is None else f"{r['change']:+.3g}"
        lines.append(f"{name:{w0}s}  {r['a_text']:>{w1}s}  {r['b_text']:>{w2}s}  {ch}")
    return lines
