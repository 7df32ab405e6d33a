"""The wire-fault vocabulary: each door, the fault kinds it knows and their parameters.

A *door* is a way into the device that carries bytes (the host line, the daisy chain,
Modbus RTU and TCP, EtherNet/IP, EtherCAT).  Each door registers its
kinds here, with the schema of their parameters (:class:`Param`): the machine file's
``[[wire.fault]]`` tables, the device API's ``inject_wire_fault`` and the web page's
fault panel all check against this one registry, and docs/wire-faults.md describes it.

A kind is either *per message* (each message the door sends is a candidate: a reply
dropped, a frame with a bad CRC; ``every``, ``probability`` and ``count`` choose which)
or *lasting* (a state that holds from ``at`` to ``until``: the line dead, a motor
powered off, the CM1's serial link down).

The built-in doors are declared at the end of this module, as data: the model checks
a machine file before any front end is imported.  Another door adds its declaration
with :func:`register` in the same way.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

__all__ = ["Param", "FaultKind", "register", "kind_of", "doors", "kinds", "describe"]

#: A parameter's value, as a machine file or a JSON request gives it.
Value = int | float | str | bool


def finite(value: float) -> bool:
    """A finite number a float holds (an integer beyond 1.8e308 is not)."""
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


@dataclass(frozen=True)
class Param:
    """One parameter of a fault kind: its type, default, bounds or choices."""

    name: str
    type: type[int] | type[float] | type[str] | type[bool]
    default: Value | None
    doc: str
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple[str, ...] = ()

    def check(self, value: object, where: str) -> Value:
        """``value`` as this parameter's type; ``ValueError`` naming ``where`` if not."""
        if self.type is bool:
            if isinstance(value, bool):
                return value
            raise ValueError(f"{where}: {self.name} must be true or false, not {value!r}")
        if self.type is str:
            if isinstance(value, str) and (not self.choices or value in self.choices):
                return value
            raise ValueError(f"{where}: {self.name} must be one of {', '.join(self.choices)}, "
                             f"not {value!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                self.type is int and isinstance(value, float)
                and not value.is_integer()):
            kind = "an integer" if self.type is int else "a number"
            raise ValueError(f"{where}: {self.name} must be {kind}, not {value!r}")
        # the range first: an integer of 400 digits is out of it (float() would overflow)
        if not (self.lo <= value <= self.hi and finite(value)):
            raise ValueError(f"{where}: {self.name} must be {self.lo:g}..{self.hi:g}, "
                             f"not {value!r}")
        return int(value) if self.type is int else float(value)

    def describe(self) -> dict[str, object]:
        """The parameter as the web page shows it (JSON)."""
        out: dict[str, object] = {"name": self.name, "type": self.type.__name__,
                                  "default": self.default, "doc": self.doc}
        if math.isfinite(self.lo):
            out["min"] = self.lo
        if math.isfinite(self.hi):
            out["max"] = self.hi
        if self.choices:
            out["choices"] = list(self.choices)
        return out


@dataclass(frozen=True)
class FaultKind:
    """A fault a door knows: per message or lasting, with its parameters."""

    door: str
    name: str
    doc: str
    params: tuple[Param, ...] = ()
    lasting: bool = False
    #: ``"required"``: the fault names a motor (``motor = N``); ``"optional"``: it may
    #: (only that motor's messages); ``"none"``: the door has no motors.
    motor: str = "none"
    #: What each peer sees (docs/wire-faults.md): one short sentence.
    seen: str = ""

    def check_params(self, given: Mapping[str, object], where: str) -> dict[str, Value]:
        """Every parameter, checked, defaults filled in (``None`` defaults left out)."""
        known = {p.name: p for p in self.params}
        unknown = sorted(set(given) - set(known))
        if unknown:
            names = ", ".join(known) or "none"
            raise ValueError(f"{where}: {self.door} {self.name} takes no parameter "
                             f"{unknown[0]!r} (its parameters: {names})")
        out: dict[str, Value] = {}
        for name, param in known.items():
            if name in given:
                out[name] = param.check(given[name], where)
            elif param.default is not None:
                out[name] = param.default
        return out

    def describe(self) -> dict[str, object]:
        return {"door": self.door, "kind": self.name, "doc": self.doc,
                "lasting": self.lasting, "motor": self.motor, "seen": self.seen,
                "params": [p.describe() for p in self.params]}


