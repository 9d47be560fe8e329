"""Open the report in a real headless Chromium (Debian's, installed by .ci/run): every figure
(inline SVG) renders, the page logs no console message or error, each section states its
verdict in its text, and the provenance is written once for the report (sections refer to it).

No extra Python dependency: Chromium's ``--dump-dom`` returns the DOM after the load
event, with the result of a small check script written into it; console messages are
read from Chromium's own log (``--enable-logging=stderr``, lines with ``CONSOLE``). A
screenshot of the whole page (window as tall as the page) and the page printed to PDF are
kept as the test's artifacts: ``<tmp_path>/browser/report_fullpage.png`` and
``report_print.pdf``, both copied into the folder named by the environment variable
``LABKIT_TEST_ARTIFACTS`` when it is set (CI can upload that folder).
The check script goes into a *copy* of the report (the report itself holds no script).
External hosts are unresolvable (``--host-resolver-rules``), so a page that needed the
network would fail here.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

CHECK = """<script>
window.__errs = [];
window.addEventListener('error', function (e) {
  window.__errs.push('error: ' + (e.message ||
    ('failed to load ' + ((e.target && (e.target.src || e.target.href)) || '?')).slice(0, 80)));
}, true);
['error', 'warn'].forEach(function (k) { var o = console[k]; console[k] = function () {
  window.__errs.push('console.' + k + ': ' + Array.from(arguments).join(' ')); o.apply(console, arguments); }; });
window.addEventListener('load', function () {
  var imgs = Array.from(document.images);
  var box = function (el) { var r = el.getBoundingClientRect();
    return {x: r.left + window.scrollX, y: r.top + window.scrollY, w: r.width, h: r.height}; };
  var svgs = Array.from(document.querySelectorAll('figure > svg')).map(function (s) {
    var b = box(s); b.marks = s.querySelectorAll('path, use, image, text').length;
    b.label = s.getAttribute('aria-label') || ''; return b; });
  var sections = Array.from(document.querySelectorAll('section:not(#provenance)')).map(function (s) {
    var v = s.querySelector('p.verdict');
    return {id: s.id, verdict: v ? v.textContent : '', provenance: s.querySelectorAll('div.provenance').length,
            figures: s.querySelectorAll('figure > svg').length}; });
  var v = {images: imgs.length,
           decoded: imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length,
           widths: imgs.map(function (i) { return i.naturalWidth; }),
           svgs: svgs, sections: sections,
           provenance: Array.from(document.querySelectorAll('div.provenance')).map(function (p) {
             return p.textContent; }),
           text: document.body.innerText,
           provenance_box: document.getElementById('provenance') ?
             box(document.getElementById('provenance')) : null,
           height: document.documentElement.scrollHeight, errors: window.__errs};
  var p = document.createElement('pre'); p.id = 'labkit-verdict'; p.textContent = JSON.stringify(v);
  document.body.appendChild(p);
});
</script>"""


def _chromium(args: list[str], profile: Path) -> subprocess.CompletedProcess:
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions",
           "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={profile}", "--hide-scrollbars",
           "--force-device-scale-factor=1", "--enable-logging=stderr", "--v=0", "--virtual-time-budget=10000",
           *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


def open_in_browser(html_path: Path, work: Path, width: int = 1200) -> dict:
    """Load a page with the check script; return the check's result plus the console lines and
    a screenshot of the whole page (``work/report_fullpage.png``)."""
    work.mkdir(parents=True, exist_ok=True)
    text = html_path.read_text(encoding="utf-8")
    probe = work / "probe.html"
    probe.write_text(text.replace("<head>", "<head>" + CHECK, 1), encoding="utf-8")
    assert CHECK in probe.read_text()
    proc = _chromium([f"--window-size={width},900", "--dump-dom", probe.as_uri()], work / "profile")
    m = re.search(r'<pre id="labkit-verdict">(.*?)</pre>', proc.stdout, re.S)
    assert m, f"no verdict in the DOM (rc {proc.returncode}); stderr:\n{proc.stderr[-2000:]}"
    verdict = json.loads(m.group(1).replace("&quot;", '"').replace("&lt;", "<").replace("&gt;", ">")
                         .replace("&amp;", "&"))
    verdict["console"] = [ln for ln in proc.stderr.splitlines() if "CONSOLE" in ln]
    shot = work / "report_fullpage.png"
    height = int(min(max(verdict["height"], 600), 30000))
    proc2 = _chromium([f"--screenshot={shot}", f"--window-size={width},{height}", html_path.as_uri()],
                      work / "profile2")
    assert shot.is_file(), proc2.stderr[-2000:]
    verdict["screenshot"] = shot
    keep = os.environ.get("LABKIT_TEST_ARTIFACTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy2(shot, Path(keep) / f"{html_path.parent.name}_fullpage.png")
    return verdict


def print_to_pdf(html_path: Path, work: Path) -> tuple[Path, int]:
    """Chromium's "print to PDF" of a page (the print style sheet applies): the PDF and its page count."""
    pdf = work / "report_print.pdf"
    proc = _chromium(["--no-pdf-header-footer", f"--print-to-pdf={pdf}", html_path.as_uri()], work / "profile3")
    assert pdf.is_file(), proc.stderr[-2000:]
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF")
    keep = os.environ.get("LABKIT_TEST_ARTIFACTS")
    if keep:
        shutil.copy2(pdf, Path(keep) / f"{html_path.parent.name}_print.pdf")
    return pdf, len(re.findall(rb"/Type\s*/Page[^s]", data))


