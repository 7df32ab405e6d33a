"""The Modbus doors' wire faults: what a request and its reply become (docs/wire-faults.md).

Both slave doors, COM0 in RTU mode (``modbus-rtu``) and the Modbus TCP door
(``modbus-tcp``), serve requests through :class:`~.slave.ModbusSlave`; the faults of
their kinds that act on the request are applied there (:func:`refusal`):

* ``no_reply``: the slave does not answer; the request is not served, as a request
  the slave never heard (a master that retries then writes once, not twice);
* ``exception``: the slave answers exception ``code`` instead of serving (5.6.8);

and the faults that act on the reply's framing are applied by the door that frames it
(:func:`rtu_reply` for RTU; the TCP door asks :func:`tcp_reply`):

* ``late`` (both): the reply goes out ``ms`` later;
* ``bad_crc`` (RTU): the CRC's bytes inverted, the frame otherwise right (5.6.3);
* ``wrong_slave`` (RTU) / ``wrong_unit`` (TCP): another address or unit identifier;
* ``silence`` (RTU): a pause of ``chars`` character times inside the frame, longer
  than the 3.5 that end a frame (5.6.2, ``gap``), or a second frame right behind the
  first without the silence (``merge``).

Only requests the slave would answer are messages (not broadcasts, not another
station's).  Each fault that acts is recorded with the bytes it changed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ...device.wire.schedule import ActiveFault, WireFaults
from ...sim.kernel import ms

__all__ = ["RtuReply", "TcpReply", "refusal", "rtu_reply", "tcp_reply", "REQUEST_KINDS"]

#: Kinds that act on the request (the slave's part).
REQUEST_KINDS = frozenset({"no_reply", "exception"})
RTU_KINDS = frozenset({"late", "bad_crc", "wrong_slave", "silence"})
TCP_KINDS = frozenset({"late", "wrong_unit"})


def refusal(faults: WireFaults, door: str, pdu: bytes) -> tuple[bool, bytes | None]:
    """``(True, reply)`` when a fault answers the request instead of the slave (``None``:
    no reply), ``(False, None)`` when the slave serves it."""
    if not faults.live(door):
        return False, None
    fault = faults.hit(door, REQUEST_KINDS)
    if fault is None:
        return False, None
    function = pdu[0] & 0x7F
    if fault.kind == "no_reply":
        faults.record(fault, f"request {pdu[:8].hex(' ')}{'...' if len(pdu) > 8 else ''}"
                             " not answered")
        return True, None
    code = int(fault.params["code"])
    faults.record(fault, f"function {function:02d} answered exception {code:02d}")
    return True, bytes((function | 0x80, code & 0xFF))


@dataclass(frozen=True)
class RtuReply:
    """How an RTU reply goes out: its bytes in pieces (the pause before each, ns), and
    how late the first piece goes."""

    pieces: tuple[tuple[int, bytes], ...]
    late: int = 0


def rtu_reply(faults: WireFaults, frame: bytes, char_ns: int,
              framed: Callable[[int, bytes], bytes]) -> RtuReply:
    """The reply ``frame`` (address, PDU, CRC) as the ``modbus-rtu`` faults make it;
    ``char_ns`` is one character's time at the line's rate (for ``silence``),
    ``framed(address, pdu)`` frames a PDU (for ``wrong_slave``)."""
    fault = faults.hit("modbus-rtu", RTU_KINDS) if faults.live("modbus-rtu") else None
    if fault is None:
        return RtuReply(((0, frame),))
    kind, params = fault.kind, fault.params
    if kind == "late":
        _record(faults, fault, frame, f"{params['ms']:g} ms late")
        return RtuReply(((0, frame),), ms(float(params["ms"])))
    if kind == "bad_crc":
        bad = frame[:-2] + bytes(b ^ 0xFF for b in frame[-2:])
        _record(faults, fault, frame, f"CRC {frame[-2:].hex(' ')} -> {bad[-2:].hex(' ')}")
        return RtuReply(((0, bad),))
    if kind == "wrong_slave":
        address, station = params.get("address"), frame[0]
        other = (station + 1) & 0xFF if address is None else int(address)
        _record(faults, fault, frame, f"from address {other} instead of {station}")
        return RtuReply(((0, framed(other, frame[1:-2])),))
    if params["mode"] == "merge":
        _record(faults, fault, frame, "followed by a second frame without the silence")
        return RtuReply(((0, frame + frame),))
    half = len(frame) // 2
    pause = round(float(params["chars"]) * char_ns)
    _record(faults, fault, frame, f"a pause of {params['chars']:g} characters after "
                                  f"byte {half}")
    return RtuReply(((0, frame[:half]), (pause, frame[half:])))


@dataclass(frozen=True)
class TcpReply:
    """How a Modbus TCP reply goes out: the unit id it carries and how late (ns)."""

    unit: int
    late: int = 0


def tcp_reply(faults: WireFaults, unit: int, adu: bytes) -> TcpReply:
    """The ``modbus-tcp`` faults' say on a reply to a request for ``unit`` (``adu``:
    the reply as it would go, for the record)."""
    fault = faults.hit("modbus-tcp", TCP_KINDS) if faults.live("modbus-tcp") else None
    if fault is None:
        return TcpReply(unit)
    if fault.kind == "late":
        _record(faults, fault, adu, f"{fault.params['ms']:g} ms late")
        return TcpReply(unit, ms(float(fault.params["ms"])))
    given = fault.params.get("unit")
    other = (unit + 1) & 0xFF if given is None else int(given)
    _record(faults, fault, adu, f"unit {other} instead of {unit}")
    return TcpReply(other)


def _record(faults: WireFaults, fault: ActiveFault, frame: bytes, what: str) -> None:
    faults.record(fault, f"reply {frame.hex(' ')[:3 * 24].rstrip()}"
                         f"{'...' if len(frame) > 24 else ''}: {what}")