@dataclass
class _Door:
    name: str
    doc: str
    kinds: dict[str, FaultKind] = field(default_factory=dict)


_DOORS: dict[str, _Door] = {}


def register(door: str, doc: str, kinds: Iterable[FaultKind]) -> None:
    """Declare ``door`` (or add to it) with its fault kinds; a kind's name is unique
    within its door.  Doors call this once, when their declaration is imported."""
    entry = _DOORS.setdefault(door, _Door(door, doc))
    for kind in kinds:
        if kind.door != door:
            raise ValueError(f"kind {kind.name!r} says door {kind.door!r}, not {door!r}")
        if kind.name in entry.kinds and entry.kinds[kind.name] != kind:
            raise ValueError(f"{door} already has a fault kind {kind.name!r}")
        entry.kinds[kind.name] = kind


def doors() -> tuple[str, ...]:
    """The doors known, in the order they were declared."""
    return tuple(_DOORS)


def kinds(door: str) -> tuple[FaultKind, ...]:
    """The fault kinds of ``door``; ``ValueError`` for an unknown door."""
    found = _DOORS.get(door)
    if found is None:
        raise ValueError(f"unknown wire-fault door {door!r} (known: {', '.join(_DOORS)})")
    return tuple(found.kinds.values())


def kind_of(door: object, kind: object) -> FaultKind:
    """The :class:`FaultKind` ``kind`` of ``door``; ``ValueError`` naming what exists."""
    if not isinstance(door, str):
        raise ValueError(f"a wire fault names its door (one of {', '.join(_DOORS)})")
    known = {k.name: k for k in kinds(door)}
    if not isinstance(kind, str) or kind not in known:
        raise ValueError(f"{door} has no fault kind {kind!r} (known: {', '.join(known)})")
    return known[kind]


def describe() -> dict[str, dict[str, object]]:
    """Every door and kind as JSON-ready data (the web page's fault panel)."""
    return {door.name: {"doc": door.doc,
                        "kinds": [k.describe() for k in door.kinds.values()]}
            for door in _DOORS.values()}


# -- the built-in doors --------------------------------------------------------------------
def _ms(name: str, default: float, doc: str, hi: float = 60_000.0) -> Param:
    return Param(name, float, default, doc, 0.0, hi)


#: Every per-message kind of the host line takes it.
_ECHO = Param("echo", bool, False, "the echo of what the host types is a message too "
              "(default: only what the motor answers and reports)")


register("host-line", "COM0 as the host reads it, on every transport (TCP, pty, stdio, "
         "a serial device, coolmuscle://): a message is one piece the motor sends "
         "(a reply line, a report, an echo, a Modbus RTU frame)", [
    FaultKind("host-line", "drop", "the message is lost", (_ECHO,),
              seen="the host library raises CoolMuscleTimeout; term says no reply came"),
    FaultKind("host-line", "garble", "one byte of the message is changed (a noise burst)", (
        Param("byte", int, None, "which byte: 0 the first, -1 the last; default: one "
              "before the line end, chosen by the fault's generator", -4096, 4095),
        Param("xor", int, None, "the bits flipped; default: one bit chosen by the "
              "fault's generator", 1, 255), _ECHO),
        seen="the host library raises ProtocolError (or CoolMuscleTimeout when the "
             "name is hit); term shows the unreadable line"),
    FaultKind("host-line", "delay", "the message arrives late; what follows waits "
              "behind it (bytes keep their order on a line)", (
                  _ms("ms", 100.0, "how late, milliseconds"), _ECHO),
              seen="a reply later than the host's timeout is a timeout, then an "
                   "unsolicited line"),
    FaultKind("host-line", "split", "the message arrives in pieces with gaps", (
        Param("pieces", int, 2, "how many pieces", 2, 64),
        _ms("gap_ms", 5.0, "silence between two pieces, milliseconds"), _ECHO),
        seen="a reader sees the line in several reads; a correct one joins them"),
    FaultKind("host-line", "duplicate", "the message arrives more than once", (
        Param("copies", int, 2, "how many times it arrives", 2, 16), _ECHO),
        seen="the host library takes the first copy and reports the rest as "
             "unsolicited lines"),
    FaultKind("host-line", "latency", "a USB-serial adapter's latency timer: what the "
              "motor sends reaches the host in blocks, when the timer runs out or a "
              "USB packet is full (FTDI: 16 ms, 62 bytes)", (
                  _ms("ms", 16.0, "the latency timer, milliseconds", 255.0),
                  Param("packet", int, 62, "bytes of one USB packet", 1, 4096)),
              lasting=True,
              seen="replies come up to the timer late, several lines in one read"),
    FaultKind("host-line", "dead", "the line is dead: nothing passes either way "
              "(a cable pulled, the adapter unplugged)", lasting=True,
              seen="no echo and no reply: CoolMuscleTimeout until it comes back"),
])

