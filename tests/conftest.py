"""Fixtures for every test; helpers live in ``clihelpers`` (importable by name)."""
from __future__ import annotations

import pytest

from clihelpers import last_json, run_cli  # noqa: F401  (re-exported for older imports)


@pytest.fixture
def cli():
    return run_cli
