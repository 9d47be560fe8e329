#!/usr/bin/env python3
"""Run mypy on the installed layout of labkit (labkit, labkit.drivers, labkit.analysis).

Why this script exists: pyproject maps the top-level folders drivers/ and analysis/ into
the labkit namespace (setuptools ``package-dir``). The editable install reaches them through
a meta-path finder, which mypy does not consult, and ``mypy_path`` cannot rename a folder, so
``mypy labkit`` would not find ``labkit.drivers``. This script builds the installed tree out of
symlinks in a temporary folder (labkit/ with drivers/ and analysis/ linked in as
labkit/drivers and labkit/analysis), runs mypy there with the repository's pyproject
configuration, and rewrites the reported paths back to the source files
(labkit/drivers/x.py -> drivers/x.py). Nothing is copied, so it takes no build step.

Usage: ``python .ci/typecheck.py [extra mypy arguments]``; the exit code is mypy's.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def package_dirs(pyproject: Path) -> dict[str, Path]:
    """Package name -> source folder, for every package in pyproject's ``packages`` list."""
    table = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]
    mapping: dict[str, str] = table.get("package-dir", {})
    out: dict[str, Path] = {}
    for name in table["packages"]:
        # The longest mapped prefix decides where a package lives (setuptools' rule).
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            prefix = ".".join(parts[:cut])
            if prefix in mapping:
                out[name] = ROOT / mapping[prefix] / Path(*parts[cut:])
                break
        else:
            out[name] = ROOT / Path(*parts)
    return out


def build_tree(dest: Path, packages: dict[str, Path]) -> None:
    """Recreate the installed package tree under ``dest``: real folders, symlinked modules."""
    for name, src in sorted(packages.items()):
        pkg_dir = dest / Path(*name.split("."))
        pkg_dir.mkdir(parents=True, exist_ok=True)
        for entry in src.iterdir():
            if entry.suffix in (".py", ".pyi") or entry.name == "py.typed":
                os.symlink(entry, pkg_dir / entry.name)


def source_path(reported: str, packages: dict[str, Path]) -> str:
    """Map a path mypy reports inside the tree back to the file in the repository."""
    module_dir, _, filename = reported.rpartition("/")
    name = module_dir.replace("/", ".")
    if name in packages:
        return os.path.relpath(packages[name] / filename, Path.cwd())
    return reported


def main(argv: list[str]) -> int:
    packages = package_dirs(ROOT / "pyproject.toml")
    with tempfile.TemporaryDirectory(prefix="labkit-mypy-") as tmp:
        build_tree(Path(tmp), packages)
        cmd = [
            sys.executable, "-m", "mypy",
            "--config-file", str(ROOT / "pyproject.toml"),
            "--cache-dir", str(ROOT / ".mypy_cache"),
            "-p", "labkit", *argv,
        ]
        proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, check=False)
    line_re = re.compile(r"^([\w/.]+\.pyi?)(:.*)$")
    for line in (proc.stdout + proc.stderr).splitlines():
        m = line_re.match(line)
        print(source_path(m.group(1), packages) + m.group(2) if m else line)
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
