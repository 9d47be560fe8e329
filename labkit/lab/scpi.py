"""A small, generic SCPI instrument: a command table, an error queue, IEEE 488.2 blocks.

An instrument is a :class:`SimScpiInstrument` whose command table maps header
patterns written the way programming guides print them to handlers::

    self.add("[SOURce#:]FREQuency[:CW]", set=self._set_freq, query=self._freq)

* upper-case letters are the short form, the whole word is the long form
  (``FREQ`` or ``FREQUENCY``, any case); nothing in between is accepted,
  exactly as on the instruments (``FREQU`` -> ``-113,"Undefined header"``);
* ``#`` is a numeric suffix (``SOURce2``, ``CHANnel1``; omitted means 1);
* ``[...]`` is an optional part.

Compound lines (``FREQ 1000;VOLT 2``, ``:CHAN1:SCAL 0.5;OFFS 0.1``) follow the
SCPI path rule (SCPI 1999 vol. 1, 6.2.4): a command that does not start with
``:`` or ``*`` continues from the previous command's parent node; a leading
``:`` returns to the root; common commands (``*...``) leave the path alone;
every new line starts at the root. The leading ``:`` of a header is optional.
Header and data are separated by any white space (space or tab). Replies of
several queries on one line are joined by ``;``.

A numeric suffix beyond the instrument's count (``:CHAN5`` on a four-channel
scope) is ``-114,"Header suffix out of range"`` (SCPI 1999 vol. 2, 21.8.4).

The IEEE 488.2 status model (IEEE 488.2-1992, 11.4-11.5): the Standard Event
Status Register (``*ESR?``, cleared by reading it or ``*CLS``) with its enable
register (``*ESE``); the status byte (``*STB?``, not cleared by reading) with
its enable register (``*SRE``): bit 2 error queue not empty, bit 5 ESB
(``ESR & ESE``), bit 6 MSS (``STB & SRE``). ``*OPC`` sets ESR bit 0 once the
operations before it are complete; ``*OPC?`` answers ``1`` then. Every error
sets its ESR bit by class (-1xx command error bit 5, -2xx execution error bit
4, -3xx and positive device-dependent bit 3, -4xx query error bit 2); the
error queue (20 entries, read by ``SYSTem:ERRor?``, ``-350,"Queue overflow"``
replacing the last entry when full) is independent of the ESR: reading one
does not clear the other.
"""
from __future__ import annotations

import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: standard SCPI error messages used by the instruments
ERRORS = {
    -100: "Command error",
    -102: "Syntax error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -114: "Header suffix out of range",
    -221: "Settings conflict",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -230: "Data corrupt or stale",
    -300: "Device-specific error",
    -350: "Queue overflow",
    -410: "Query INTERRUPTED",
    -420: "Query UNTERMINATED",
}

#: headers remembered by :meth:`SimScpiInstrument.lookup`; longer headers than this are undefined
LOOKUP_CACHE = 4096
MAX_HEADER_CHARS = 256

#: ESR bits (IEEE 488.2-1992, 11.5.1.1)
ESR_OPC, ESR_QYE, ESR_DDE, ESR_EXE, ESR_CME = 1, 4, 8, 16, 32
#: status byte bits (IEEE 488.2-1992, 11.2; SCPI 1999 vol. 1, 9.1: bit 2 error/event queue)
STB_EAV, STB_ESB, STB_MSS = 4, 32, 64


def esr_bit(code: int) -> int:
    """The ESR bit an error of ``code`` sets (IEEE 488.2-1992, 11.5.1.1; SCPI 1999 vol. 2, 21.8)."""
    if -199 <= code <= -100:
        return ESR_CME
    if -299 <= code <= -200:
        return ESR_EXE
    if -499 <= code <= -400:
        return ESR_QYE
    if code != 0:
        return ESR_DDE   # -3xx and the device's own positive codes
    return 0


class ScpiError(Exception):
    """Raised by a handler: the code (and message) goes to the error queue."""

    def __init__(self, code: int, message: str | None = None) -> None:
        self.code = code
        self.message = message or ERRORS.get(code, "Error")
        super().__init__(f"{code},{self.message}")


