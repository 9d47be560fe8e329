"""A small, generic SCPI instrument: a command table, an error queue, IEEE 488.2 blocks.

An instrument is a :class:`ScpiInstrument` whose command table maps header
patterns written the way programming guides print them to handlers::

    self.add("[SOURce#:]FREQuency[:CW]", set=self._set_freq, query=self._freq)

* upper-case letters are the short form, the whole word is the long form
  (``FREQ`` or ``FREQUENCY``, any case); nothing in between is accepted,
  exactly as on the instruments (``FREQU`` -> ``-113,"Undefined header"``);
* ``#`` is a numeric suffix (``SOURce2``, ``CHANnel1``; omitted means 1);
* ``[...]`` is an optional part.

Compound lines (``FREQ 1000;VOLT 2``, ``SOUR1:FREQ 1000;VOLT 2``) follow the
SCPI path rule: a command that does not start with ``:`` or ``*`` continues
from the previous command's parent node. Replies of several queries on one
line are joined by ``;``. Errors go to a 20-entry queue read by
``SYSTem:ERRor?`` (``+0,"No error"`` when empty; ``-350,"Queue overflow"``
replaces the last entry when full).
"""
from __future__ import annotations

import re
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

#: standard SCPI error messages used by the instruments
ERRORS = {
    -100: "Command error",
    -102: "Syntax error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -221: "Settings conflict",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -230: "Data corrupt or stale",
    -350: "Queue overflow",
}


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


def compile_pattern(pattern: str) -> re.Pattern[str]:
    """Turn ``[SOURce#:]FREQuency[:CW]`` into a regex on the upper-cased header."""
    out = []
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


def _split_outside_quotes(text: str, sep: str) -> tuple[list[str], bool]:
    """Split on ``sep`` where it is not inside '...' or "..."; also say whether a quote was left open."""
    out, cur, quote = [], [], None
    for c in text:
        if quote:
            cur.append(c)
            if c == quote:
                quote = None
        elif c in "\"'":
            quote = c
            cur.append(c)
        elif c == sep:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(c)
    out.append("".join(cur))
    return out, quote is not None


def split_params(text: str) -> list[str]:
    """Split a parameter list on commas outside quotes; strip blanks."""
    text = text.strip()
    if not text:
        return []
    parts, open_quote = _split_outside_quotes(text, ",")
    if open_quote:
        raise ScpiError(-102, "Syntax error;unterminated string")
    return [p.strip() for p in parts]


def split_commands(line: str) -> list[str]:
    """Split a program message on ``;`` outside quotes."""
    parts, _ = _split_outside_quotes(line, ";")
    return [p.strip() for p in parts if p.strip()]


# ------------------------------------------------------------------------------------------
# parameter parsing

_NUM = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z/]*)\s*$")
#: SI suffixes per unit; SCPI reads ``MHZ`` as megahertz and ``MV`` as millivolt
_SUFFIX = {
    "HZ": {"HZ": 1.0, "KHZ": 1e3, "MHZ": 1e6, "MAHZ": 1e6, "GHZ": 1e9},
    "V": {"V": 1.0, "MV": 1e-3, "UV": 1e-6, "KV": 1e3, "VPP": 1.0, "MVPP": 1e-3, "VRMS": 1.0},
    "S": {"S": 1.0, "MS": 1e-3, "US": 1e-6, "NS": 1e-9, "PS": 1e-12, "KS": 1e3},
    "OHM": {"OHM": 1.0, "KOHM": 1e3, "MOHM": 1e6},
    "": {},
}


def parse_number(text: str, unit: str = "", *, minimum: float | None = None,
                 maximum: float | None = None, default: float | None = None,
                 clip: bool = False) -> float:
    """Parse a SCPI numeric parameter: ``1e3``, ``1 KHZ``, ``MIN``, ``MAX``, ``DEF``.

    Out of range: clipped to the limit when ``clip``, else ``-222`` is raised.
    :meth:`ScpiInstrument.num` clips *and* queues ``-222``, as the Keysight
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


def definite_block(payload: bytes) -> bytes:
    """An IEEE 488.2 definite-length block ``#<n><len><payload>``."""
    size = str(len(payload))
    return b"#" + str(len(size)).encode() + size.encode() + payload


# ------------------------------------------------------------------------------------------
# the instrument


