"""One output policy for every labkit command that writes files.

The rules (``docs/file-formats.md``, "Outputs"):

* **Checked before any work starts.** A command lists *every* file it will
  write -- the main output and its sidecars (CSV, PNG, overlay video, JSON,
  per-point videos) -- and calls :func:`check_outputs` before it opens an
  instrument, runs a simulation or tracks a frame.
* **Never overwritten silently.** An existing output is refused (exit 2) with
  a hint: ``--force`` replaces it; ``--resume`` continues it where that applies.
* **Replaced atomically with --force.** :func:`atomic_output` hands the
  writer a temporary name in the same folder (same suffix, so writers that
  infer a format from the suffix still work) and renames it over the old
  file with :func:`os.replace` only once the writer returned. A crash or an
  error mid-write leaves the old file as it was (and removes the partial one).
  A command that writes several files (a track and its CSV and PNG, a
  parameter file and its JSON) uses :func:`atomic_outputs`: every file is
  written to its temporary name first, and the renames happen only once all
  writers returned, so a failure in the last writer still leaves every old
  file in place. A command that fills a folder uses :func:`staged_dir`.
* **Missing folders.** The folder that will hold an output file must exist;
  labkit does not create it (a mistyped folder is far more often a typo than
  a wish). A command whose ``--out`` *is* a folder (``report``, ``demo``,
  ``simulate scenario``, ``sample-data``) creates that one folder, but not its
  parents.
"""
from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from labkit.errors import InputError

__all__ = ["check_outputs", "check_output_dir", "atomic_output", "atomic_outputs", "process_alive",
           "remove_stale_temporaries", "staged_dir", "temp_name"]


def _hint(resume: bool) -> str:
    return ("use --force (force=True from Python) to replace it"
            + (", or --resume to continue it" if resume else ""))


def check_outputs(paths: Iterable[str | os.PathLike[str] | None], *, force: bool = False,
                  key: str = "--out", resume: bool = False,
                  suffixes: Iterable[str] | None = None) -> list[Path]:
    """Check files a command is about to write; call before any work starts.

    Parameters
    ----------
    paths:
        Every file the command will write (``None`` entries are skipped, so
        optional outputs can be passed as they are).
    force:
        The command's ``--force``: existing files may be replaced.
    key:
        The option named in messages (``"--out"``, ``"--overlay"``).
    resume:
        Mention ``--resume`` in the hint (the command can continue the file).
    suffixes:
        Accepted suffixes (lower case, with the dot), e.g. ``(".mkv", ".avi")``.

    Returns
    -------
    list of Path
        The paths (``None`` entries dropped), for the command to use.

    Raises
    ------
    InputError
        (exit 2) an output exists and ``force`` is false; its folder does not
        exist or is not a folder; the path is a folder; a suffix is not accepted;
        the same file is named twice.
    """
    out: list[Path] = []
    allowed = tuple(s.lower() for s in suffixes) if suffixes is not None else None
    for p in paths:
        if p is None:
            continue
        path = Path(p)
        if allowed is not None and path.suffix.lower() not in allowed:
            raise InputError(f"unsupported file type {path.suffix or '(none)'!r}", file=path, key=key,
                             expected=" or ".join(allowed))
        if path.is_dir():
            raise InputError("is a folder", file=path, key=key, expected="a file name")
        parent = path.resolve().parent
        if not parent.is_dir():
            raise InputError("the output's folder does not exist (labkit does not create it)",
                             file=path, key=key, expected=f"an existing folder {parent}")
        remove_stale_temporaries(parent)
        if path.exists() and not force:
            raise InputError(f"already exists; {_hint(resume)}", file=path, key=key)
        if any(q.resolve() == path.resolve() for q in out):
            raise InputError("named twice among the outputs", file=path, key=key)
        out.append(path)
    return out