@dataclass
class Call:
    """What a handler gets: the parameters, the numeric suffixes, the raw header."""

    params: list[str]
    suffixes: list[int]
    header: str
    query: bool

    def suffix(self, i: int = 0, default: int = 1) -> int:
        return self.suffixes[i] if i < len(self.suffixes) else default

    def one(self) -> str:
        """The single parameter (``-109`` when missing, ``-108`` when more)."""
        if not self.params:
            raise ScpiError(-109)
        if len(self.params) > 1:
            raise ScpiError(-108)
        return self.params[0]


_WORD = re.compile(r"([A-Z*]+)([a-z]*)(#?)")


def suffix_names(pattern: str) -> list[str]:
    """Short forms of the mnemonics that carry a ``#`` suffix, in order (``[SOURce#:]..`` -> ``["SOUR"]``)."""
    return [m.group(1) for m in _WORD.finditer(pattern) if m.group(3)]


def compile_pattern(pattern: str) -> re.Pattern[str]:
    """Turn ``[SOURce#:]FREQuency[:CW]`` into a regex on the upper-cased header (leading ``:`` optional)."""
    out = []
    pattern = pattern.lstrip(":")
    i = 0
    while i < len(pattern):
        c = pattern[i]
        if c == "[":
            out.append("(?:")
            i += 1
        elif c == "]":
            out.append(")?")
            i += 1
        elif c == ":":
            out.append(":")
            i += 1
        else:
            m = _WORD.match(pattern, i)
            if not m or m.end() == i:
                raise ValueError(f"bad SCPI pattern {pattern!r} at {i}")
            short, rest, suffix = m.group(1), m.group(2), m.group(3)
            alts = re.escape(short) if not rest else f"(?:{re.escape(short + rest.upper())}|{re.escape(short)})"
            out.append(alts + (r"(\d+)?" if suffix else ""))
            i = m.end()
    return re.compile(":?" + "".join(out))


@dataclass
class Command:
    pattern: str
    regex: re.Pattern[str]
    set: Callable[[Call], Any] | None = None
    query: Callable[[Call], Any] | None = None
    answers: bool = False   # the (unusual) command form that answers, like the lab's CAM:REC
    suffix_names: tuple[str, ...] = ()
    query_params: bool = True   # the query reads parameters (MIN/MAX, a source...)


def _split_outside_quotes(text: str, sep: str) -> tuple[list[str], bool]:
    """Split on ``sep`` where it is not inside '...', "..." or a definite-length block
    (``#<n><length><bytes>``, skipped by its length); also say whether a quote was left open.
    Linear in the text: the scan jumps from one special character to the next."""
    special = _SPECIALS[sep]
    out: list[str] = []
    start = pos = 0
    while True:
        m = special.search(text, pos)
        if m is None:
            break
        c, at = m.group(), m.start()
        if c == sep:
            out.append(text[start:at])
            start = pos = at + 1
        elif c == "#":
            pos = _past_block(text, at)
        else:
            end = text.find(c, at + 1)
            if end < 0:
                out.append(text[start:])
                return out, True
            pos = end + 1
    out.append(text[start:])
    return out, False


_SPECIALS = {sep: re.compile("[" + re.escape(sep) + "#\"']") for sep in (",", ";")}


_QUOTE_OR_BLOCK = re.compile("[#\"']")


def _strip(text: str) -> str:
    """``text.strip()``, except that a definite-length block keeps its bytes (blank ones too)."""
    text = text.lstrip()
    end = pos = 0
    while True:
        m = _QUOTE_OR_BLOCK.search(text, pos)
        if m is None:
            break
        if m.group() == "#":
            pos = _past_block(text, m.start())
            end = max(end, pos) if pos > m.start() + 1 else end
        else:
            close = text.find(m.group(), m.start() + 1)
            pos = len(text) if close < 0 else close + 1
    return text[:end] + text[end:].rstrip()


def _past_block(text: str, at: int) -> int:
    """The index after a definite-length block starting at ``at`` (``#``), or after the ``#`` alone."""
    if at + 1 < len(text) and "1" <= text[at + 1] <= "9":
        n = int(text[at + 1])
        digits = text[at + 2:at + 2 + n]
        if len(digits) == n and digits.isdigit():
            return min(len(text), at + 2 + n + int(digits))
    return at + 1