register("chain", "the daisy chain behind ID1 (cml-users-guide.txt 1.1, ch. 3 K65)", [
    FaultKind("chain", "power_off", "the motor is powered off: it answers nothing and "
              "relays nothing, so the motors beyond it are cut off too; when it comes "
              "back it powers up with its saved data only (ch. 3: what $ stored, and "
              "the K parameters, which persist by themselves)", lasting=True,
              motor="required",
              seen="silence from that ID and the IDs beyond; after until, the motor "
                   "answers with its saved registers and banks"),
    FaultKind("chain", "link_break", "the link from motor N to motor N+1 is broken: "
              "the motors beyond it get nothing from the host and their replies never "
              "arrive (they keep running what they run)", lasting=True,
              motor="required",
              seen="silence from the IDs beyond the link"),
])

def _modbus(door: str) -> list[FaultKind]:
    common = [
        FaultKind(door, "no_reply", "the request gets no reply",
                  seen="the master's response timeout; pymodbus retries"),
        FaultKind(door, "late", "the reply comes late (beyond the master's timeout)", (
            _ms("ms", 1500.0, "how late, milliseconds"),),
            seen="a timeout; the late reply then arrives as a stray frame"),
        FaultKind(door, "exception", "the request is refused with an exception code "
                  "instead of being served (5.6.8)", (
                      Param("code", int, 4, "the exception code (1 illegal function, 2 "
                            "illegal address, 3 illegal value, 4 device failure, 6 busy)",
                            1, 255),),
                  seen="pymodbus returns an ExceptionResponse with that code; mbpoll "
                       "prints it"),
    ]
    if door == "modbus-rtu":
        return [*common,
                FaultKind(door, "bad_crc", "the reply's CRC is wrong (5.6.3)",
                          seen="the master counts a CRC error and retries"),
                FaultKind(door, "wrong_slave", "the reply comes from another slave "
                          "address", (Param("address", int, None, "the address the reply "
                                            "carries; default: the station + 1", 0, 255),),
                          seen="the master drops the frame: a timeout"),
                FaultKind(door, "silence", "the 3.5-character silence between frames is "
                          "broken (5.6.2)", (
                              Param("mode", str, "gap", "gap: a pause inside the reply, "
                                    "longer than the silence that ends a frame; merge: "
                                    "another frame follows without the silence",
                                    choices=("gap", "merge")),
                              Param("chars", float, 4.0, "the pause, in character "
                                    "times (gap)", 0.0, 100000.0)),
                          seen="gap: two broken frames, a CRC error; merge: one long "
                               "frame, a CRC error")]
    return [*common,
            FaultKind(door, "wrong_unit", "the reply carries another unit identifier", (
                Param("unit", int, None, "the unit id the reply carries; default: the "
                      "request's + 1", 0, 255),),
                seen="the master drops or refuses the reply")]


register("modbus-rtu", "COM0 in Modbus RTU mode (5.6): a message is one reply frame",
         _modbus("modbus-rtu"))
register("modbus-tcp", "the Modbus TCP door: a message is one response ADU",
         _modbus("modbus-tcp"))

