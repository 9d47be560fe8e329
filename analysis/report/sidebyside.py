"""Two reports' headline numbers side by side (before and after a calibration, two robots, ...).

Reads the ``headline`` of each report's ``agreement.json`` (written by
:func:`~labkit.analysis.report.build.build_report`); nothing is recomputed.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from labkit.analysis.report.numbers import format_uncertain, format_value
from labkit.errors import InputError


def load_headline(report_dir: str | Path) -> dict[str, Any]:
    """The ``headline`` table of a report folder (InputError naming the file if absent or unreadable)."""
    return _load(report_dir)["headline"]


def _load(report_dir: str | Path) -> dict[str, Any]:
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
    return data


def _text(entry: dict[str, Any] | None) -> str:
    if entry is None:
        return "-"
    v = entry.get("value")
    if "of" in entry:
        return f"{format_value(v)} of {entry['of']}"
    if entry.get("std") is not None:
        return format_uncertain(v, entry["std"], "")
    return format_value(v, int(entry.get("digits", 4)))


def compare_reports(a_dir: str | Path, b_dir: str | Path) -> dict[str, Any]:
    """Headline numbers of two reports, row by row.

    Returns
    -------
    dict
        ``a``, ``b`` (the folders) and ``rows``: one per headline key in either report, with
        ``key``, ``label``, ``units``, ``a`` and ``b`` (value or None), ``a_text``/``b_text``
        (with uncertainty where the report has one) and ``change`` (b - a, when both are numbers).
    """
    da, db = _load(a_dir), _load(b_dir)
    ha, hb = da["headline"], db["headline"]
    rows = []
    for key in list(ha) + [k for k in hb if k not in ha]:
        ea, eb = ha.get(key), hb.get(key)
        va = ea.get("value") if ea else None
        vb = eb.get("value") if eb else None
        any_entry = ea or eb or {}
        rows.append({"key": key, "label": any_entry.get("label", key), "units": any_entry.get("units", ""),
                     "a": va, "b": vb, "a_text": _text(ea), "b_text": _text(eb),
                     "change": (vb - va) if isinstance(va, (int, float)) and isinstance(vb, (int, float))
                     else None})
    verdicts = []
    sa, sb = da.get("sections") or {}, db.get("sections") or {}
    for sid in list(sa) + [k for k in sb if k not in sa]:
        va_, vb_ = ((x.get(sid) or {}).get("verdict", {}).get("result", "-") for x in (sa, sb))
        verdicts.append({"section": sid, "a": va_, "b": vb_})
    meta = {k: {"created_utc": d.get("meta", {}).get("created_utc"), "command": d.get("meta", {}).get("command")}
            for k, d in (("a", da), ("b", db))}
    return {"a": str(a_dir), "b": str(b_dir), "rows": rows, "verdicts": verdicts, "meta": meta}


def comparison_html(result: dict[str, Any]) -> str:
    """The comparison as a self-contained HTML page (the report's style sheet, no scripts)."""
    from labkit.analysis.report import html as rh

    rows = [[r["label"] + (f" ({r['units']})" if r["units"] else ""), r["a_text"], r["b_text"],
             "" if r["change"] is None else f"{r['change']:+.3g}"] for r in result["rows"]]
    verdicts = [[v["section"], ("html", rh.verdict_badge(v["a"])), ("html", rh.verdict_badge(v["b"]))]
                for v in result.get("verdicts", [])]
    meta = result.get("meta", {})
    parts = ['<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
             f"<title>labkit: two reports side by side</title><style>{rh.CSS}</style></head><body>",
             "<h1>Two reports side by side</h1>",
             rh.table(["", "folder", "made", "command"],
                      [[k.upper(), ("html", f'<span class="mono">{rh.e(result[k])}</span>'),
                        (meta.get(k) or {}).get("created_utc") or "",
                        ("html", f'<code>{rh.e((meta.get(k) or {}).get("command") or "")}</code>')]
                       for k in ("a", "b")]),
             "<h2>Headline numbers</h2>",
             rh.table(["quantity", "A", "B", "change (B - A)"], rows, num_cols={1, 2, 3})]
    if verdicts:
        parts += ["<h2>Section verdicts</h2>", rh.table(["section", "A", "B"], verdicts)]
    parts.append("</body></html>")
    return "\n".join(parts)


def comparison_lines(result: dict[str, Any]) -> list[str]:
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
