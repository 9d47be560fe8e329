"""Headless Chromium for the live-view tests: Debian's ``/usr/bin/chromium`` driven by Playwright
(never a downloaded browser), every console message and page error recorded."""
from __future__ import annotations

CHROMIUM = "/usr/bin/chromium"


class Browser:
    """A headless Chromium; :meth:`page` opens a URL in a new page that records its console."""

    def __init__(self, pw) -> None:
        self.browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        self.console: list[str] = []

    def page(self, url: str, height: int = 900):
        page = self.browser.new_page(viewport={"width": 1280, "height": height})
        page.on("console", lambda m: self.console.append(f"{m.type}: {m.text}"))
        page.on("pageerror", lambda e: self.console.append(f"pageerror: {e}"))
        page.goto(url)
        return page

    def close(self) -> None:
        self.browser.close()