register("enip", "the CM1 EtherNet/IP module (cm1-ethernetip-interface-manual.txt)", [
    FaultKind("enip", "class1_loss", "Class 1 packets are lost (each packet is a "
              "message)", (
                  Param("direction", str, "o2t", "o2t: the scanner's packets (the "
                        "module's watchdog closes the connection after RPI x 4 x "
                        "2^multiplier); t2o: the module's packets (the scanner's "
                        "watchdog); both", choices=("o2t", "t2o", "both")),),
              seen="the connection times out: the module drops the I/O connection, "
                   "its outputs go back to all 0, Identity status shows a faulted "
                   "I/O connection; the scanner sees 0x01/0x0203 connection timed out"),
    FaultKind("enip", "forward_open_refused", "a Forward_Open is refused (each "
              "Forward_Open is a message)", (
                  Param("general", int, 0x01, "CIP general status", 1, 255),
                  Param("extended", int, 0x0113, "extended status (CIP Vol 1 table "
                        "3-5.33; 0x0113 out of connections); -1: none", -1, 0xFFFF)),
              seen="pycomm3 and ethernetip report the chosen general/extended status"),
    FaultKind("enip", "serial_link", "the module's serial link to the motor fails "
              "(3.1.1 communication error code)", (
                  Param("state", str, "timeout", "timeout: bit 1 (was working); "
                        "absent: bit 2 (never established); errors: bit 0",
                        choices=("timeout", "absent", "errors")),),
              lasting=True,
              seen="input image bytes 0-1 carry the bit; the motor values freeze; "
                   "outputs are not delivered"),
])

#: The bridge an ``ethercat`` fault acts at (1 = next to the master, line order).
#: Bridges an EtherCAT segment may have (``[ethercat] bridges``, ``--bridges``): 8 carry
#: a 32-axis line; the bound keeps a typo from building thousands.
MAX_BRIDGES = 64
_BRIDGE = Param("bridge", int, 1, "the bridge, in line order (1: next to the master)", 1,
                MAX_BRIDGES)

register("ethercat", "the EtherCAT bridges' segment (ethercat-bridge-users-guide.txt; "
         "ETG.1000.4): a message is one frame from the master, or one bridge cycle", [
    FaultKind("ethercat", "lost_frame", "the frame is lost on the wire", (
        Param("way", str, "out", "out: lost on its way to the bridge, which (and every "
              "bridge behind it) never sees it; back: lost on its way back to the master, "
              "after every bridge has processed it", choices=("out", "back")), _BRIDGE),
              seen="pysoem: receive_processdata returns -1 (no frame) for that cycle; "
                   "a lost mailbox or register frame is a failed read SOEM retries or "
                   "reports"),
    FaultKind("ethercat", "wkc", "a datagram's working counter is off when the frame "
              "comes back (ETG.1000.4 table 12: the counter the master checks)", (
                  Param("delta", int, -1, "added to the counter (-1: a slave seems not to "
                        "have served it; +1: one more than there are)", -3, 3),
                  Param("datagram", str, "process", "process: the frame's first logical "
                        "datagram (LRD, LWR, LRW: the process data), frames without one are "
                        "not messages; any: the frame's first datagram",
                        choices=("process", "any"))),
              seen="pysoem: receive_processdata returns expected_wkc - 1 (the process "
                   "data of that cycle is not to be trusted)"),
    FaultKind("ethercat", "mailbox_lost", "a mailbox answer is lost: the frame that "
              "read a bridge's full read mailbox (SM1) is lost on its way back, after the "
              "ESC has emptied the mailbox (each such frame is a message)", (
                  Param("bridge", int, 0, "only this bridge's answers (line order); 0: "
                        "any bridge's", 0, 8),),
              seen="SOEM: the mailbox read gets no working counter, so it toggles SM1's "
                   "repeat request and reads the answer again: the SDO completes"),
    FaultKind("ethercat", "link_down", "the cable into the bridge's port 0 is pulled: "
              "it and every bridge behind it leave the segment; their SM watchdogs run "
              "out (OP -> SAFE-OP + ERROR, AL status code 001Bh) while the motors run "
              "on; at until the cable is back", (_BRIDGE,), lasting=True,
              seen="pysoem: the working counter drops; read_state shows the bridge in "
                   "SAFE-OP + ERROR with al_status 0x001B once the link is back; "
                   "the master takes it to OP again"),
    FaultKind("ethercat", "late_cycle", "a bridge cycle (6.3: 1 ms) starts late; the "
              "cycles due meanwhile do not run (each cycle is a message)", (
                  _ms("ms", 3.0, "how late, milliseconds", 1000.0),),
              seen="pysoem: the inputs (statusword, position) stay as they were for "
                   "the cycles skipped; the outputs reach the motors late"),
])
