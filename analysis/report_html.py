"""A self-contained HTML page: inline CSS, figures as base64 PNG, no scripts, no external URLs.

It opens offline in any browser and can be mailed as one file.
"""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto;
       max-width: 1100px; color: #222; line-height: 1.4; padding: 0 1em; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #bbb; }
section.missing p.status { color: #8a4b00; background: #fff4e0; padding: .5em; border-left: 4px solid #e69500; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
table { border-collapse: collapse; margin: 1em 0; font-size: .9em; }
th, td { border: 1px solid #ccc; padding: .3em .6em; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.prov { font-size: .8em; color: #555; font-family: ui-monospace, Menlo, Consolas, monospace; word-break: break-all; }
footer { margin-top: 3em; font-size: .8em; color: #777; }
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def img_tag(path: Path, alt: str) -> str:
    """An <img> with the PNG embedded as a data URI."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{_e(alt)}">'


def fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def table(headers: list[str], rows: list[list[Any]], num_cols: set[int] | None = None) -> str:
    num_cols = num_cols or set()
    head = "".join(f"<th>{_e(h)}</th>" for h in headers)
    body = []
    for row in rows:
        cells = []
        for i, v in enumerate(row):
            cls = ' class="num"' if i in num_cols else ""
            if isinstance(v, tuple) and v and v[0] == "html":
                cells.append(f"<td{cls}>{v[1]}</td>")
            else:
                cells.append(f"<td{cls}>{_e(fmt(v))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def prov(p: Any) -> tuple[str, str]:
    """Provenance rendered as a compact monospace cell: one ``key: value`` line per entry."""
    if not isinstance(p, dict):
        return ("html", f'<span class="prov">{_e(p)}</span>')
    lines = []
    for key, value in p.items():
        if isinstance(value, (list, tuple)):
            text = "; ".join(str(v) for v in value)
        elif isinstance(value, dict):
            text = json.dumps(value, sort_keys=True, default=str)
        else:
            text = fmt(value)
        lines.append(f"<b>{_e(key)}</b>: {_e(text)}")
    return ("html", '<span class="prov">' + "<br>".join(lines) + "</span>")


def render(title: str, sections: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    """The whole page. Each section: ``id``, ``title``, ``status`` ("ok"|"missing"),
    ``message``, ``figures`` [(path, caption)], ``html`` (already escaped fragments)."""
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
             f"<title>{_e(title)}</title><style>{CSS}</style></head><body>",
             f"<h1>{_e(title)}</h1>",
             f"<p>Generated {_e(meta.get('created_utc', ''))} by {_e(meta.get('software', 'labkit'))}.</p>",
             "<nav><ul>" + "".join(f'<li><a href="#{_e(s["id"])}">{_e(s["title"])}</a>'
                                    f'{" (missing input)" if s["status"] != "ok" else ""}</li>'
                                    for s in sections) + "</ul></nav>"]
    for s in sections:
        cls = "ok" if s["status"] == "ok" else "missing"
        parts.append(f'<section id="{_e(s["id"])}" class="{cls}"><h2>{_e(s["title"])}</h2>')
        if s.get("message"):
            parts.append(f'<p class="status">{_e(s["message"])}</p>')
        for path, caption in s.get("figures", []):
            parts.append(f"<figure>{img_tag(path, caption)}<figcaption>{_e(caption)}</figcaption></figure>")
        parts.extend(s.get("html", []))
        parts.append("</section>")
    inputs = meta.get("inputs", {})
    parts.append("<footer><p>Inputs: " + _e(json.dumps(inputs, sort_keys=True)) + "</p></footer>")
    parts.append("</body></html>")
    return "\n".join(parts)
