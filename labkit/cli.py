"""The ``labkit`` command line: one entry point, subcommands discovered in :mod:`labkit.commands`.

Contract (``docs/architecture.md``): every subcommand accepts ``--json``
(then the last line of standard output is one JSON object), ``--quiet`` (no
progress bar), and exits 0 on success, 2 on bad input, 3 on an instrument or
transport fault, 4 when a drive output could not be confirmed off (with a
banner saying which and what to do), 130 when interrupted (SIGINT, SIGTERM,
SIGHUP or SIGQUIT), always with a one-line message on standard error.
"""
from __future__ import annotations

import argparse
import importlib
import json
import logging
import pkgutil
import sys
from collections.abc import Mapping, Sequence
from types import ModuleType
from typing import Any

from labkit import __version__
from labkit.errors import EXIT_INPUT, EXIT_INTERRUPTED, DriveNotOff, InputError, Interrupted, LabkitError
from labkit.experiments.safety import check_stop, install_stop_handlers, restore_handlers, stop_handled


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line and exit 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def common_parser() -> argparse.ArgumentParser:
    """The options every subcommand (and nested subcommand) takes."""
    common = _Parser(add_help=False)
    common.add_argument("--json", action="store_true",
                        help="print one JSON summary object as the last line of stdout")
    common.add_argument("--quiet", action="store_true", help="no progress bar")
    common.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what labkit does on stderr, the shutdown path included (-vv: more)")
    return common


class _StderrHandler(logging.Handler):
    """Writes to whatever ``sys.stderr`` is at the time (a test's captured stream, a redirected one)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
        except Exception:       # a closed stderr must not break a shutdown
            pass


def _configure_logging(verbose: int) -> None:
    """``-v``: INFO lines of labkit's loggers on stderr; ``-vv``: DEBUG; none: warnings only (stderr)."""
    level = logging.WARNING if not verbose else logging.INFO if verbose == 1 else logging.DEBUG
    root = logging.getLogger("labkit")
    root.setLevel(level)
    if not any(isinstance(h, _StderrHandler) for h in root.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("labkit %(name)s: %(message)s"))
        root.addHandler(handler)


def _command_modules() -> list[ModuleType]:
    import labkit.commands as pkg

    mods = []
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"labkit.commands.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return mods


def build_parser() -> argparse.ArgumentParser:
    common = common_parser()
    parser = _Parser(prog="labkit", description="Vibration-lab toolkit for PZT microrobots.")
    parser.add_argument("--version", action="version", version=f"labkit {__version__}")
    # typed as plain ArgumentParser: the shared parent parser is one (mypy infers _Parser otherwise)
    sub: argparse._SubParsersAction[argparse.ArgumentParser] = parser.add_subparsers(
        dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=getattr(mod, "HELP", ""), parents=[common],
                           description=getattr(mod, "HELP", None))
        mod.add_arguments(p, common)
        p.set_defaults(_run=mod.run)
    return parser


def emit_json(summary: Mapping[str, object]) -> None:
    """Print the summary as one JSON line (NaN becomes null so any parser reads it)."""
    from labkit.jsonutil import to_jsonable  # imported late: numpy is slow to import

    print(json.dumps(to_jsonable(summary, finite=True)), flush=True)



def main(argv: Sequence[str] | None = None) -> int:
    """Run ``labkit``; returns (and exits with) the process exit code.

    The stop signals (SIGINT, SIGTERM, SIGHUP, SIGQUIT) are handled from the first
    line on, before the subcommands are imported: each raises, so the drive is
    turned off and the run file finished exactly as for Ctrl-C (exit 130). A
    shell's background job starts with SIGINT and SIGQUIT ignored; this undoes it.
    One that arrived while ``labkit`` itself was being imported (:func:`labkit.early_signals`)
    stops the command before it starts. Once the command has ended (any way), further
    stop signals are only noted: the exit code stays what the command earned (a second
    Ctrl-C while the first is reported exits 130, not with a traceback), and a stop that
    arrives after a run's file says ``complete`` exits 0 saying so.
    """
    previous: dict[int, Any] = {}
    late: list[int] = []
    try:
        code = _main(argv, previous, late)
    except (KeyboardInterrupt, Interrupted) as exc:      # a second stop while the first was reported
        _hold(late)
        stop_handled()
        code = _stopped(None, exc)
    finally:
        _hold(late)
        if argv is not None:        # called in-process (tests, scripts): give the handlers back
            restore_handlers(previous)
    return _exit(code, argv)