def _pixels(png: Path) -> np.ndarray:
    import matplotlib.image

    return matplotlib.image.imread(str(png))


def test_chromium_is_installed():
    assert CHROMIUM, "Chromium not found: .ci/run installs it (apt-get install chromium)"


@pytest.mark.slow
def test_report_renders_in_chromium(inputs, tmp_path):
    from labkit.analysis.report.build import build_report

    tracks = [str(inputs[f"track{i}"]) for i in range(5)]
    s = build_report(tmp_path / "rep", runs=[str(inputs["inchip"]), str(inputs["shaker"])], tracks=tracks,
                     fit=str(inputs["fit"]), sims=[str(inputs["sweep"]), str(inputs["sim_200"]),
                                                   str(inputs["sim_300"])], simulate_knee=False)
    assert CHROMIUM, "Chromium not found"
    v = open_in_browser(Path(s["html"]), tmp_path / "browser")
    assert v["errors"] == [] and v["console"] == [], (v["errors"], v["console"])
    # every figure is an inline SVG that the browser laid out at a readable size and that holds marks
    assert v["images"] == 0 and len(v["svgs"]) == len(s["svgs"]) == 7
    for fig in v["svgs"]:
        assert fig["w"] >= 500 and fig["h"] >= 200 and fig["marks"] > 20, fig
    # ... and painted: the screenshot, cropped to each figure's box, is not blank
    img = _pixels(v["screenshot"])[..., :3]
    assert img.shape[0] >= 0.95 * v["height"] and img.shape[1] >= 1100
    for fig in v["svgs"]:
        y0, x0 = int(fig["y"]), int(fig["x"])
        crop = img[y0:y0 + int(fig["h"]), x0:x0 + int(fig["w"])]
        assert crop.size and crop.std() > 0.05 and (crop < 0.5).mean() > 0.005, fig["label"][:60]
    # each section states its verdict in its text, as build_report judged it
    words = {"pass": "Verdict: PASS", "fail": "Verdict: FAIL", "not judged": "Verdict: not judged",
             "missing": "Verdict: not judged (missing input)"}
    secs = {x["id"]: x for x in v["sections"]}
    assert list(secs) == list(s["verdicts"]) and len(secs) == 7
    for sid, result in s["verdicts"].items():
        assert secs[sid]["verdict"].startswith(words[result]), (sid, secs[sid]["verdict"])
        assert secs[sid]["verdict"] in v["text"]
    assert s["verdicts"]["speed"] == "fail"         # the fixture's band comparison fails (see test_report)
    # provenance once for the report: one inputs line per section, the inputs with their checksums
    # and the command once at the end, shorter than one printed page (A4 at 96 px/in: 1123 px)
    assert [x["provenance"] for x in secs.values()] == [1] * 7
    assert v["text"].count("command (from the folder") == 1
    from labkit.analysis.report.provenance import sha256

    assert v["text"].count(sha256(inputs["fit"])) == v["text"].count(sha256(inputs["sweep"])) == 1
    assert v["provenance_box"] is not None and v["provenance_box"]["h"] < 1000, v["provenance_box"]
    # printing: the print style sheet starts each of the 7 sections on a new page after the title page
    _, pages = print_to_pdf(Path(s["html"]), tmp_path / "browser")
    assert 8 <= pages <= 40, pages


def test_checker_catches_broken_page(tmp_path):
    """Positive control: a broken image and a console error are both seen."""
    assert CHROMIUM, "Chromium not found"
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><head><title>x</title></head><body><p>x</p>'
                    '<img src="data:image/png;base64,AAAA" alt="broken">'
                    '<img src="https://example.invalid/a.png" alt="remote">'
                    '<script>console.error("boom")</script></body></html>')
    v = open_in_browser(page, tmp_path / "browser")
    assert v["images"] == 2 and v["decoded"] == 0
    assert any("boom" in e for e in v["errors"])
    assert any("boom" in line for line in v["console"])