class ScpiInstrument:
    """Base of the simulated SCPI instruments: a command table and IEEE 488.2 commons.

    Subclasses set :attr:`idn` and fill the table in :meth:`build`; the
    transport calls :meth:`handle` with each received line and sends back
    what it returns (``bytes`` ending in ``\\n``) unless ``None``.
    """

    name = "instrument"
    idn = "labkit,virtual,0,0"
    error_queue_size = 20

    def __init__(self, name: str | None = None) -> None:
        if name:
            self.name = name
        self.commands: list[Command] = []
        self.errors: deque[tuple[int, str]] = deque()
        self.lock = threading.RLock()
        self.settings: dict[str, Any] = {}
        self.setting_defaults: dict[str, tuple[Any, bool]] = {}
        self.add("*IDN", query=lambda c: self.idn)
        self.add("*RST", set=lambda c: self.reset())
        self.add("*CLS", set=lambda c: self.errors.clear())
        self.add("*OPC", set=lambda c: None, query=lambda c: self.opc())
        self.add("*WAI", set=lambda c: self.opc())
        self.add("*TST", query=lambda c: "+0")
        self.add("*ESR", query=lambda c: fmt_int(32 if self.errors else 0))
        self.add("*STB", query=lambda c: fmt_int(4 if self.errors else 0))
        self.add("*ESE", set=lambda c: None, query=lambda c: "+0")
        self.add("*SRE", set=lambda c: None, query=lambda c: "+0")
        self.add("SYSTem:ERRor[:NEXT]", query=lambda c: self.next_error())
        self.add("SYSTem:VERSion", query=lambda c: "1999.0")
        self.build()

    # -- table ------------------------------------------------------------------------------
    def build(self) -> None:
        """Fill the command table (subclasses)."""

    def add(self, pattern: str, set: Callable[[Call], Any] | None = None,
            query: Callable[[Call], Any] | None = None, answers: bool = False) -> None:
        self.commands.append(Command(pattern, compile_pattern(pattern), set, query, answers))

    def setting(self, pattern: str, key: str, default: Any, parse: Callable[[str], Any],
                fmt: Callable[[Any], str] = str, per_suffix: bool = False) -> None:
        """A plain stored setting: ``pattern value`` sets, ``pattern?`` reads.

        With ``per_suffix`` the value is kept per numeric suffix (channel).
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
            value = store[key].get(c.suffix(), default) if per_suffix else store[key]
            return fmt(value)

        self.add(pattern, set=do_set, query=do_query)

    def get(self, key: str, suffix: int | None = None) -> Any:
        store = self.settings
        default, per_suffix = self.setting_defaults[key]
        if per_suffix:
            return store[key].get(1 if suffix is None else suffix, default)
        return store[key]

    def reset(self) -> None:
        """``*RST``: stored settings back to defaults (subclasses extend)."""
        store = self.settings
        for key, (default, per_suffix) in self.setting_defaults.items():
            store[key] = {} if per_suffix else default

    def opc(self) -> str:
        return "1"

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

    # -- errors ------------------------------------------------------------------------------
    def push_error(self, code: int, message: str | None = None) -> None:
        message = message or ERRORS.get(code, "Error")
        if len(self.errors) >= self.error_queue_size:
            self.errors.pop()
            self.errors.append((-350, ERRORS[-350]))
            return
        self.errors.append((code, message))

    def next_error(self) -> str:
        if not self.errors:
            return '+0,"No error"'
        code, message = self.errors.popleft()
        return f'{code:+d},"{message}"'

    # -- dispatch ----------------------------------------------------------------------------
    def lookup(self, header: str) -> tuple[Command, list[int]] | None:
        up = header.upper()
        for cmd in self.commands:
            m = cmd.regex.fullmatch(up)
            if m:
                return cmd, [int(g) for g in m.groups() if g is not None]
        return None

    def handle(self, line: str) -> bytes | None:
        """Execute one received line; return the reply (with ``\\n``) or None."""
        replies: list[bytes] = []
        prefix = ""
        for part in split_commands(line):
            header, _, rest = part.partition(" ")
            if not header.startswith((":", "*")) and prefix:
                full = prefix + ":" + header
            else:
                full = header
            query = full.endswith("?")
            bare = full[:-1] if query else full
            if not bare.startswith("*"):
                path = bare.lstrip(":")
                prefix = path.rsplit(":", 1)[0] if ":" in path else ""
            reply = self.execute(bare, rest, query)
            if reply is not None:
                replies.append(reply if isinstance(reply, bytes) else str(reply).encode("ascii"))
        if not replies:
            return None
        return b";".join(replies) + b"\n"

    def execute(self, header: str, rest: str, query: bool) -> Any:
        found = self.lookup(header)
        if found is None:
            self.push_error(-113)
            return None
        cmd, suffixes = found
        handler = cmd.query if query else cmd.set
        if handler is None:
            self.push_error(-113, "Undefined header;query only" if not query else "Undefined header;no query")
            return None
        try:
            params = split_params(rest)
            with self.lock:
                result = handler(Call(params, suffixes, header, query))
            return result if (query or cmd.answers) else None
        except ScpiError as exc:
            self.push_error(exc.code, exc.message)
            return None
        except Exception as exc:  # a fault of the simulation, not of the command: say so
            self.push_error(-300, f"Device-specific error;{type(exc).__name__}: {exc}"[:200])
            return None
