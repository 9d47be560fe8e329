"""The error types whose class decides the CLI's exit code.

=====================  ====  ==================================================
error                  exit  meaning
=====================  ====  ==================================================
:class:`InputError`    2     bad input: usage, config, parameter file, data file
:class:`LimitError`    2     a requested setting is outside a declared limit
:class:`InstrumentError` 3   an instrument or its transport failed
:class:`DriveNotOff`   4     a drive output could NOT be confirmed off: act at the bench
interrupt              130   SIGINT/SIGTERM/SIGHUP/SIGQUIT; outputs were turned off
=====================  ====  ==================================================

Drivers and analysis raise these; only :mod:`labkit.cli` turns them into exit
codes and one-line messages.
"""
from __future__ import annotations

from pathlib import Path

EXIT_OK = 0
EXIT_INPUT = 2
EXIT_INSTRUMENT = 3
EXIT_DRIVE_ON = 4
EXIT_INTERRUPTED = 130


class LabkitError(Exception):
    """Base of every error labkit reports to the person at the bench."""

    exit_code = 1


class InputError(LabkitError):
    """Bad input: names the file, the key and what was expected.

    Parameters
    ----------
    message:
        What was wrong.
    file:
        The file it was found in, if any.
    key:
        The key (dotted path for nested tables), if any.
    expected:
        What would have been accepted (``"a number in mg, > 0"``).
    """

    exit_code = EXIT_INPUT

    def __init__(self, message: str, *, file: str | Path | None = None,
                 key: str | None = None, expected: str | None = None) -> None:
        self.message = message
        self.file = None if file is None else str(file)
        self.key = key
        self.expected = expected
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = []
        if self.file:
            where.append(self.file)
        if self.key:
            where.append(f"key '{self.key}'")
        text = (": ".join(where) + ": " if where else "") + self.message
        if self.expected:
            text += f" (expected {self.expected})"
        return text


class ConfigError(InputError):
    """A config or parameter file is malformed or holds a bad value."""


class LimitError(InputError):
    """A setting would exceed a declared safety limit; nothing was sent.

    ``limit`` names the limit (``"pzt_max_v"``, ``"shaker stroke"``).
    """

    def __init__(self, message: str, *, limit: str, **kw) -> None:
        self.limit = limit
        super().__init__(message, **kw)


class InstrumentError(LabkitError):
    """An instrument or its transport failed: timeout, dropped link, garbled reply.

    Always names the instrument and the command that was in flight.
    """

    exit_code = EXIT_INSTRUMENT

    def __init__(self, message: str, *, instrument: str = "?", command: str | None = None) -> None:
        self.instrument = instrument
        self.command = command
        text = f"{instrument}: {message}"
        if command is not None:
            text += f" (command {command!r})"
        super().__init__(text)


class DriveNotOff(InstrumentError):
    """The OFF of an output that drives the PZT or the shaker could not be confirmed (exit 4).

    Parameters
    ----------
    instrument:
        The generator's role name (``funcgen``).
    where:
        Its model and resource, for the person who must find it.
    fault:
        The last error while sending the OFF.
    original:
        Why the run was stopping in the first place (its final status), if it was.
    config:
        The config file, for the suggested ``labkit off CONFIG``.
    """

    exit_code = EXIT_DRIVE_ON

    def __init__(self, instrument: str, where: str, fault: str, original: str = "", config: str = "") -> None:
        self.where = where
        self.fault = fault
        self.original = original
        self.config = config
        msg = (f"DRIVE OFF NOT CONFIRMED ({where}): {fault}; turn the generator output off by hand"
               + (f" (the run had stopped because: {original})" if original else ""))
        super().__init__(msg, instrument=instrument)


class Interrupted(BaseException):
    """Raised from a SIGTERM handler so cleanup runs as for Ctrl-C.

    A BaseException, like KeyboardInterrupt, so ``except Exception`` blocks in
    drivers cannot swallow it.
    """

    def __init__(self, signame: str = "SIGTERM") -> None:
        self.signame = signame
        super().__init__(signame)