def split_params(text: str) -> list[str]:
    """Split a parameter list on commas outside quotes; strip blanks."""
    text = _strip(text)
    if not text:
        return []
    parts, open_quote = _split_outside_quotes(text, ",")
    if open_quote:
        raise ScpiError(-102, "Syntax error;unterminated string")
    return [_strip(p) for p in parts]


#: a program message unit: header, then (after white space: space or tab) the data
_UNIT = re.compile(r"^\s*([:*]?[A-Za-z0-9_:*]*\??)(?:[ \t]+(.*))?$", re.S)


def split_commands(line: str) -> list[str]:
    """Split a program message on ``;`` outside quotes."""
    parts, _ = _split_outside_quotes(line, ";")
    return [q for q in (_strip(p) for p in parts) if q]


# ------------------------------------------------------------------------------------------
# parameter parsing

_NUM = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z/]*)\s*$")
#: SI suffixes per unit; SCPI reads ``MHZ`` as megahertz and ``MV`` as millivolt
_SUFFIX = {
    "HZ": {"HZ": 1.0, "KHZ": 1e3, "MHZ": 1e6, "MAHZ": 1e6, "GHZ": 1e9},
    "V": {"V": 1.0, "MV": 1e-3, "UV": 1e-6, "KV": 1e3},
    "S": {"S": 1.0, "MS": 1e-3, "US": 1e-6, "NS": 1e-9, "PS": 1e-12, "KS": 1e3},
    "OHM": {"OHM": 1.0, "KOHM": 1e3, "MOHM": 1e6},
    "": {},
}


def parse_number(text: str, unit: str = "", *, minimum: float | None = None,
                 maximum: float | None = None, default: float | None = None,
                 clip: bool = False) -> float:
    """Parse a SCPI numeric parameter: ``1e3``, ``1 KHZ``, ``MIN``, ``MAX``, ``DEF``.

    Out of range: clipped to the limit when ``clip``, else ``-222`` is raised.
    :meth:`SimScpiInstrument.num` clips *and* queues ``-222``, as the Keysight
    instruments do.
    """
    word = text.strip().upper()
    if word in ("MIN", "MINIMUM") and minimum is not None:
        return minimum
    if word in ("MAX", "MAXIMUM") and maximum is not None:
        return maximum
    if word in ("DEF", "DEFAULT") and default is not None:
        return default
    m = _NUM.match(text)
    if not m:
        raise ScpiError(-104 if re.match(r"^[A-Za-z]", word) else -102)
    value = float(m.group(1))
    suffix = m.group(2).upper()
    if suffix:
        table = _SUFFIX.get(unit, {})
        if suffix not in table:
            raise ScpiError(-102, "Syntax error;unknown suffix")
        value *= table[suffix]
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        if not clip:
            raise ScpiError(-222)
        return float(min(max(value, minimum if minimum is not None else value),
                         maximum if maximum is not None else value))
    return value


def parse_bool(text: str) -> bool:
    word = text.strip().upper()
    if word in ("ON", "1"):
        return True
    if word in ("OFF", "0"):
        return False
    raise ScpiError(-224)


def parse_enum(text: str, choices: list[str]) -> str:
    """Match a keyword against choices written as ``LINear`` (short or long form)."""
    word = text.strip().upper()
    for choice in choices:
        short = "".join(ch for ch in choice if ch.isupper() or ch.isdigit())
        if word in (short, choice.upper()):
            return short
    raise ScpiError(-224)


def fmt_num(value: float) -> str:
    """Keysight numeric reply format: ``+1.00000000000000E+03``."""
    return f"{value:+.14E}"


def fmt_int(value: int) -> str:
    return f"{int(value):+d}"


