"""Open the report in a real headless Chromium (Debian's, installed by .ci/run): it renders,
every figure decodes (naturalWidth > 0), and the page logs no console message or error.

No extra Python dependency: Chromium's ``--dump-dom`` returns the DOM after the load
event, with the verdict of a small check script written into it; console messages are
read from Chromium's own log (``--enable-logging=stderr``, lines with ``CONSOLE``);
``--screenshot`` proves something was painted. The check script goes into a *copy* of
the report (the report itself holds no script). External hosts are unresolvable
(``--host-resolver-rules``), so a page that needed the network would fail here.
"""
from __future__ import annotations

import json
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
  var v = {images: imgs.length,
           decoded: imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length,
           widths: imgs.map(function (i) { return i.naturalWidth; }),
           sections: document.querySelectorAll('section').length,
           height: document.body.scrollHeight, errors: window.__errs};
  var p = document.createElement('pre'); p.id = 'labkit-verdict'; p.textContent = JSON.stringify(v);
  document.body.appendChild(p);
});
</script>"""


def _chromium(args: list[str], profile: Path) -> subprocess.CompletedProcess:
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions",
           "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={profile}",
           "--enable-logging=stderr", "--v=0", "--virtual-time-budget=10000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


def open_in_browser(html_path: Path, work: Path) -> dict:
    """Load a page with the check script; return the verdict plus console lines and a screenshot."""
    work.mkdir(parents=True, exist_ok=True)
    text = html_path.read_text(encoding="utf-8")
    probe = work / "probe.html"
    probe.write_text(text.replace("<head>", "<head>" + CHECK, 1), encoding="utf-8")
    assert CHECK in probe.read_text()
    proc = _chromium(["--dump-dom", probe.as_uri()], work / "profile")
    m = re.search(r'<pre id="labkit-verdict">(.*?)</pre>', proc.stdout, re.S)
    assert m, f"no verdict in the DOM (rc {proc.returncode}); stderr:\n{proc.stderr[-2000:]}"
    verdict = json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<")
                         .replace("&gt;", ">"))
    verdict["console"] = [ln for ln in proc.stderr.splitlines() if "CONSOLE" in ln]
    shot = work / "shot.png"
    proc2 = _chromium([f"--screenshot={shot}", "--window-size=1200,2000", html_path.as_uri()], work / "profile2")
    assert shot.is_file(), proc2.stderr[-2000:]
    verdict["screenshot"] = shot
    return verdict


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
    assert v["images"] == len(s["figures"]) == 7
    assert v["decoded"] == v["images"], v["widths"]
    assert min(v["widths"]) >= 300                        # real figures, not 1-px placeholders
    assert v["sections"] == 5 and v["height"] > 2000
    assert v["errors"] == [] and v["console"] == [], (v["errors"], v["console"])
    img = _pixels(v["screenshot"])
    assert img.shape[0] >= 1000 and img[..., :3].std() > 0.05    # painted: not a blank page


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
