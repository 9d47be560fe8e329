"""docs/python-api.md runs: every ```python block, in order, in one namespace, from a scratch folder.

The scratch folder links ``sample_data`` to the repository's (read only: the guide writes
its own files, robot.toml, frf.png, ..., into a temporary folder of its own, ``work``); the
guide runs twice, as a reader would run it again. The blocks' own asserts
and prints are the checks; a few outcomes are checked here as well.
"""
from __future__ import annotations

import hashlib
import os
import re

import pytest

from clihelpers import REPO

pytest.importorskip("xarray", reason="xarray is in the test extra: pip install -e '.[test]'")

DOC = REPO / "docs" / "python-api.md"
FILE_FORMATS = REPO / "docs" / "file-formats.md"


def python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)


def _run_guide(blocks: list[str]) -> dict[str, object]:
    ns: dict[str, object] = {"__name__": "python_api_guide"}
    for i, block in enumerate(blocks, 1):
        try:
            exec(compile(block, f"{DOC.name}[block {i}]", "exec"), ns)
        except Exception as exc:  # pragma: no cover - the failure message is the point
            raise AssertionError(f"{DOC.name} block {i} failed: {exc!r}\n{block}") from exc
    return ns


def test_the_python_api_guide_runs_twice_writing_only_into_its_own_folder(tmp_path, monkeypatch, capsys):
    blocks = python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) >= 8, "the guide lost its code blocks"
    assert all("doctest: +SKIP" not in b for b in blocks)
    sample = REPO / "sample_data"
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sample.iterdir() if p.is_file()}
    os.symlink(sample, tmp_path / "sample_data")
    monkeypatch.chdir(tmp_path)
    works = []
    for _ in range(2):                  # a reader runs it again: it must work again
        ns = _run_guide(blocks)
        out = capsys.readouterr().out
        # what the guide promises its reader
        assert "run_inchip complete" in out
        assert "refused:" in out and "force=True" in out
        work = ns["work"]
        for name in ("frf.png", "speed.png", "robot.toml", "robot.fit.h5", "sim_240hz.h5"):
            assert (work / name).is_file(), name         # type: ignore[operator]
        works.append(work)
    assert works[0] != works[1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sample_data"]      # nothing in the current folder
    assert {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sample.iterdir() if p.is_file()} == before
    import matplotlib.pyplot as plt

    plt.close("all")


def test_file_formats_doc_names_every_kind_and_the_current_version():
    from labkit.files import H5_KINDS
    from labkit.h5io import READS_SCHEMA_VERSION, SCHEMA_VERSION

    text = FILE_FORMATS.read_text(encoding="utf-8")
    for kind in H5_KINDS:
        assert f"`{kind}`" in text, kind
    assert f"**schema version {SCHEMA_VERSION}**" in text
    assert READS_SCHEMA_VERSION == SCHEMA_VERSION
    rows = re.findall(r"^\| (\d+) \|", text, re.M)
    assert [int(r) for r in rows] == list(range(SCHEMA_VERSION + 1))
