"""One reader per file kind: HDF5 files are opened for reading only in the reader layer.

Every module of labkit, labkit.analysis and labkit.drivers is parsed (AST, no import), and
every call that opens an HDF5 file is found: ``h5py.File(...)`` and labkit's ``open_h5(...)``,
with their mode (second argument or ``mode=``; both default to ``"r"``). A read (mode ``"r"``)
is allowed only in the reader layer (``labkit/files/``, which holds one reader per kind, and
``labkit/h5io.py``, the primitive they share) and in the few places listed in :data:`EXEMPT`
with the reason. Writes (``"w"``, ``"r+"``, ``"a"``) are the producers' own business.

:data:`PENDING` lists second readers of a kind that exist today; the test fails on any read
not allowed here AND on any PENDING entry that no longer reads, so that list can only shrink.
"""
from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("labkit", "analysis", "drivers")
READER_LAYER = ("labkit/files/", "labkit/h5io.py")

#: Reads that are not a second reader of a kind: module -> why.
EXEMPT: dict[str, str] = {
    "labkit/commands/info.py": "lists any HDF5 file's groups and datasets (no kind); content via labkit.open",
    "labkit/experiments/runfile.py": "the run file's writer checks kind and schema before it appends (--resume)",
}

#: Second readers of a kind that exist today: module -> the kind and where its reader is.
PENDING: dict[str, str] = {}


def _modules() -> Iterator[Path]:
    for pkg in PACKAGES:
        yield from sorted((ROOT / pkg).rglob("*.py"))


def _mode(call: ast.Call) -> str | None:
    """The mode string of an open call ("r" by default; None when not a constant)."""
    arg = call.args[1] if len(call.args) > 1 else next((k.value for k in call.keywords if k.arg == "mode"), None)
    if arg is None:
        return "r"
    return arg.value if isinstance(arg, ast.Constant) and isinstance(arg.value, str) else None


def _is_open(call: ast.Call) -> bool:
    f = call.func
    if isinstance(f, ast.Attribute):
        return f.attr == "File" and isinstance(f.value, ast.Name) and f.value.id == "h5py" or f.attr == "open_h5"
    return isinstance(f, ast.Name) and f.id == "open_h5"


def hdf5_reads(source: str) -> list[int]:
    """Line numbers of the calls in ``source`` that open an HDF5 file for reading."""
    tree = ast.parse(source)
    return [n.lineno for n in ast.walk(tree)
            if isinstance(n, ast.Call) and _is_open(n) and _mode(n) in ("r", None)]


def test_the_scanner_finds_reads_and_ignores_writes() -> None:
    src = ("import h5py\nfrom labkit.h5io import open_h5\n"
           "with h5py.File(p) as f: pass\n"            # 3: read by default
           "with h5py.File(p, 'w') as f: pass\n"       # 4: write
           "with open_h5(p, kind='track') as f: pass\n"  # 5: read
           "with h5py.File(p, mode='r+') as f: pass\n"  # 6: append
           "with h5py.File(p, mode) as f: pass\n")      # 7: unknown mode: counted as a read
    assert hdf5_reads(src) == [3, 5, 7]


def test_hdf5_files_are_read_only_in_the_reader_layer() -> None:
    found: dict[str, list[int]] = {}
    for path in _modules():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(READER_LAYER):
            continue
        lines = hdf5_reads(path.read_text(encoding="utf-8"))
        if lines:
            found[rel] = lines
    new = {m: lines for m, lines in found.items() if m not in EXEMPT and m not in PENDING}
    assert not new, ("HDF5 read outside labkit/files (add a reader there, or say why in EXEMPT): "
                     + "; ".join(f"{m} line(s) {lines}" for m, lines in new.items()))
    gone = sorted(set(PENDING) - set(found))
    assert not gone, f"no longer a second reader: remove from PENDING: {gone}"
    stale = sorted(set(EXEMPT) - set(found))
    assert not stale, f"no longer reads HDF5: remove from EXEMPT: {stale}"


def test_the_reader_layer_reads_every_kind_labkit_writes() -> None:
    """Each HDF5 kind labkit writes has its reader in labkit.files (``labkit.open`` dispatches on it)."""
    from labkit.files import H5_KINDS

    source = (ROOT / "labkit" / "files" / "__init__.py").read_text(encoding="utf-8")
    for kind in H5_KINDS:
        assert f'"{kind}"' in source.split("def open_file", 1)[1], kind


def test_every_kind_labkit_stamps_is_one_labkit_open_reads() -> None:
    """Every ``stamp(f, "<kind>")`` in the tree (the writers' kind attribute) is a kind of H5_KINDS."""
    from labkit.files import H5_KINDS

    stamped = set()
    for path in _modules():
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(n, ast.Call) and getattr(n.func, "id", getattr(n.func, "attr", "")) == "stamp" \
                    and len(n.args) > 1 and isinstance(n.args[1], ast.Constant):
                stamped.add(n.args[1].value)
    assert {"sim_sweep", "sim_regime_map", "track"} <= stamped, stamped      # the scanner finds the writers
    assert stamped <= set(H5_KINDS), f"written but not read by labkit.open: {sorted(stamped - set(H5_KINDS))}"
