"""The sans-IO protocol core of the host library: bytes in, lines and events out.

One :class:`Protocol` object is shared by the sync and the asyncio client; it never
reads, writes, sleeps or looks at a clock.  It owns:

* **line ends** (cml-users-guide.txt ch. 3 K70): a line ends at CR, LF or CRLF; the
  delimiter the motor uses is learned from what it sends (:attr:`Protocol.delimiter`);
* **echo** (ch. 3 K23 function 8): a received line equal to a line the client sent
  and has not yet seen echoed is that line's echo.  Whether the motor echoes is
  learned at every exchange (:attr:`Protocol.echo`); nothing needs configuring;
* **exchanges**: one request at a time (:class:`Exchange`): the lines sent, and a
  predicate naming the line that completes it.  With echo on, only lines after the
  echo of the exchange's first line belong to it (anything earlier is an event or a
  stale reply); ``errorNN.n`` lines of the addressed motor are collected as errors;
* **events**: ``Ux``/``IN``/``OUT`` reports (K23 functions 1, 2, 4), messages, and
  lines nobody asked for, numbered in arrival order (:class:`MotorEvent`).

The ambiguity that remains (a ``Ux.n=`` report and the reply to ``?99.n`` look the
same) and the choices made are in docs/fidelity.md, "Host library and tools".
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Literal

from ..errors import MotorError
from .replies import Received, classify

__all__ = ["Protocol", "Exchange", "MotorEvent", "EventKind", "LineSplitter", "MAX_LINE"]

#: A line longer than this without a line end is cut and reported as garbled.
MAX_LINE: Final = 4096
#: Sent lines remembered for echo matching.
ECHO_MEMORY: Final = 16
#: Events kept for waits that look back (``wait_in_position`` after the move began).
EVENT_MEMORY: Final = 256

EventKind = Literal["status", "input", "output", "message", "error", "unsolicited",
                    "garbled"]
#: A line that writes K23 may switch the echo off or on (ch. 3 K23 function 8).
_K23_WRITE: Final = re.compile(r"K23(\.\d+)?\s*[-+]?=", re.IGNORECASE)
#: Queries whose replies look like K23 reports (6.6 ?50, ?70, ?99).
_REPORT_QUERY: Final = re.compile(r"\?(50|70|99)(?![0-9])")
_REPORT_QUERIES: Final = {"50": "output", "70": "input", "99": "status"}
_EVENT_KINDS: Final = {"status": "status", "input": "input", "output": "output",
                       "message": "message", "error": "error", "garbled": "garbled"}


@dataclass(frozen=True, slots=True)
class MotorEvent:
    """Something the motor said that no request was waiting for.

    ``kind``: ``status`` (``Ux.n=``, K23 1), ``input`` (``IN.n=``, K23 2), ``output``
    (``OUT.n=``, K23 4), ``message`` (``saved.n``, ``End.n`` ...), ``error``
    (``errorNN.n``), ``unsolicited`` (a reply to nobody, e.g. one that came after its
    request timed out, or a bank's ``?96`` display) or ``garbled`` (unreadable bytes).
    ``value`` is the number of a report (the Ux value, the input/output word).
    ``seq`` numbers every line received, in order.
    """

    seq: int
    kind: EventKind
    motor: int | None
    text: str
    value: int | None = None


@dataclass(eq=False)
class Exchange:
    """One request: lines to send and the line that completes the answer.

    ``done`` is called with each candidate line; the first line it accepts ends the
    exchange.  ``motor`` is the ID whose ``errorNN`` lines count as this exchange's
    errors (``None``: any).  After completion ``lines`` holds every non-event line of
    the answer in order (the completing one last) and ``errors`` the reported errors.
    """

    send: tuple[str, ...]
    done: Callable[[Received], bool]
    motor: int | None = None
    wanted: str = "a reply"
    lines: list[Received] = field(default_factory=list)
    errors: list[MotorError] = field(default_factory=list)
    garbled: list[str] = field(default_factory=list)
    timeout: float = 1.0
    until_echo: bool = False
    echo_may_change: bool = False
    reply_kinds: frozenset[str] = frozenset()
    echoed: int = 0
    complete: bool = False
    end_seq: int = 0
    #: A line sent whose echo a reply line may equal (a bank listing can hold the
    #: ``?96.n`` fence): its echo is credited but also kept among ``lines``, and the
    #: caller drops the last one (:func:`coolmuscle.client.ops.listing`).
    keep_echo: str | None = None

    def describe(self) -> str:
        """For timeout messages: what was sent and what was awaited."""
        sent = " / ".join(self.send) or "(nothing)"
        text = f"no {self.wanted} to {sent!r}"
        if self.garbled:
            text += f" (received {len(self.garbled)} unreadable line(s): {self.garbled[0]!r})"
        return text


class LineSplitter:
    """Bytes -> lines; CR, LF and CRLF each end one line (K70: 0 CR, 1 CRLF).

    ``delimiter`` is the line end seen last (K70 may change while connected)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._after_cr = False
        self.delimiter: bytes | None = None

    def feed(self, data: bytes) -> list[bytes]:
        lines: list[bytes] = []
        for byte in data:
            if byte == 0x0A and self._after_cr:
                self._after_cr = False
                self.delimiter = b"\r\n"
                continue
            if self._after_cr:
                self.delimiter = b"\r"
            self._after_cr = byte == 0x0D
            if byte in (0x0D, 0x0A):
                if byte == 0x0A:
                    self.delimiter = b"\n"
                lines.append(bytes(self._buf))
                self._buf.clear()
            elif len(self._buf) >= MAX_LINE:
                lines.append(bytes(self._buf))
                self._buf[:] = bytes([byte])
            else:
                self._buf.append(byte)
        return lines

    @property
    def partial(self) -> bytes:
        """Bytes of a line not yet ended."""
        return bytes(self._buf)


class Protocol:
    """State of one connection to a host line (one chain); see the module docstring."""

    def __init__(self) -> None:
        self._split = LineSplitter()
        self._sent: deque[tuple[str, Exchange | None]] = deque(maxlen=ECHO_MEMORY)
        self.echo: bool | None = None
        self.exchange: Exchange | None = None
        self.events: deque[MotorEvent] = deque(maxlen=EVENT_MEMORY)
        self.seq = 0
        #: motor ID -> (seq, Ux) of the latest ``Ux.n=`` line, report or reply.
        self.status_seen: dict[int, tuple[int, int]] = {}

    # -- what the client sends ---------------------------------------------------
    @property
    def delimiter(self) -> bytes | None:
        """The line end the motor uses (K70), once seen: ``b"\\r\\n"`` or ``b"\\r"``."""
        return self._split.delimiter

    def encode(self, lines: tuple[str, ...] | list[str],
               owner: Exchange | None = None) -> bytes:
        """Bytes for ``lines``, each ended with CR (the Enter key, 2.1); remembered for echo.

        With echo off only an exchange's lines are remembered (it forgets them when
        it completes): a line nobody waits for would otherwise stay, and a later reply
        equal to it (a bank listing line) would pass for its echo.
        """
        remember = self.echo is not False or (owner is not None and not owner.complete)
        for line in lines:
            if "\r" in line or "\n" in line:
                raise ValueError(f"a line to send holds a line end: {line!r}")
            if remember:
                self._sent.append((line, owner))
        return b"".join(line.encode("latin-1") + b"\r" for line in lines)

    def begin(self, exchange: Exchange) -> bytes:
        """Start ``exchange`` (the previous one is abandoned); returns the bytes to write."""
        self.exchange = exchange
        exchange.echo_may_change = any(_K23_WRITE.search(line) for line in exchange.send[:-1])
        exchange.reply_kinds = frozenset(_REPORT_QUERIES[m.group(1)] for line in exchange.send[:-1]
                                         for m in _REPORT_QUERY.finditer(line))
        return self.encode(exchange.send, exchange)

    def abandon(self) -> None:
        """Forget the pending exchange (its deadline passed); late answers become events.

        When echo was believed on and nothing of the exchange came back, echo is
        unknown again and is learned anew by the next exchange.
        """
        exchange, self.exchange = self.exchange, None
        if exchange is not None and exchange.send and exchange.echoed == 0 and self.echo:
            self.echo = None

    # -- what the motor sends ------------------------------------------------------
    def receive(self, data: bytes) -> list[MotorEvent]:
        """Feed received bytes; returns the new events (exchange lines are not events)."""
        events: list[MotorEvent] = []
        for raw in self._split.feed(data):
            event = self._line(raw)
            if event is not None:
                self.events.append(event)
                events.append(event)
        return events

    def events_since(self, seq: int) -> list[MotorEvent]:
        """Remembered events numbered after ``seq``."""
        return [e for e in self.events if e.seq > seq]

    def _line(self, raw: bytes) -> MotorEvent | None:
        text = raw.decode("latin-1")
        if not text:
            return None  # a blank line (a lone CR, or an LF after a CR-only end): nothing
        self.seq += 1
        if self._echo_of(text):
            return None
        line = classify(raw)
        if line.kind == "status" and line.motor is not None:
            value = _int_or_none(line.value, 10)
            if value is not None:
                self.status_seen[line.motor] = (self.seq, value)
        exchange = self.exchange
        if exchange is not None and not exchange.complete and self._belongs(exchange, line):
            return self._answer(exchange, line)
        return self._event(line)

    def _echo_of(self, text: str) -> bool:
        """Whether ``text`` is the echo of a line sent; credits the exchange that sent it.

        When ``text`` is the next line of the pending exchange to be echoed (echoes come
        in the order the lines went), that line is matched first: the same text sent by
        an exchange that timed out with its echo lost (a dead line) is older, and its
        echo is not coming; matching it would leave every later exchange one echo
        behind.  Otherwise the oldest line of that text is (a late echo)."""
        current = self.exchange
        index = None
        if current is not None and not current.complete and \
                current.echoed < len(current.send) and current.send[current.echoed] == text:
            index = next((i for i, (sent, owner) in enumerate(self._sent)
                          if sent == text and owner is current), None)
        if index is None:
            index = next((i for i, (sent, _o) in enumerate(self._sent) if sent == text), None)
        if index is None:
            return False
        owner = self._sent[index][1]
        if self.echo is False and owner is not None and owner.keep_echo is not None:
            return False            # no echo comes: a listing line of that text
        for _ in range(index):
            self._sent.popleft()  # older lines whose echo never came
        _text, owner = self._sent.popleft()
        self.echo = True
        if owner is not None and owner is self.exchange and not owner.complete:
            owner.echoed += 1
            if owner.until_echo and owner.echoed >= len(owner.send):
                owner.complete = True
                owner.end_seq = self.seq
            if owner.keep_echo == text:
                return False        # maybe a listing line: the caller sorts it out
        return True

    def _belongs(self, exchange: Exchange, line: Received) -> bool:
        """Lines before the exchange's first echo (echo on) belong to what came before."""
        if self.echo is not True or exchange.echoed > 0:
            return True
        if line.kind == "garbled":
            exchange.echoed += 1  # most likely the echo itself, damaged: count it
            exchange.garbled.append(line.text)
            return False
        return False

    def _answer(self, exchange: Exchange, line: Received) -> MotorEvent | None:
        if line.kind == "error":
            if exchange.motor not in (None, line.motor):
                return self._event(line)  # another motor's error: not this answer
            exchange.errors.append(line.error())
            exchange.lines.append(line)
            return None
        if line.kind == "garbled":
            if line.text:
                exchange.garbled.append(line.text)
                return self._event(line)
            return None
        strict = self.echo is True and not exchange.echo_may_change
        all_echoed = exchange.echoed >= len(exchange.send)
        if (all_echoed or not strict) and exchange.done(line):
            exchange.lines.append(line)
            exchange.complete = True
            exchange.end_seq = self.seq
            self._learn_echo(exchange)
            return None
        if line.kind in ("status", "input", "output") and (
                all_echoed or not strict or line.kind not in exchange.reply_kinds):
            return self._event(line)  # a report, unless one of our lines asked for it
        exchange.lines.append(line)  # between our echoes: it answers one of our lines
        return None

    def _learn_echo(self, exchange: Exchange) -> None:
        """All lines echoed: echo on.  The last one not echoed: echo is off now.
        Either way the exchange's lines are forgotten (their echo is not coming)."""
        if exchange.send and exchange.echoed < len(exchange.send):
            self.echo = False
        self._sent = deque(((t, o) for t, o in self._sent if o is not exchange),
                           maxlen=ECHO_MEMORY)

    def _event(self, line: Received) -> MotorEvent:
        kind = _EVENT_KINDS.get(line.kind, "unsolicited")
        value: int | None = None
        if kind == "status":
            value = _int_or_none(line.value, 10)
        elif kind in ("input", "output"):
            value = _int_or_none(line.value, 16)
        elif kind == "error" and line.name:
            value = int(line.name[5:])
        return MotorEvent(self.seq, kind, line.motor, line.text, value)  # type: ignore[arg-type]


def _int_or_none(text: str | None, base: int) -> int | None:
    try:
        return int((text or "").strip(), base)
    except ValueError:
        return None