def _main(argv: Sequence[str] | None, previous: dict[int, Any], late: list[int]) -> int:
    args: argparse.Namespace | None = None
    try:
        install_stop_handlers(previous)     # inside the try: a signal during it is handled too
        check_stop()            # one that arrived while labkit was imported (labkit.early_signals)
        parser = build_parser()
        args = parser.parse_args(argv)
        _configure_logging(getattr(args, "verbose", 0))
        summary = args._run(args)
        _hold(late)             # the command is done: a stop from here on does not undo it
        check_stop()            # a stop signal whose exception was dropped still stops (exit 130)
        if args.json:
            emit_json(summary if isinstance(summary, dict) else {"result": summary})
    except DriveNotOff as exc:
        _hold(late)
        _banner(exc)
        _fail(args, str(exc), exc.exit_code)
        return exc.exit_code
    except LabkitError as exc:
        _hold(late)
        _fail(args, str(exc), exc.exit_code)
        return exc.exit_code
    except BrokenPipeError:
        # the reader of standard output went away (``labkit info FILE | head``): not an error of
        # ours; nothing more can be printed, and Python's final flush must not complain either
        _hold(late)
        _quiet_stdout()
        return 0
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError) as exc:
        # a path the person gave (an --out folder that does not exist, a read-only place):
        # bad input, not a crash
        _hold(late)
        where = f"{exc.filename}: " if exc.filename else ""
        _fail(args, f"{where}{exc.strerror or exc}", EXIT_INPUT)
        return EXIT_INPUT
    except (KeyboardInterrupt, Interrupted) as exc:
        _hold(late)
        stop_handled()
        return _stopped(args, exc)
    except Exception:
        # a stop signal's exception turned into another one on its way (raised inside an extension
        # module's import, numpy reports an ImportError): the stop it was
        _hold(late)
        try:
            check_stop()
        except (KeyboardInterrupt, Interrupted) as stop:
            stop_handled()
            return _stopped(args, stop)
        raise
    return 0


def _stopped(args: argparse.Namespace | None, exc: BaseException) -> int:
    """Report a stop signal: exit 130, or 0 when it came after the run's file said complete."""
    from labkit.experiments.safety import completed_run

    name = exc.signame if isinstance(exc, Interrupted) else "SIGINT"
    done = completed_run() if getattr(args, "command", None) in ("sweep", "shaker") else None
    if done is not None:
        _say(f"labkit: {name} arrived after the run had completed; {done} says complete")
        if getattr(args, "json", False):
            try:
                emit_json({"ok": True, "status": "complete", "file": done, "signal_after_completion": name})
            except (OSError, ValueError):
                pass
        return 0
    _fail(args, f"interrupted by {name}; outputs were turned off", EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


def _hold(late: list[int]) -> None:
    """From now on a stop signal is only noted in ``late`` (the command has ended)."""
    import signal
    import threading

    from labkit.experiments.safety import STOP_SIGNALS

    if threading.current_thread() is not threading.main_thread():
        return
    for s in STOP_SIGNALS:
        signal.signal(s, lambda signum, frame: late.append(signum))


def _banner(exc: DriveNotOff) -> None:
    """The unmissable console warning: which output may still be on, what to do, and why the run stopped."""
    bar = "!" * 78
    lines = [bar, f"!!  DRIVE MAY STILL BE ON: {exc.instrument} ({exc.where})",
             f"!!  the OFF command could not be confirmed: {exc.fault}",
             "!!  TURN THE GENERATOR OUTPUT OFF BY HAND NOW (its Output key, or unplug the amplifier),",
             f"!!  or run: labkit off {exc.config or 'CONFIG'}"]
    if exc.original:
        lines.append(f"!!  the run had stopped because: {exc.original}")
    lines.append(bar)
    _say("\n".join(lines))


def _quiet_stdout() -> None:
    """Point standard output at /dev/null (its reader closed the pipe)."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def _say(text: str) -> None:
    """Print to standard error; a vanished terminal (SIGHUP) must not turn a clean stop into a crash."""
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _fail(args: argparse.Namespace | None, message: str, code: int) -> None:
    command = getattr(args, "command", None)
    _say(f"labkit {command}: error: {message}" if command else f"labkit: error: {message}")
    if getattr(args, "json", False):
        try:
            emit_json({"ok": False, "exit_code": code, "error": message})
        except (OSError, ValueError):
            pass


def _exit(code: int, argv: Sequence[str] | None) -> int:
    if argv is None:  # called as the console script
        # Python's finalisation resets every handler it installed to the default, so a stop
        # signal arriving while the interpreter shuts down would kill the process (exit -N)
        # after its exit code was decided: the command has ended and reported; ignore them
        import signal

        from labkit.experiments.safety import STOP_SIGNALS

        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        if code == EXIT_INTERRUPTED:
            # CPython may still end a process whose KeyboardInterrupt labkit caught and reported
            # by killing itself with SIGINT after finalising (exit -2: its flag for an unhandled
            # KeyboardInterrupt, which such an exception can set on its way through code the
            # interpreter ran for an extension); seen for up to 1 in 4 ``labkit fit`` stopped in
            # their first second (tests/experiments/test_temporaries.py). Everything is closed and
            # reported by now: run the exit handlers, flush, and leave with the code earned.
            import atexit
            import os

            atexit._run_exitfuncs()
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (OSError, ValueError):
                    pass
            os._exit(code)
        sys.exit(code)
    return code


def require_file(path: str, what: str = "file") -> str:
    """Fail with exit 2 when an input file is missing (before any work starts)."""
    from pathlib import Path

    if not Path(path).is_file():
        raise InputError(f"no such {what}", file=path)
    return path


if __name__ == "__main__":  # pragma: no cover
    main()
