"""A self-contained HTML page: inline CSS (with a print style sheet), figures as inline SVG,
no scripts, no external URLs. It opens offline in any browser, can be mailed as one file,
and prints to a clean PDF ("print to PDF": no navigation, figures not split across pages).
"""
from __future__ import annotations

import html
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labkit.analysis.report.numbers import format_value

if TYPE_CHECKING:
    from labkit.analysis.report.build import HeadlineEntry, Section
    from labkit.analysis.report.provenance import ReportMeta, SectionProvenance

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto;
       max-width: 1150px; color: #222; line-height: 1.4; padding: 0 1em; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #bbb; }
section.missing p.status { color: #8a4b00; background: #fff4e0; padding: .5em; border-left: 4px solid #e69500; }
p.status { color: #555; }
p.verdict { font-weight: 600; padding: .45em .7em; border-left: 5px solid #999; background: #f6f6f6; }
p.verdict.pass { border-color: #1e8449; background: #eafaf1; }
p.verdict.fail { border-color: #c0392b; background: #fdedec; }
p.verdict.missing { border-color: #e69500; background: #fff4e0; }
figure { margin: 1em 0; }
figure svg { width: 100%; height: auto; display: block; border: 1px solid #ddd; }
div.summary { border: 1px solid #ccc; background: #fbfbfb; padding: .3em 1em; margin: 1em 0; }
div.summary table { margin: .5em 0; }
figcaption { font-size: .9em; color: #444; margin-top: .3em; }
figcaption .files { color: #777; font-family: ui-monospace, Menlo, Consolas, monospace; font-size: .9em; }
table { border-collapse: collapse; margin: 1em 0; font-size: .88em; }
th, td { border: 1px solid #ccc; padding: .3em .6em; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.badge { font-weight: 700; padding: 0 .4em; border-radius: 3px; }
.badge.pass { color: #1e8449; } .badge.fail { color: #c0392b; } .badge.na { color: #777; }
div.provenance { font-size: .8em; color: #444; background: #fafafa; border: 1px solid #e2e2e2; padding: .5em .8em;
                 margin: 1em 0; }
div.provenance table { font-size: 1em; margin: .3em 0; }
div.provenance code, .mono { font-family: ui-monospace, Menlo, Consolas, monospace; word-break: break-all; }
footer { margin-top: 3em; font-size: .8em; color: #777; }
@media print {
  @page { size: A4; margin: 14mm 12mm; }
  body { max-width: none; margin: 0; padding: 0; font-size: 10pt; color: #000; }
  nav { display: none; }
  section > h2 { break-before: page; margin-top: 0; }
  div.summary h2 { break-before: auto; margin-top: .3em; }
  table { font-size: 7.5pt; max-width: 100%; }
  td.num { white-space: normal; }
  th, td { padding: .15em .35em; }
  h2, h3 { break-after: avoid; }
  figure, table, div.provenance, p.verdict { break-inside: avoid; }
  figure svg { border: none; max-height: 235mm; width: 100%; }
  div.summary { break-inside: avoid; }
  p.verdict { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  a { color: #000; text-decoration: none; }
}
"""


def e(x: Any) -> str:
    """HTML-escaped text."""
    return html.escape(str(x), quote=True)


_e = e          # the name earlier code used


def inline_svg(path: Path, label: str) -> str:
    """An SVG file's ``<svg>`` element for inlining (XML declaration and DOCTYPE dropped), with
    ``role="img"`` and an accessible label."""
    text = Path(path).read_text(encoding="utf-8")
    start = text.find("<svg")
    if start < 0:
        raise ValueError(f"{path} holds no <svg> element")
    svg = text[start:]
    # scale to the page's width, but a small figure (one knee panel) no more than 1.5 times its own size
    m = re.match(r'<svg\b[^>]*?\bwidth="([0-9.]+)pt"', svg)
    style = f' style="max-width: min(100%, {float(m.group(1)) * 4 / 3 * 1.5:.0f}px)"' if m else ""
    return re.sub(r"^<svg\b", f'<svg role="img" aria-label="{e(label)}"{style}', svg, count=1)


def fmt(value: Any, digits: int = 4) -> str:
    if isinstance(value, float) or value is None:
        return format_value(value, digits)
    return str(value)


def table(headers: list[str], rows: list[list[Any]], num_cols: set[int] | None = None) -> str:
    num_cols = num_cols or set()
    head = "".join(f"<th>{e(h)}</th>" for h in headers)
    body = []
    for row in rows:
        cells = []
        for i, v in enumerate(row):
            cls = ' class="num"' if i in num_cols else ""
            if isinstance(v, tuple) and v and v[0] == "html":
                cells.append(f"<td{cls}>{v[1]}</td>")
            else:
                cells.append(f"<td{cls}>{e(fmt(v))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def verdict_badge(result: str) -> str:
    cls = {"pass": "pass", "fail": "fail"}.get(result, "na")
    return f'<span class="badge {cls}">{e(result.upper() if cls != "na" else result)}</span>'


def provenance_block(p: SectionProvenance) -> str:
    """One section's provenance: which of the report's inputs it used (by number) and its notes."""
    parts = ['<div class="provenance"><b>Inputs</b>: ']
    files = p.get("files", [])
    parts.append(", ".join(f'<a href="#input-{f["number"]}">[{f["number"]}]</a> '
                           f'<span class="mono">{e(Path(f["shown_as"]).name)}</span>' for f in files)
                 or "none")
    for k, v in (p.get("notes") or {}).items():
        if k == "verdict_note":
            continue
        text = v if isinstance(v, str) else json.dumps(v, sort_keys=True, default=str)
        parts.append(f"<div>{e(k)}: {e(text)}</div>")
    parts.append("</div>")
    return "".join(parts)


def report_provenance(meta: ReportMeta) -> str:
    """The report's provenance, once: every input with SHA-256 and size, the software, the command."""
    rows = [[("html", f'<span id="input-{i}">{i}</span>'),
             ("html", f'<span class="mono">{e(f["shown_as"])}</span>'),
             ("html", f'<span class="mono">{e(f.get("sha256", "(not a file)"))}</span>'), f.get("bytes", "")]
            for i, f in enumerate(meta.get("input_files", []), 1)]
    return ('<section id="provenance"><h2>Provenance</h2>'
            + table(["#", "input (relative to this report's folder)", "SHA-256", "bytes"], rows, num_cols={3})
            + f'<div>software: <code>{e(meta.get("software", ""))}</code></div>'
            + "<div>command (from the folder holding the report's folder): "
            + f'<code>{e(meta.get("command", ""))}</code></div></section>')


def headline_block(headline: dict[str, HeadlineEntry]) -> str:
    """The headline numbers (those ``labkit report --compare`` puts side by side) as a table."""
    from labkit.analysis.report.numbers import format_uncertain

    rows = []
    for key, h in headline.items():
        v = h.get("value")
        if "of" in h:
            text = f"{format_value(v)} of {h['of']}"
        elif h.get("std") is not None:
            text = format_uncertain(v, h["std"])
        else:
            text = format_value(v, int(h.get("digits", 4)))
        rows.append([h.get("label", key), text, h.get("units", "")])
    if not rows:
        return ""
    return ('<div class="summary"><h2 id="summary">Headline numbers</h2>'
            + table(["quantity", "value", "units"], rows, num_cols={1})
            + "<p>The same numbers are in <code>agreement.json</code> (<code>headline</code>); "
              "<code>labkit report --compare A_DIR B_DIR</code> puts two reports' side by side.</p></div>")


def render(title: str, sections: list[Section], meta: ReportMeta,
           headline: dict[str, HeadlineEntry] | None = None) -> str:
    """The whole page."""
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
             f"<title>{e(title)}</title><style>{CSS}</style></head><body>",
             f"<h1>{e(title)}</h1>",
             f"<p>Generated {e(meta.get('created_utc', ''))} by {e(meta.get('software', 'labkit'))}.</p>",
             "<nav><ul>" + "".join(f'<li><a href="#{e(s.id)}">{e(s.title)}</a>: '
                                   f'{verdict_badge(s.verdict.get("result", "n/a"))}</li>'
                                   for s in sections) + "</ul></nav>",
             headline_block(headline or {})]
    for s in sections:
        cls = "ok" if s.status == "ok" else "missing"
        parts.append(f'<section id="{e(s.id)}" class="{cls}"><h2>{e(s.title)}</h2>')
        v = s.verdict
        parts.append(f'<p class="verdict {e(v.get("result", "").replace(" ", "-"))}">{e(v.get("text", ""))}</p>')
        if s.message and s.status == "ok":
            parts.append(f'<p class="status">{e(s.message)}</p>')
        for files, caption, _key in s.figures:
            parts.append(f"<figure>{inline_svg(files.svg, caption)}<figcaption>{e(caption)} "
                         f'<span class="files">({e(files.png.name)} at 200 dpi, {e(files.svg.name)})</span>'
                         f"</figcaption></figure>")
        parts.extend(s.html)
        if s.status == "ok" and s.provenance:
            parts.append(provenance_block(s.provenance))
        parts.append("</section>")
    parts.append(report_provenance(meta))
    parts.append("<footer><p>Tolerances: " + e(json.dumps(meta.get("tolerances", {}), sort_keys=True))
                 + "</p></footer>")
    parts.append("</body></html>")
    return "\n".join(parts)
