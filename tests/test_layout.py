"""Packaging: one import root, labkit.

pyproject maps the top-level folders drivers/ and analysis/ into the labkit namespace
(setuptools ``package-dir``) with an explicit ``packages`` list. These tests check the list
against the folders, build a real wheel from a copy of the sources, and install it
(non-editable) into a temporary target to check what a user gets: ``labkit.drivers`` and
``labkit.analysis``, and no top-level ``drivers`` or ``analysis``.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SETUPTOOLS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
PACKAGE_DIR: dict[str, str] = SETUPTOOLS["package-dir"]
PACKAGES: list[str] = SETUPTOOLS["packages"]


def mapped_packages() -> dict[str, Path]:
    """Every folder with an ``__init__.py`` under a mapped folder, by its installed name."""
    found: dict[str, Path] = {}
    for pkg, folder in PACKAGE_DIR.items():
        base = ROOT / folder
        for init in base.rglob("__init__.py"):
            rel = init.parent.relative_to(base)
            name = ".".join([pkg, *rel.parts])
            # A sub-folder that another mapping owns is named by that mapping (none today):
            # the deepest mapped folder containing it decides.
            owners = [p for p in PACKAGE_DIR if (ROOT / PACKAGE_DIR[p]) in (init.parent, *init.parents)]
            if max(owners, key=lambda p: len((ROOT / PACKAGE_DIR[p]).parts)) == pkg:
                found[name] = init.parent
    return found


def source_modules() -> set[str]:
    """Every ``.py`` file of the packages, as its path inside an installed tree."""
    out: set[str] = set()
    for name, folder in mapped_packages().items():
        for f in folder.glob("*.py"):
            out.add("/".join(name.split(".")) + "/" + f.name)
    return out


def test_every_package_folder_is_listed():
    folders = mapped_packages()
    missing = sorted(set(folders) - set(PACKAGES))
    assert not missing, f"pyproject.toml [tool.setuptools] packages lacks {missing} (folders with __init__.py)"
    stale = sorted(set(PACKAGES) - set(folders))
    assert not stale, f"pyproject.toml [tool.setuptools] packages lists {stale}, which have no folder with __init__.py"


def test_package_dir_maps_the_design_cards_folders():
    assert PACKAGE_DIR == {"labkit": "labkit", "labkit.drivers": "drivers", "labkit.analysis": "analysis"}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel built (no isolation, no network) from a copy of the sources."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    for folder in sorted(set(PACKAGE_DIR.values())):
        shutil.copytree(ROOT / folder, src / folder, ignore=ignore)
    out = tmp / "dist"
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                           "--no-index", "-q", "-w", str(out), str(src)],
                          capture_output=True, text=True, timeout=240, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    wheels = list(out.glob("labkit-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_has_one_import_root(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    tops = {n.split("/")[0] for n in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"labkit"}
    assert "labkit/drivers/__init__.py" in names
    assert "labkit/analysis/__init__.py" in names
    assert "labkit/analysis/modal/__init__.py" in names
    assert not any(n.startswith(("drivers/", "analysis/")) for n in names)
    missing = sorted(source_modules() - set(names))
    assert not missing, f"source modules missing from the wheel: {missing}"


def _python(code: str, target: Path, cwd: Path, *, no_site: bool) -> subprocess.CompletedProcess[str]:
    # The target alone on PYTHONPATH; cwd is an empty folder so sys.path[0] holds nothing.
    # With -S the venv's site-packages (and the editable install's finder in it) is not loaded:
    # the interpreter sees only the installed wheel, as in a fresh environment.
    flags = ["-S"] if no_site else []
    env = {"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run([sys.executable, *flags, "-c", code], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=60, check=False)


def test_installed_wheel_imports_labkit_analysis_not_analysis(wheel, tmp_path):
    target = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q",
                           "--target", str(target), str(wheel)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert not (target / "analysis").exists() and not (target / "drivers").exists()
    cwd = tmp_path / "empty"
    cwd.mkdir()

    for top in ("analysis", "drivers"):
        r = _python(f"import {top}", target, cwd, no_site=True)
        assert r.returncode != 0 and f"No module named '{top}'" in r.stderr, r.stderr

    # (Only the packages whose __init__ needs nothing outside the standard library.)
    r = _python("import labkit.analysis, labkit.drivers;"
                "print(labkit.analysis.__file__); print(labkit.drivers.__file__)", target, cwd, no_site=True)
    assert r.returncode == 0, r.stderr
    for line in r.stdout.split():
        assert Path(line).is_relative_to(target), line

    # With the venv's site-packages (numpy and the rest), a real module imports from the wheel,
    # ahead of the editable install, and a top-level "analysis" still does not exist.
    r = _python("import labkit.analysis.frf as m, labkit.drivers.base as d, labkit.analysis.modal as mm\n"
                "print(m.__file__); print(d.__file__); print(mm.__file__)\n"
                "try:\n    import analysis\nexcept ModuleNotFoundError:\n    print('no-analysis')",
                target, cwd, no_site=False)
    assert r.returncode == 0, r.stderr
    *files, verdict = r.stdout.split()
    assert verdict == "no-analysis"
    for line in files:
        assert Path(line).is_relative_to(target), line
