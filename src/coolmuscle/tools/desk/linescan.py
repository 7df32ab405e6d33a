"""``coolmuscle scan``: which motor IDs answer on a line, at which K20 rate, which firmware.

Only queries are sent (6.6 ``?85``, and ``K20.n`` / ``K65.1`` alone, ch. 3: a K number
without ``=`` answers its value), so a scan changes nothing on a running machine.

The rate (ch. 3 K20 table): on a serial line (a device, ``rfc2217://``) the K20 rates
are tried in turn, the factory 38.4 kbps first; on a socket there is no wire and one
try.  At each rate the probe is a lone CR (it ends whatever an earlier try left in the
motor's line buffer, as one bad line) and then ``?85.n`` + CR; the rate is right when
the motor's title for ``n`` comes back, or the echo of the query (the first motor of
the line echoes it, ch. 3 K23 8, even when ID ``n`` is not on the chain).

A motor at another rate reads the probe as garbage (docs/fidelity.md "Baud rate of the
host"), and a garbled byte may be a CML command: ``?85.1`` sent whole at 57.6 kbps reads
``)`` (motor free) at 9.6 kbps, run at the next CR.  So on a wire the probe goes out in
pieces with the line idle between them (:data:`PIECE_GAP`): ``?``, ``8``, ``5.``, each
digit, CR.  Under the UART model of :mod:`coolmuscle.device.uart`, with the rates off by
up to 3 %, a motor at any other K20 rate reads each piece as bytes above 0x7F or 0x00
only: no CML character and no line end (tests/test_desk_scan.py checks every pair).

The IDs: a daisy chain numbers its motors 1 to the final ID in order (5.6.6: a Modbus
slave on the final motor's COM1 is "the final Motor ID + 1"), so by default the scan
asks ID1, ID2 ... and stops at the first that does not answer; given IDs are all asked.

Time is bounded (:func:`scan_bound`): per rate tried, the pieces, a quiet wait of at
most :data:`QUIET_MAX` and twice the reply timeout; per ID asked, twice the reply
timeout (``?85`` and ``K20``) plus the wire time of a query and its answer across the
chain's links at K65 (1.1).  On ``coolmuscle://?mode=fast`` the waits are virtual time.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ...client.driver import port_clock
from ...client.replies import Version, parse_version
from ...device.hostline import BAUD_RATES
from ...errors import ProtocolError
from .errors import DeskError, NoMotorError
from .ports import has_wire, open_port, port_url

__all__ = ["SCAN_ORDER", "FoundMotor", "ScanResult", "scan", "scan_port", "scan_bound",
           "probe_pieces", "Lines"]

#: The K20 rates in the order they are tried: the factory rate (K20=0) first.
SCAN_ORDER = (38400, 9600, 19200, 57600, 115200, 230400)
#: Seconds a motor has to answer one query (a motor answers within milliseconds; a USB
#: serial adapter adds up to 16 ms).
REPLY_TIMEOUT = 0.3
#: Idle line between the pieces of the probe: several frames at 9.6 kbps (1.04 ms).
PIECE_GAP = 0.01
#: The motor is quiet (the answer to the lone CR is over) after this long without a byte.
QUIET = 0.05
#: The longest wait for quiet.
QUIET_MAX = 0.3
#: Bytes of a query and its answer crossing one link of the chain (1.1), for the timeout.
HOP_BYTES = 48
#: Read slice while waiting.
_READ_SLICE = 0.02
#: Every motor ID (1.1: up to 15 motors on one line).
ALL_IDS = tuple(range(1, 16))
_K_REPLY = re.compile(r"K(\d+)\.(\d+)=(-?\d+)")


def probe_pieces(motor: int) -> tuple[bytes, ...]:
    """``?85.n`` + CR as the pieces sent apart on a wire (module docstring)."""
    return (b"?", b"8", b"5.", *(digit.encode() for digit in str(motor)), b"\r")


@dataclass(frozen=True)
class FoundMotor:
    """A motor that answered: its ID, the ``?85`` title, its K20 (``None``: not read)."""

    motor: int
    title: str
    k20: int | None

    @property
    def version(self) -> Version:
        return parse_version(self.title)

    @property
    def firmware(self) -> str:
        """The profile the title suggests: ``cm2``, ``rt3`` or ``cm1`` (6.6 ?85); ``?``
        for a title not in the form of 6.6."""
        try:
            return self.version.profile()
        except ProtocolError:
            return "?"

    def line(self) -> str:
        """``ID1  K20=0 (38400 bit/s)  cm2  ID1 : CM2v3.10R.1 #0802A12345``."""
        if self.k20 is None:
            rate = "K20=?"
        else:
            rate = f"K20={self.k20} ({BAUD_RATES.get(self.k20, 0)} bit/s)"
        return f"ID{self.motor:<3}{rate}  {self.firmware}  {self.title}"