_TEMPORARY = re.compile(r"^\.(?:staging\.(\d+)\.|.*\.(\d+)\.[^.]+\.partial)")


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files and staging folders a killed labkit left in ``folder``.

    Only those whose process (the PID in the name, see :func:`temp_name`, :func:`staged_dir`)
    has ended: another command writing there now keeps its own. Returns what was removed.
    """
    import shutil

    gone: list[Path] = []
    folder = Path(folder)
    if not folder.is_dir():
        return gone
    for p in folder.iterdir():
        m = _TEMPORARY.match(p.name)
        if not m or process_alive(int(m.group(1) or m.group(2))):
            continue
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                p.unlink()
        gone.append(p)
    return gone


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` still runs (another user's counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def check_output_dir(path: str | os.PathLike[str], *, force: bool = False, key: str = "--out",
                     names: Iterable[str] = ()) -> Path:
    """Check an output *folder* (created if missing; its parent must exist).

    With ``names`` (the files the command will write in it), any of them
    already present is refused unless ``force``; without ``names``, a
    non-empty folder is refused unless ``force``.
    """
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise InputError("is a file, not a folder", file=d, key=key, expected="a folder")
    if not d.resolve().parent.is_dir():
        raise InputError("the folder that would hold it does not exist (labkit creates only the output "
                         "folder itself)", file=d, key=key, expected=f"an existing folder {d.resolve().parent}")
    remove_stale_temporaries(d)
    if d.is_dir() and not force:
        names = list(names)
        clash = [n for n in names if (d / n).exists()] if names else sorted(p.name for p in d.iterdir())
        if clash:
            shown = ", ".join(clash[:3]) + (" ..." if len(clash) > 3 else "")
            raise InputError(f"already holds {shown}; {_hint(False)}", file=d, key=key)
    return d


def temp_name(path: str | os.PathLike[str]) -> Path:
    """A fresh temporary file name beside ``path`` with the same suffix (the file is not left open)."""
    path = Path(path)
    # the PID in the name: a later command removes what a killed one left (remove_stale_temporaries)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.{os.getpid()}.", suffix=f".partial{path.suffix}",
                                dir=path.resolve().parent)
    os.close(fd)
    # mkstemp makes the file private (0600); give it the mode a plain open() would have
    os.chmod(name, 0o666 & ~_umask())
    return Path(name)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Write ``path`` through a temporary name in the same folder, renamed over it at the end.

    Use as ``with atomic_output(out) as tmp: writer(tmp)``. On any exception
    (including KeyboardInterrupt) the temporary file is removed and ``path``
    is left exactly as it was; on success :func:`os.replace` swaps it in,
    which on POSIX is atomic: a reader (or a crash) sees the old file or the
    new one, never neither. The temporary file exists, empty, when the block
    starts (writers that refuse to overwrite must be given ``force``-style
    freedom, e.g. ``h5py.File(tmp, "w")``).
    """
    path = Path(path)
    tmp = temp_name(path)
    try:
        yield tmp
        if not tmp.exists():
            raise InputError("the writer did not produce the file", file=path)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_outputs(paths: Iterable[str | os.PathLike[str]]) -> Iterator[list[Path]]:
    """Several outputs replaced together: temporaries for all, renamed only once every writer returned.

    ``with atomic_outputs([h5, csv, png]) as (t_h5, t_csv, t_png): ...``. On any exception every
    temporary file is removed and every target left as it was. The renames at the end are one
    :func:`os.replace` each, in order; between two of them (microseconds) a power cut could
    leave a mix of old and new files, never a missing or partial one.
    """
    targets = [Path(p) for p in paths]
    temps: list[Path] = []
    try:
        for t in targets:
            temps.append(temp_name(t))
        yield list(temps)
        for t, tmp in zip(targets, temps):
            if not tmp.exists():
                raise InputError("the writer did not produce the file", file=t)
        for t, tmp in zip(targets, temps):
            os.replace(tmp, t)
    except BaseException:
        for tmp in temps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise


@contextlib.contextmanager
def staged_dir(out: str | os.PathLike[str], names: Iterable[str]) -> Iterator[Path]:
    """Fill folder ``out`` through a hidden staging folder inside it.

    The writer writes the files ``names`` into the yielded folder; once it returned, each is
    moved over ``out/<name>`` with :func:`os.replace` (same file system: atomic per file) and
    the staging folder removed. On any exception the staging folder is removed and ``out``
    is left exactly as it was. ``out`` must exist.
    """
    import shutil

    out = Path(out)
    stage = Path(tempfile.mkdtemp(prefix=f".staging.{os.getpid()}.", dir=out))
    try:
        yield stage
        names = list(names)
        missing = [n for n in names if not (stage / n).exists()]
        if missing:
            raise InputError(f"the writer did not produce {', '.join(missing)}", file=out)
        for n in names:
            os.replace(stage / n, out / n)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
