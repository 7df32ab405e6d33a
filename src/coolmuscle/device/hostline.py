"""The host line (COM0 in RS-232 mode) as the motor sees it, byte by byte.

This is motor behaviour, so it lives in the model, not in a transport:

* local echo of every received byte unless K23 includes 8 (ch. 3 K23);
* a line ends at CR (``\\r``) or LF (``\\n``); an LF right after a CR is the
  second half of a CRLF and ends nothing (docs/fidelity.md "line endings");
* every reply line ends with the delimiter of K70 (0: CR, 1: CRLF);
* optional wire-time pacing: bytes leave at the K20 baud rate, 10 bits a byte
  (start, 8 data, stop; 5.6.1), scheduled in virtual time;
* with pacing, a host whose port is set to another rate than K20 (ch. 3 K20: "the host
  baud rate needs to be changed to match") or another frame than the motor's (8 data
  bits, K82 parity, 1 stop bit; 5.6.1) sends the motor garbage and reads garbage: each
  side reads what its UART makes of the other's bytes (:mod:`.uart`).  A transport
  that knows its host's rate tells the line (:meth:`HostLine.set_host_baud`: the pty
  reads the rate the client set, an RFC 2217 client sets it), and its frame if it
  knows it (:meth:`HostLine.set_host_frame`); one that does not (TCP, stdio) is
  always matched.

Transports (TCP, pty, stdio, pyserial URL) only shuttle bytes: they call
:meth:`HostLine.feed` with what the host sent and subscribe to the bytes the
motor sends with :meth:`HostLine.add_listener`.

Several hosts may share the line (TCP clients, a pty program): ``feed(data,
source=...)`` assembles each source's line apart (its own partial line, CRLF
state and over-long-line discard), so one host's unfinished ``P1.1=12`` and
another's ``?96.1`` are never run as one line.  While a line runs,
:attr:`HostLine.source` names its sender (bank uploads belong to it);
:meth:`HostLine.open_source` / :meth:`HostLine.end_source` tell the line which
hosts are connected.  The echo is part of the motor's answer to a line (ch. 3 K23
8): a host alone on the line sees it byte by byte as it types; while other hosts are
connected each line's echo goes out whole at its line end, just before what the
line answers, so one host's echo never runs into another's (docs/fidelity.md
"Several hosts on COM0").

COM0 can also speak Modbus RTU (5.6, K81): a :class:`LineMode` installed as
:attr:`HostLine.mode` then takes the received bytes instead of the text line,
and text replies are not sent while it is active.

Wire faults (docs/wire-faults.md): once one of the host line or the chain is installed,
a :class:`WireHook` as :attr:`HostLine.wire` decides what the host gets of each piece
sent, and when (:mod:`.wire.line`), and whether what the host sends is lost; without
one, bytes go straight to the listeners.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from ..sim.kernel import NS_PER_S, PRIO_IO, PRIO_REPORT, Kernel
from .uart import PLAIN, Frame, as_read_at, bounded_host_baud

log = logging.getLogger(__name__)

#: K20 / K65 value -> bits per second (ch. 3 K20).
BAUD_RATES: dict[int, int] = {0: 38400, 1: 9600, 2: 19200, 3: 57600, 4: 115200, 5: 230400}

#: Longest line the motor buffers; longer input is discarded up to the next CR.
MAX_LINE = 512

ByteListener = Callable[[bytes], None]
#: The baud rate a host's port is set to now, or ``None`` when not known (matched).
HostBaud = Callable[[], int | None]
#: The frame a host's port is set to now (data bits, parity, stop bits), or ``None`` when
#: not known (the motor's).
HostFrame = Callable[[], Frame | None]

#: K82 value -> the parity of the motor's frame (ch. 3 K82: 0 none, 1 even, 2 odd).
PARITY_OF_K82: dict[int, str] = {0: "N", 1: "E", 2: "O"}

#: :attr:`HostLine._open_echo` when no sender's echo is half-way out (``None`` is a sender).
_NOBODY = object()


@dataclass(unsafe_hash=True)
class LineSettings:
    """What the host line needs from the motor's parameters, read live (immutable by
    convention)."""

    echo: bool = True               # K23 without 8
    delimiter: bytes = b"\r\n"      # K70: 0 -> CR, 1 -> CRLF
    baud: int = 38400               # K20
    modbus: bool = True             # K81 not 0: COM0 may speak Modbus RTU (the mode decides)
    frame: Frame = PLAIN            # 8 data bits, K82 parity, 1 stop bit (5.6.1)


class WireHook(Protocol):
    """The host line's wire faults (:class:`coolmuscle.device.wire.line.LineFaults`):
    installed as :attr:`HostLine.wire` once a ``host-line`` or ``chain`` fault is."""

    def deliver(self, data: bytes, baud: int, frame: Frame, echo: bool) -> None:
        """A piece the motor sends now at ``baud`` in ``frame`` (``echo``: of what the
        host typed); hands what the host gets to ``hand_out``."""

    def swallows(self, data: bytes) -> bool:
        """Whether the bytes the host sends now are lost (a dead line)."""


class LineMode(Protocol):
    """Another protocol on COM0 (Modbus RTU, 5.6): takes the bytes while active."""

    def active(self) -> bool:
        """Whether received bytes go to this mode (and text output is muted)."""

    def receive(self, data: bytes) -> None:
        """Bytes from the host, arrived at ``kernel.now``."""


def byte_time_ns(baud: int, frame: Frame = PLAIN) -> int:
    """Wire time of one byte at ``baud`` (10 bits; 11 with a parity bit)."""
    if frame is PLAIN:
        return (10 * NS_PER_S) // baud
    return int(frame.bits * NS_PER_S) // baud


class HostLine:
    """Byte-level host line: echo, line assembly, delimiter, optional pacing.

    ``on_line`` is called with each complete line (without its terminator) at
    the virtual time its last byte arrived.  ``settings`` returns the live
    :class:`LineSettings` (from motor ID1's K20/K23/K70/K81).
    """

    def __init__(self, kernel: Kernel, on_line: Callable[[str], None],
                 settings: Callable[[], LineSettings], *, pacing: bool = False) -> None:
        self.kernel = kernel
        self._on_line = on_line
        self._settings = settings
        self.pacing = pacing
        self._assembly: dict[object, _Assembly] = {}
        #: Connected hosts (:meth:`open_source`); the echo is typed when one is alone.
        self._hosts: set[object] = set()
        #: The sender whose typed echo ends the output so far, without its line end.
        self._open_echo: object = _NOBODY
        #: The sender of the line being run (``None``: the single default host).
        self.source: object = None
        #: Called with a source that went away (its bank upload ends with it).
        self.on_source_end: Callable[[object], None] | None = None
        self._listeners: list[ByteListener] = []
        #: source -> its port's baud rate (:meth:`set_host_baud`); listener -> its source
        self._host_baud: dict[object, HostBaud] = {}
        self._host_frame: dict[object, HostFrame] = {}
        self._listener_source: dict[ByteListener, object] = {}
        self._tx_free_at = 0  # virtual time the transmitter is free again (pacing)
        self._rx_free_at = 0
        self.bytes_in = 0
        self.bytes_out = 0
        #: COM0 in another protocol's mode (Modbus RTU); ``None``: always text.  It is
        #: asked only while the settings say COM0 may speak it (``LineSettings.modbus``).
        self.mode: LineMode | None = None
        #: The wire faults between the motor and the host (docs/wire-faults.md);
        #: ``None`` until one is installed: then bytes go straight to the listeners.
        self.wire: WireHook | None = None

    # -- output ---------------------------------------------------------
    def add_listener(self, listener: ByteListener,
                     source: object = None) -> Callable[[], None]:
        """Receive every byte the motor sends; returns an unsubscribe function.

        ``source``: the host this listener reads for; with pacing it reads what its port
        makes of the motor's bytes at the rate :meth:`set_host_baud` gives for it."""
        self._listeners.append(listener)
        if source is not None:
            self._listener_source[listener] = source

        def remove() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)
            self._listener_source.pop(listener, None)
        return remove

    def set_host_baud(self, source: object, baud: HostBaud | None) -> None:
        """How to read the baud rate ``source``'s port is set to (``None``: not known,
        always matched).  Asked as bytes cross the wire, with pacing only (docs/
        fidelity.md "Baud rate of the host")."""
        if baud is None:
            self._host_baud.pop(source, None)
        else:
            self._host_baud[source] = baud

    def set_host_frame(self, source: object, frame: HostFrame | None) -> None:
        """How to read the frame ``source``'s port is set to (``None``: not known, the
        motor's).  Asked with the rate, with pacing only."""
        if frame is None:
            self._host_frame.pop(source, None)
        else:
            self._host_frame[source] = frame

    def _host_rate(self, source: object) -> int | None:
        baud = self._host_baud.get(source)
        rate = baud() if baud is not None else None
        return bounded_host_baud(rate) if rate is not None else None

    def _frame_of(self, source: object, motor: Frame) -> Frame:
        frame = self._host_frame.get(source)
        found = frame() if frame is not None else None
        return found if found is not None else motor

    def write(self, data: bytes | bytearray | memoryview, echo: bool = False) -> None:
        """Send raw bytes to the host (paced when pacing is on); ``echo``: they are the
        echo of what the host typed (the wire faults leave echoes alone unless told)."""
        if not data:
            return
        self._open_echo = _NOBODY
        data = bytes(data)                 # a buffer the caller may reuse: copied
        if not self.pacing:
            self._deliver(data, echo=echo)
            return
        settings = self._settings()
        baud, frame = settings.baud, settings.frame
        start = max(self.kernel.now, self._tx_free_at)
        self._tx_free_at = start + len(data) * byte_time_ns(baud, frame)
        self.kernel.schedule_at(self._tx_free_at,
                                lambda: self._deliver(data, baud, frame, echo),
                                priority=PRIO_REPORT, name="hostline-tx")

    def send_line(self, text: str) -> None:
        """Send one reply line followed by the K70 delimiter (not in Modbus mode)."""
        settings = self._settings()
        if settings.modbus and self.mode is not None and self.mode.active():
            return
        # joined, never ``+``: compiled, mypyc 1.19 leaks the left operand of bytes + bytes
        # (docs/performance.md "Compiled hot modules")
        self.write(b"".join((text.encode("latin-1", "replace"), settings.delimiter)))

    def _deliver(self, data: bytes, baud: int = 0, frame: Frame = PLAIN,
                 echo: bool = False) -> None:
        """``baud``, ``frame``: the motor's on the wire (paced); ``baud`` 0 unpaced."""
        wire = self.wire
        if wire is not None:          # the wire faults decide what the host gets, when
            wire.deliver(data, baud, frame, echo)
            return
        self.hand_out(data, baud, frame)

    def hand_out(self, data: bytes, baud: int = 0, frame: Frame = PLAIN) -> None:
        """Give bytes that reached the host's end of the line to every listener."""
        self.bytes_out += len(data)
        mismatched = bool(baud and self._host_baud)
        for listener in list(self._listeners):
            try:
                listener(self._as_heard(listener, data, baud, frame) if mismatched else data)
            except Exception:  # a broken client must not stop the motor
                log.exception("host line listener failed")

    def _as_heard(self, listener: ByteListener, data: bytes, baud: int,
                  frame: Frame) -> bytes:
        """What ``listener``'s host reads of ``data`` sent at ``baud`` (.uart)."""
        source = self._listener_source.get(listener)
        host = self._host_rate(source)
        if host is None:
            return data
        return as_read_at(data, baud, host, frame, self._frame_of(source, frame))

    # -- input ----------------------------------------------------------
    def feed(self, data: bytes | bytearray | memoryview, source: object = None) -> None:
        """Bytes from the host ``source``; with pacing they arrive at the K20 rate."""
        if not data:
            return
        data = bytes(data)                 # a buffer the caller may reuse: copied
        hook = self.wire
        if hook is not None and hook.swallows(data):
            return
        if not self.pacing:
            self._receive(data, source)
            return
        settings = self._settings()
        baud, motor = settings.baud, settings.frame
        wire = len(data) * byte_time_ns(baud, motor)
        if self._host_baud:
            host = self._host_rate(source)
            frame = self._frame_of(source, motor) if host is not None else motor
            if host is not None and (host != baud or frame != motor):
                # sent at the host's rate and frame, read at K20 and K82
                wire = len(data) * byte_time_ns(host, frame)
                data = as_read_at(data, host, baud, frame, motor)
        start = max(self.kernel.now, self._rx_free_at)
        self._rx_free_at = start + wire
        self.kernel.schedule_at(self._rx_free_at, lambda: self._receive(data, source),
                                priority=PRIO_IO, name="hostline-rx")

    def rx_backlog_ns(self) -> int:
        """With pacing: virtual time until the bytes fed so far have all arrived."""
        return max(0, self._rx_free_at - self.kernel.now) if self.pacing else 0

    def _receive(self, data: bytes, source: object = None) -> None:
        self.bytes_in += len(data)
        if self.mode is not None and self._settings().modbus and self.mode.active():
            self.mode.receive(data)
            return
        self.receive_text(data, source)

    def _assembly_of(self, source: object) -> _Assembly:
        found = self._assembly.get(source)
        if found is None:
            found = self._assembly[source] = _Assembly()
        return found

    def receive_text(self, data: bytes | bytearray | memoryview,
                     source: object = None) -> None:
        """Bytes for the RS-232 text line (also what follows a Modbus escape, 5.6.9)."""
        settings = self._settings()
        asm = self._assembly_of(source)
        typed = self._alone(source)
        echo = bytearray()          # typed: this chunk's echo, written as it comes
        failure: Exception | None = None
        for byte in data:
            if byte == 0x0A and asm.last_was_cr:
                asm.last_was_cr = False
                continue
            asm.last_was_cr = byte == 0x0D
            if byte in (0x0D, 0x0A):
                if settings.echo:
                    self._echo_line_end(asm, source, echo, settings.delimiter, typed)
                echo.clear()
                asm.held.clear()
                asm.shown = asm.cut = False
                try:
                    self._end_line(asm, source)
                except Exception as exc:  # isolate the line; report after the chunk
                    failure = failure or exc
                settings = self._settings()  # the line may have changed K23/K70
                continue
            if settings.echo:
                if typed:
                    echo.append(byte)
                elif len(asm.held) < MAX_LINE:
                    asm.held.append(byte)
            if len(asm.buf) >= MAX_LINE:
                asm.overflow = True
            else:
                asm.buf.append(byte)
        if echo:
            if asm.held:                 # held while others were connected: first
                echo[:0] = asm.held
                asm.held.clear()
            self.write(bytes(echo), True)
            asm.shown = True
            self._open_echo = source
        if failure is not None:
            raise failure

    def _alone(self, source: object) -> bool:
        """Whether ``source`` is the only host connected (its echo goes out as typed)."""
        hosts = self._hosts
        return not hosts or (len(hosts) == 1 and source in hosts)

    def _echo_line_end(self, asm: _Assembly, source: object, echo: bytearray,
                       delimiter: bytes, typed: bool) -> None:
        """The echo at the end of a line: the rest of the line and the delimiter; the
        whole line when what was shown of it was cut off by another host's line (or,
        while hosts share the line, by anything).  Joined, never ``+`` (send_line)."""
        if asm.cut or (asm.shown and not typed and self._open_echo is not source):
            out = b"".join((asm.buf, delimiter))
        else:
            out = b"".join((asm.held, echo, delimiter))
        other = self._open_echo
        if other is not _NOBODY and other is not source:
            # another host's typed echo is half-way out: end it there, and it is sent
            # again whole at its own line end
            out = b"".join((delimiter, out))
            cut = self._assembly.get(other)
            if cut is not None:
                cut.cut = True
        self.write(out, True)

    def discard_partial(self, source: object = None) -> None:
        """Forget a partly received line of ``source`` (its sender went away mid-line)."""
        asm = self._assembly.get(source)
        if asm is not None:
            asm.buf.clear()
            asm.held.clear()
            asm.overflow = asm.shown = asm.cut = False
            asm.last_was_cr = False

    def open_source(self, source: object) -> None:
        """A host connected (a TCP client, the pty, stdin): while another one is
        connected too, each line's echo goes out whole at its line end."""
        self._hosts.add(source)

    def end_source(self, source: object) -> None:
        """``source`` went away: forget its half line and end what it owned."""
        self._hosts.discard(source)
        if source is None:
            return
        self._host_baud.pop(source, None)
        self._host_frame.pop(source, None)
        self._assembly.pop(source, None)
        if self.on_source_end is not None:
            self.on_source_end(source)

    def _end_line(self, asm: _Assembly, source: object) -> None:
        raw = bytes(asm.buf)
        asm.buf.clear()
        if asm.overflow:
            asm.overflow = False
            log.debug("discarded over-long line (%d+ bytes)", MAX_LINE)
            return
        self.source = source
        try:
            self._on_line(raw.decode("latin-1"))
        finally:
            self.source = None


class _Assembly:
    """One sender's line in progress: its bytes, over-long flag and CRLF state, and
    its echo: held back (``held``), partly shown (``shown``), cut off by another
    host's line (``cut``)."""

    __slots__ = ("buf", "overflow", "last_was_cr", "held", "shown", "cut")

    def __init__(self) -> None:
        self.buf = bytearray()
        self.overflow = False
        self.last_was_cr = False
        self.held = bytearray()
        self.shown = False
        self.cut = False
