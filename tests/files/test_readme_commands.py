"""The README's two commands: what they run, and that the test command brings the browser it needs.

Running them is CI's job (`.ci/run` from a fresh clone); these checks keep the README, the
script and the browser test in step, so that "exactly as written" stays true.
"""
from __future__ import annotations

import re

from clihelpers import REPO

README = REPO / "README.md"
CI = REPO / ".ci" / "run"


def _commands() -> list[str]:
    block = re.search(r"```bash\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert block, "README.md starts with no ```bash block"
    return [ln.strip() for ln in block.group(1).splitlines() if ln.strip()]


def test_the_readme_has_the_two_commands():
    first, second = _commands()
    assert first == "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && labkit demo"
    assert second == "bash .ci/run"


def test_the_test_command_installs_chromium_before_the_tests_and_runs_pytest():
    text = CI.read_text(encoding="utf-8")
    install = text.index("apt-get install")
    assert "chromium" in text[install:install + 120]
    assert install < text.index('pip install -q -e ".[test]"') < text.rindex("python -m pytest -q")
    assert "rm -rf .venv" in text and "python3 -m venv .venv" in text        # a fresh environment


def test_the_browser_tests_fail_rather_than_skip_without_chromium():
    text = (REPO / "tests" / "report" / "test_browser.py").read_text(encoding="utf-8")
    assert "assert CHROMIUM" in text
    assert "skip" not in text.replace("skipped", "")


def test_the_readme_is_a_users_page_under_900_words():
    """A user's page, not a changelog: short, and no dated history (that is CHANGELOG.md's)."""
    import re as _re

    text = README.read_text(encoding="utf-8")
    assert len(text.split()) < 900, len(text.split())
    assert not _re.search(r"\b(January|February|March|April|May|June|July|August|September|October|"
                          r"November|December) 20\d\d\b|\bissue \d+\b", text)
    assert (REPO / "CHANGELOG.md").is_file()