def definite_block(payload: bytes, digits: int | None = None) -> bytes:
    """An IEEE 488.2 definite-length block ``#<n><len><payload>`` (IEEE 488.2-1992, 8.7.9).

    ``digits`` fixes the length field's width, as instruments do: InfiniiVision
    ``#800001000`` (8), Rigol ``#9000001200`` (9); None: the shortest.
    """
    size = str(len(payload)) if digits is None else str(len(payload)).zfill(digits)
    if len(size) > 9:
        raise ValueError(f"block of {len(payload)} bytes does not fit a {digits}-digit header")
    return b"#" + str(len(size)).encode() + size.encode() + payload


# ------------------------------------------------------------------------------------------
# the instrument


class SimScpiInstrument:
    """Base of the simulated SCPI instruments: a command table and IEEE 488.2 commons.

    Subclasses set :attr:`idn` and fill the table in :meth:`build`; the
    transport calls :meth:`handle` with each received line and sends back
    what it returns (``bytes`` ending in ``\\n``) unless ``None``.

    Dialect (per instrument, from its programming guide): :attr:`no_error`
    (the empty error queue's reply), :attr:`int_sign` (``+0`` or ``0`` for
    integer replies), :attr:`block_digits` (the block header's length field),
    :attr:`suffix_limits` (largest numeric suffix per mnemonic short form).
    """

    name = "instrument"
    idn = "labkit,virtual,0,0"
    error_queue_size = 20
    no_error = '+0,"No error"'
    int_sign = True
    block_digits: int | None = None
    suffix_limits: dict[str, int] = {}
    #: Queries take parameters unless said otherwise (the generators' ``? MIN|MAX|DEF``); the
    #: scopes document none, so there a parameter to a query is ``-108`` unless the command says so.
    query_params_default = True

    def __init__(self, name: str | None = None) -> None:
        if name:
            self.name = name
        self.commands: list[Command] = []
        self.errors: deque[tuple[int, str]] = deque()
        self.lock = threading.RLock()
        self.settings: dict[str, Any] = {}
        self.setting_defaults: dict[str, tuple[Any, bool]] = {}
        self.esr = 0      # Standard Event Status Register
        self.ese = 0      # its enable register
        self.sre = 0      # Service Request Enable register
        self.add("*IDN", query=lambda c: self.idn)
        self.add("*RST", set=lambda c: self.reset())
        self.add("*CLS", set=lambda c: self.clear_status())
        self.add("*OPC", set=lambda c: self.operation_complete(), query=lambda c: self.opc())
        self.add("*WAI", set=lambda c: self.wait_pending())
        self.add("*TST", query=lambda c: self.fmt_int(0))
        self.add("*ESR", query=lambda c: self.fmt_int(self.read_esr()))
        self.add("*STB", query=lambda c: self.fmt_int(self.status_byte()))
        self.add("*ESE", set=lambda c: setattr(self, "ese", self._register(c)),
                 query=lambda c: self.fmt_int(self.ese))
        self.add("*SRE", set=lambda c: setattr(self, "sre", self._register(c) & ~STB_MSS),
                 query=lambda c: self.fmt_int(self.sre))
        self.add("SYSTem:ERRor[:NEXT]", query=lambda c: self.next_error())
        self.add("SYSTem:VERSion", query=lambda c: "1999.0")
        self.build()

    # -- table ------------------------------------------------------------------------------
    def build(self) -> None:
        """Fill the command table (subclasses)."""

    def add(self, pattern: str, set: Callable[[Call], Any] | None = None,
            query: Callable[[Call], Any] | None = None, answers: bool = False,
            query_params: bool | None = None) -> None:
        """``query_params``: whether the query takes parameters; None: as
        :attr:`query_params_default` says (a parameter to a query that takes none is ``-108``)."""
        takes = self.query_params_default if query_params is None else query_params
        self.commands.append(Command(pattern, compile_pattern(pattern), set, query, answers,
                                     tuple(suffix_names(pattern)), takes))

    def setting(self, pattern: str, key: str, default: Any, parse: Callable[[str], Any],
                fmt: Callable[[Any], str] = str, per_suffix: bool = False,
                limits: tuple[float, float] | None = None) -> None:
        """A plain stored setting: ``pattern value`` sets, ``pattern?`` reads.

        With ``per_suffix`` the value is kept per numeric suffix (channel).
        With ``limits`` (lo, hi) the query also answers ``? MIN``, ``? MAX``
        and ``? DEF`` (the ``*RST`` value).
        """
        store = self.settings
        store.setdefault(key, {} if per_suffix else default)
        self.setting_defaults[key] = (default, per_suffix)

        def do_set(c: Call) -> None:
            value = parse(c.one())
            if per_suffix:
                store[key][c.suffix()] = value
            else:
                store[key] = value

        def do_query(c: Call) -> str:
            if c.params:
                return fmt(self.query_limit(c, limits, default))
            value = store[key].get(c.suffix(), default) if per_suffix else store[key]
            return fmt(value)

        self.add(pattern, set=do_set, query=do_query, query_params=True)

    def query_limit(self, c: Call, limits: tuple[float, float] | None, default: Any) -> Any:
        """The value a ``? MIN|MAX|DEF`` query names; -108 if the setting has no such query."""
        word = c.one().strip().upper()
        if limits is not None:
            if word in ("MIN", "MINIMUM"):
                return limits[0]
            if word in ("MAX", "MAXIMUM"):
                return limits[1]
            if word in ("DEF", "DEFAULT"):
                return default
            raise ScpiError(-224)
        raise ScpiError(-108)

    def get(self, key: str, suffix: int | None = None) -> Any:
        store = self.settings
        default, per_suffix = self.setting_defaults[key]
        if per_suffix:
            return store[key].get(1 if suffix is None else suffix, default)
        return store[key]

    def reset(self) -> None:
        """``*RST``: stored settings back to defaults (subclasses extend); the status registers stay."""
        store = self.settings
        for key, (default, per_suffix) in self.setting_defaults.items():
            store[key] = {} if per_suffix else default

    def num(self, text: str, unit: str = "", minimum: float | None = None,
            maximum: float | None = None, default: float | None = None) -> float:
        """Parse a number; out of range -> the limit is used and ``-222`` queued."""
        value = parse_number(text, unit, minimum=minimum, maximum=maximum, default=default, clip=True)
        try:
            parse_number(text, unit, minimum=minimum, maximum=maximum, default=default, clip=False)
        except ScpiError:
            side = "upper" if maximum is not None and value >= maximum else "lower"
            self.push_error(-222, f"Data out of range;value clipped to {side} limit")
        return value

    # -- formats ------------------------------------------------------------------------------
    def fnum(self, value: float) -> str:
        """An NR3 reply in the instrument's style (Keysight ``+1.00000000000000E+03``)."""
        return fmt_num(value)

    def fmt_int(self, value: int) -> str:
        """An NR1 reply in the instrument's style (``+0`` Keysight, ``0`` Rigol)."""
        return f"{int(value):+d}" if self.int_sign else f"{int(value):d}"

    def block(self, payload: bytes) -> bytes:
        """A definite-length block with this instrument's header width."""
        return definite_block(payload, self.block_digits)

    # -- status model ---------------------------------------------------------------------------
    def _register(self, c: Call) -> int:
        value = parse_number(c.one(), "")
        if value != int(value) or not 0 <= value <= 255:
            raise ScpiError(-222)
        return int(value)

    def read_esr(self) -> int:
        """``*ESR?``: the register's value; reading it clears it."""
        value, self.esr = self.esr, 0
        return value

    def status_byte(self) -> int:
        """``*STB?`` (not cleared by reading): EAV, ESB, MSS and the subclass's summary bits."""
        stb = self.summary_bits()
        if self.errors:
            stb |= STB_EAV
        if self.esr & self.ese:
            stb |= STB_ESB
        if stb & self.sre:
            stb |= STB_MSS
        return stb

    def summary_bits(self) -> int:
        """Bits 0-3 and 7 of the status byte (subclasses: QUES, OPER summaries)."""
        return 0

    def clear_status(self) -> None:
        """``*CLS``: the event registers and the error queue are cleared; enable registers stay."""
        self.errors.clear()
        self.esr = 0

    def pending(self) -> bool:
        """True while an operation started by an earlier command is still in progress."""
        return False

    def wait_pending(self) -> None:
        """Block until :meth:`pending` is False (the instrument's lock is released meanwhile)."""
        while self.pending():
            self.lock.release()
            try:
                time.sleep(0.002)
            finally:
                self.lock.acquire()

    def operation_complete(self) -> None:
        """``*OPC``: ESR bit 0 once what came before is done."""
        self.wait_pending()
        self.esr |= ESR_OPC

    def opc(self) -> str:
        """``*OPC?``: ``1`` once what came before is done."""
        self.wait_pending()
        return "1"

    # -- errors ------------------------------------------------------------------------------
    def push_error(self, code: int, message: str | None = None) -> None:
        message = message or ERRORS.get(code, "Error")
        self.esr |= esr_bit(code)
        if len(self.errors) >= self.error_queue_size:
            self.errors.pop()
            self.errors.append((-350, ERRORS[-350]))
            return
        self.errors.append((code, message))

    def next_error(self) -> str:
        if not self.errors:
            return self.no_error
        code, message = self.errors.popleft()
        return f'{self.fmt_int(code)},"{message}"'

    # -- dispatch ----------------------------------------------------------------------------
    def lookup(self, header: str) -> tuple[Command, list[int]] | None:
        """The command a header names and its numeric suffixes (remembered: a message repeating
        one command 100 000 times costs one search)."""
        up = header.upper()
        cache = self.__dict__.setdefault("_lookups", {})
        key = (up, len(self.commands))      # the table may still grow after build()
        if key in cache:
            return cache[key]
        found = None
        for cmd in self.commands:
            m = cmd.regex.fullmatch(up)
            if m:
                found = cmd, [int(g) if g is not None else 1 for g in m.groups()]
                break
        if len(cache) > LOOKUP_CACHE:
            cache.clear()
        cache[key] = found
        return found

    def handle(self, line: str) -> bytes | None:
        """Execute one received line; return the reply (with ``\\n``) or None."""
        replies: list[bytes] = []
        prefix = ""
        for part in split_commands(line):
            m = _UNIT.match(part)
            if m is None:
                self.push_error(-102)
                continue
            header, rest = m.group(1), m.group(2) or ""
            if header.startswith("*"):
                full = header            # common commands leave the path alone
            elif header.startswith(":") or not prefix:
                full = header.lstrip(":")
                prefix = ""
            else:
                full = prefix + ":" + header
            query = full.endswith("?")
            bare = full[:-1] if query else full
            if not bare.startswith("*"):
                # an undefined header leaves the path at the root: a relative header repeated
                # after an error does not grow the path (nor the cost of every later lookup)
                known = len(bare) <= MAX_HEADER_CHARS and self.lookup(bare) is not None
                prefix = bare.rsplit(":", 1)[0] if ":" in bare and known else ""
            reply = self.execute(bare, rest, query)
            if reply is not None:
                replies.append(reply if isinstance(reply, bytes) else str(reply).encode("ascii", "replace"))
        if not replies:
            return None
        return b";".join(replies) + b"\n"

    def _suffixes_ok(self, cmd: Command, suffixes: list[int]) -> bool:
        for name, n in zip(cmd.suffix_names, suffixes):
            limit = self.suffix_limits.get(name)
            if n < 1 or (limit is not None and n > limit):
                return False
        return True

    def execute(self, header: str, rest: str, query: bool) -> Any:
        found = self.lookup(header) if len(header) <= MAX_HEADER_CHARS else None
        if found is None:
            self.push_error(-113)
            return None
        cmd, suffixes = found
        if not self._suffixes_ok(cmd, suffixes):
            self.push_error(-114)
            return None
        handler = cmd.query if query else cmd.set
        if handler is None:
            self.push_error(-113, "Undefined header;query only" if not query else "Undefined header;no query")
            return None
        try:
            params = split_params(rest)
            if query and params and not cmd.query_params:
                raise ScpiError(-108)
            with self.lock:
                result = handler(Call(params, suffixes, header, query))
            return result if (query or cmd.answers) else None
        except ScpiError as exc:
            self.push_error(exc.code, exc.message)
            return None
        except Exception as exc:  # a fault of the simulation, not of the command: say so
            self.push_error(-300, f"Device-specific error;{type(exc).__name__}: {exc}"[:200])
            return None