@dataclass(frozen=True)
class ScanResult:
    """What a scan found on ``url``: the rate it answered at (``None``: no wire) and the
    motors, in ID order."""

    url: str
    baud: int | None
    motors: tuple[FoundMotor, ...]
    seconds: float

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(m.motor for m in self.motors)

    def motor(self, motor_id: int) -> FoundMotor:
        found = next((m for m in self.motors if m.motor == motor_id), None)
        if found is None:
            raise LookupError(f"ID{motor_id} did not answer on {self.url}")
        return found

    def lines(self) -> list[str]:
        """One line per motor."""
        return [m.line() for m in self.motors]

    def summary(self) -> str:
        where = f"at {self.baud} bit/s" if self.baud else "(a socket: no wire, no rate)"
        count = len(self.motors)
        return (f"{count} motor{'s' if count != 1 else ''} on {self.url} {where} "
                f"({self.seconds:.1f} s)")


class Lines:
    """Complete lines read from a pyserial port, each wait bounded by a deadline on the
    port's clock (virtual seconds on ``coolmuscle://?mode=fast``)."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self._buffer = bytearray()
        self.now, _virtual = port_clock(port)

    def clear(self) -> None:
        self._buffer.clear()

    def _read(self) -> bytes:
        data: bytes = self.port.read(max(1, self.port.in_waiting))
        return data

    def until(self, wanted: Callable[[str], bool], timeout: float) -> list[str]:
        """Lines read until one is ``wanted`` or ``timeout`` s pass."""
        lines: list[str] = []
        deadline = self.now() + timeout
        while self.now() < deadline:
            self._buffer += self._read()
            while (end := re.search(rb"\r\n|\r|\n", self._buffer)) is not None:
                lines.append(self._buffer[:end.start()].decode("latin-1"))
                del self._buffer[:end.end()]
                if wanted(lines[-1]):
                    return lines
        return lines

    def quiet(self, quiet: float = QUIET, limit: float = QUIET_MAX) -> None:
        """Read and drop until nothing came for ``quiet`` s (at most ``limit`` s)."""
        start = last = self.now()
        while self.now() - start < limit and self.now() - last < quiet:
            if self._read():
                last = self.now()
        self._buffer.clear()


def _title_of(motor: int) -> Callable[[str], bool]:
    """The ``?85`` answer of ``motor``: ``ID1 : CM2v3.10R.1 #0802A12345`` (6.6), or any
    line that starts ``ID1 :`` (a title of a form 6.6 does not show)."""
    start = re.compile(rf"ID{motor}\s*:")

    def is_title(text: str) -> bool:
        return start.match(text) is not None
    return is_title


def send_pieces(port: Any, pieces: Iterable[bytes], wire: bool) -> None:
    """Write the pieces, the line idle :data:`PIECE_GAP` between them on a wire."""
    pieces = tuple(pieces)
    if not wire:
        port.write(b"".join(pieces))
        return
    for i, piece in enumerate(pieces):
        if i:
            time.sleep(PIECE_GAP)
        port.write(piece)


def ask_title(port: Any, lines: Lines, motor: int, timeout: float) -> str | None:
    """``?85.n`` (6.6): the motor's version title, or ``None``."""
    port.write(f"?85.{motor}\r".encode("ascii"))
    got = lines.until(_title_of(motor), timeout)
    return next((text for text in got if _title_of(motor)(text)), None)


def ask_k(port: Any, lines: Lines, motor: int, k: int, timeout: float) -> int | None:
    """``K#.n`` alone (ch. 3): the value of K#, or ``None``."""
    def is_reply(text: str) -> bool:
        match = _K_REPLY.fullmatch(text)
        return match is not None and (int(match.group(1)), int(match.group(2))) == (k, motor)
    port.write(f"K{k}.{motor}\r".encode("ascii"))
    got = lines.until(is_reply, timeout)
    reply = next((text for text in got if is_reply(text)), None)
    return int(reply.split("=")[1]) if reply is not None else None


def _try_rate(port: Any, lines: Lines, motor: int, timeout: float,
              wire: bool) -> tuple[bool, str | None]:
    """One try at the port's rate: (whether the line answers, the title of ``motor``)."""
    port.reset_input_buffer()
    lines.clear()
    send_pieces(port, (b"\r",), wire)
    lines.quiet()
    send_pieces(port, probe_pieces(motor), wire)
    is_title = _title_of(motor)
    query = f"?85.{motor}"
    got = lines.until(lambda text: is_title(text) or text == query, timeout)
    if query in got and not any(is_title(text) for text in got):
        got += lines.until(is_title, timeout)        # echoed: the title may follow
    title = next((text for text in got if is_title(text)), None)
    return title is not None or query in got, title


def hop_seconds(k65: int | None) -> float:
    """Wire time of a query and its answer across one link of the chain at K65."""
    baud = BAUD_RATES.get(k65, 9600) if k65 is not None else 9600
    return HOP_BYTES * 10 / baud


def scan_bound(bauds: Sequence[int], ids: Sequence[int], timeout: float = REPLY_TIMEOUT,
               wire: bool = True) -> float:
    """The longest a scan asking ``ids`` over ``bauds`` takes, in seconds (the reads of
    ID1's K65 and the last quiet wait included)."""
    pieces = (len(probe_pieces(max(ids))) + 1) * PIECE_GAP if wire else 0.0
    per_rate = pieces + QUIET_MAX + 2 * timeout
    tries = len(bauds) if wire else 1
    per_id = 2 * (timeout + (max(ids) - 1) * hop_seconds(None))
    return tries * per_rate + timeout + len(ids) * per_id + QUIET_MAX


def scan_port(port: Any, url: str, *, bauds: Sequence[int] | None = None,
              ids: Sequence[int] | None = None, timeout: float = REPLY_TIMEOUT,
              progress: Callable[[str], None] | None = None) -> ScanResult:
    """Scan an open port; it is left at the rate found (see the module docstring).
    ``ids``: the IDs to ask (default: 1, 2 ... up to the first that does not answer).

    Raises :class:`NoMotorError` when nothing answers."""
    chain = ids is None
    ids = _check_ids(ALL_IDS if ids is None else ids)
    started = time.monotonic()
    wire = has_wire(url)
    rates = tuple(bauds) if bauds else SCAN_ORDER
    saved_timeout = port.timeout
    port.timeout = _READ_SLICE
    lines = Lines(port)
    try:
        rate, first = _find_rate(port, lines, rates if wire else rates[:1], ids[0], timeout,
                                 wire, progress)
        if rate is None:
            raise NoMotorError(_nothing(url, rates if wire else (), ids[0], timeout))
        motors = _ask_motors(port, lines, ids, first, timeout, progress, chain)
    finally:
        port.timeout = saved_timeout
    if not motors:
        raise NoMotorError(f"the line {url} answers at {rate} bit/s but no motor of "
                           f"{_id_range(ids)} answered ?85")
    return ScanResult(url, rate if wire else None, tuple(motors),
                      time.monotonic() - started)


def _find_rate(port: Any, lines: Lines, rates: Sequence[int], motor: int, timeout: float,
               wire: bool, progress: Callable[[str], None] | None
               ) -> tuple[int | None, str | None]:
    for rate in rates:
        if wire:
            port.baudrate = rate
        if progress is not None:
            progress(f"trying {rate} bit/s" if wire else "asking (no wire: one try)")
        answered, title = _try_rate(port, lines, motor, timeout, wire)
        if answered:
            return rate, title
    return None, None


def _ask_motors(port: Any, lines: Lines, ids: Sequence[int], first: str | None,
                timeout: float, progress: Callable[[str], None] | None,
                chain: bool) -> list[FoundMotor]:
    motors: list[FoundMotor] = []
    hop = hop_seconds(ask_k(port, lines, 1, 65, timeout) if first and ids[0] == 1 else None)
    for motor in ids:
        allowance = timeout + (motor - 1) * hop
        title = first if motor == ids[0] else None
        if title is None:
            if progress is not None:
                progress(f"asking ID{motor}")
            title = ask_title(port, lines, motor, allowance)
        if title is not None:
            motors.append(FoundMotor(motor, title, ask_k(port, lines, motor, 20, allowance)))
        elif chain:
            break                         # the chain ends before this ID (5.6.6)
    lines.quiet()
    return motors


def _check_ids(ids: Sequence[int]) -> tuple[int, ...]:
    chosen = tuple(sorted(set(ids)))
    if not chosen or not all(1 <= i <= 15 for i in chosen):
        raise DeskError("motor IDs are 1..15")
    return chosen


def _id_range(ids: Sequence[int]) -> str:
    return f"ID{ids[0]}" if len(ids) == 1 else f"ID{ids[0]}-ID{ids[-1]}"


def _nothing(url: str, rates: Sequence[int], motor: int, timeout: float) -> str:
    if not rates:
        return (f"no motor answers on {url} (?85.{motor} within {timeout:g} s); is "
                "something serving that address?")
    if len(rates) == 1:
        return (f"no motor answers on {url} at {rates[0]} bit/s (?85.{motor} within "
                f"{timeout:g} s); a wrong --baud? (without it every K20 rate is tried)")
    tried = ", ".join(str(r) for r in rates[:-1]) + f" or {rates[-1]}"
    return (f"no motor answers on {url} at {tried} bit/s (?85.{motor} within {timeout:g} s "
            "at each); check the cable, the power and the port")


def scan(port: str, *, bauds: Sequence[int] | None = None,
         ids: Sequence[int] | None = None, timeout: float = REPLY_TIMEOUT,
         progress: Callable[[str], None] | None = None) -> ScanResult:
    """Scan PORT (a device, ``HOST:PORT`` or a pyserial URL); see :func:`scan_port`."""
    url = port_url(port)
    rates = tuple(bauds) if bauds else SCAN_ORDER
    opened = open_port(url, rates[0])
    try:
        return scan_port(opened, url, bauds=rates, ids=ids, timeout=timeout,
                         progress=progress)
    finally:
        opened.close()
