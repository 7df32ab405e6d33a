"""The motor as a Modbus slave: request PDU in, response PDU out (cml-users-guide.txt 5.6).

This module owns the behaviour both slave front ends share (COM0 RTU, Modbus TCP):

* which motor a Modbus address names: ID1 answers to K81 (5.6.3), a chain motor
  with a negative K84 to ``|K84|`` (5.6.6 setting example 2), address 0 is a
  broadcast every addressed motor executes without replying (5.6.4);
* the function codes of the host communication: 03, 04 and 16 (5.6.3 table);
  anything else is exception 01, an address outside the map exception 02 (5.6.8);
* FC16 data writes and the two CML command inputs at K78+100 / K78+102 with the
  CR terminator, the padding byte and the endian rule of the 5.6.7 examples.

A frame whose structure is broken (too short or too long for its function, a data
field that does not fit) gets no reply, as a Modbus slave drops garbage.  Every
choice where the manual is silent is in docs/fidelity.md "Modbus".  No I/O here.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ...device.wire.chain import cut_from
from .faults import refusal
from .registers import CML_COMMAND, CML_COMMAND_MODBUS, LONG, MotorMap, RegisterError, long_of

if TYPE_CHECKING:
    from ...device.api import Device

log = logging.getLogger(__name__)

#: Function codes of the host communication (5.6.3 table, "only in the host communication").
READ_HOLDING, READ_INPUT, WRITE_MULTIPLE = 0x03, 0x04, 0x10
SLAVE_FUNCTIONS = frozenset({READ_HOLDING, READ_INPUT, WRITE_MULTIPLE})

#: Exception codes (5.6.8).
ILLEGAL_FUNCTION = 0x01
ILLEGAL_ADDRESS = 0x02

BROADCAST = 0
#: Modbus TCP's "no gateway" unit identifier: always the motor behind the socket.
TCP_DIRECT_UNIT = 0xFF

CR = 0x0D
EQUALS = 0x3D

#: Firmware profiles whose K78..K84 are the Modbus parameters of 5.6 (CM1 reuses them).
MODBUS_FIRMWARES = frozenset({"cm2", "rt3"})
#: Profiles where K85 is the Modbus endian (RT3's K85 is the power-up logic bank).
ENDIAN_FIRMWARES = frozenset({"cm2"})


#: The sender name of the CML command inputs (K78+100 / K78+102) for bank uploads.
CML_SESSION = "cml-input"


def exception_pdu(function: int, code: int) -> bytes:
    """``function + 0x80`` and the exception code (5.6.8)."""
    return bytes((function | 0x80, code))


def firmware_name(device: Device) -> str:
    """The firmware profile name of ``device`` (``cm2`` when it does not say)."""
    firmware = getattr(device, "firmware", None)
    return str(getattr(firmware, "name", "cm2"))


def supports_modbus(device: Device) -> bool:
    """Whether the profile has the Modbus parameters K78–K85 of 5.6."""
    return firmware_name(device) in MODBUS_FIRMWARES


def decode_cml_command(data: bytes, *, binary_value: bool, little: bool) -> str:
    """The CML line an FC16 write to K78+100 (``binary_value``) or K78+102 carries.

    The command ends at the first CR (5.6.7 "Enter CR (0x0D) at the end of data");
    without a CR it is the whole data field less trailing NUL padding.  At K78+100
    the four bytes after the first ``=`` are the value as a binary long in K85
    order ("Endian should be applied to the data field after 0x3D").
    """
    if binary_value:
        eq = data.find(EQUALS)
        cr = data.find(CR)
        if eq >= 0 and (cr < 0 or eq < cr) and len(data) >= eq + 5:
            raw = data[eq + 1:eq + 5]
            value = long_of((raw[0] << 8) | raw[1], (raw[2] << 8) | raw[3], little)
            rest = _text_until_cr(data[eq + 5:])
            return data[:eq + 1].decode("latin-1") + str(value) + rest
    return _text_until_cr(data)


def _text_until_cr(data: bytes) -> str:
    cr = data.find(CR)
    text = data[:cr] if cr >= 0 else data.rstrip(b"\x00")
    return text.decode("latin-1")


class ModbusSlave:
    """The register map of 5.6.7 for every Modbus address of a chain (see module doc)."""

    def __init__(self, device: Device) -> None:
        self.device = device
        self.enabled = supports_modbus(device)
        self._endian_k85 = firmware_name(device) in ENDIAN_FIRMWARES
        self.requests = 0
        self.exceptions = 0
        self.dropped = 0

    # -- addressing -------------------------------------------------------------
    def addressed(self) -> dict[int, int]:
        """Modbus address -> motor ID on COM0: ID1 at ``|K81|``, chain motors at ``|K84|``.

        The first motor to claim an address keeps it (ID1 first, then by ID).
        """
        table: dict[int, int] = {}
        if not self.enabled:
            return table
        k81 = abs(self.device.get_param(1, 81))
        if k81:
            table[k81] = 1
        for motor in self.device.motor_ids:
            if motor == 1:
                continue
            k84 = self.device.get_param(motor, 84)
            if k84 < 0 and 0 < -k84 <= 0xFF:
                table.setdefault(-k84, motor)
        return table

    def targets(self, unit: int, *, tcp: bool = False) -> list[int]:
        """The motors a request to ``unit`` reaches (several for a broadcast)."""
        table = self.addressed()
        if tcp:   # the TCP door also works while COM0 is in text mode (K81=0)
            if 1 not in table.values():
                table.setdefault(1, 1)
            table[TCP_DIRECT_UNIT] = 1
        if unit == BROADCAST:
            return sorted(set(table.values()))
        motor = table.get(unit)
        return [] if motor is None else [motor]

    def _reached(self, motors: list[int]) -> list[int]:
        """The motors a request reaches: not one powered off or beyond a broken link
        (the chain's wire faults; the request travels the chain from COM0 of ID1)."""
        cut = cut_from(self.device.wire_faults)
        return [m for m in motors if m < cut] if cut else motors

    # -- requests -----------------------------------------------------------------
    def handle(self, unit: int, pdu: bytes, *, tcp: bool = False) -> bytes | None:
        """The response PDU to ``pdu`` sent to ``unit``, or ``None`` for no reply."""
        motors = self._reached(self.targets(unit, tcp=tcp))
        if not motors or not pdu or pdu[0] & 0x80:
            if motors:
                self.dropped += 1
            return None
        if unit != BROADCAST:       # a wire fault may answer it instead (docs/wire-faults.md)
            refused, answer = refusal(self.device.wire_faults,
                                      "modbus-tcp" if tcp else "modbus-rtu", pdu)
            if refused:
                return answer
        self.requests += 1
        reply: bytes | None = None
        for motor in motors:
            reply = self._handle_one(motor, pdu)
        if unit == BROADCAST:
            return None   # 5.6.4: executed without response
        if reply is None:
            self.dropped += 1
        elif reply[0] & 0x80:
            self.exceptions += 1
        return reply

    def _handle_one(self, motor: int, pdu: bytes) -> bytes | None:
        function = pdu[0]
        if function not in SLAVE_FUNCTIONS:
            return exception_pdu(function, ILLEGAL_FUNCTION)
        base = self.device.get_param(motor, 78)
        if base < 0:   # ch. 3 K78: "When K78=-1 is set, this function is not activated"
            return exception_pdu(function, ILLEGAL_FUNCTION)
        little = self._endian_k85 and self.device.get_param(motor, 85) in (1, 3)
        regs = MotorMap(self.device, motor, base, little)
        if function == WRITE_MULTIPLE:
            return self._write(regs, pdu)
        if len(pdu) != 5:
            return None   # a read is exactly function, address, count
        address = (pdu[1] << 8) | pdu[2]
        count = (pdu[3] << 8) | pdu[4]
        try:
            if function == READ_HOLDING:
                words = regs.read_holding(address, count)
            else:
                words = regs.read_input(address, count)
        except RegisterError as exc:
            log.debug("modbus: FC%02d ID%d: %s", function, motor, exc)
            return exception_pdu(function, ILLEGAL_ADDRESS)
        out = bytearray((function, 2 * len(words)))
        for word in words:
            out += word.to_bytes(2, "big")
        return bytes(out)

    def _write(self, regs: MotorMap, pdu: bytes) -> bytes | None:
        """FC16: data write or CML command (5.6.7 "Function Code 16")."""
        if len(pdu) < 6:
            return None
        address = (pdu[1] << 8) | pdu[2]
        count = (pdu[3] << 8) | pdu[4]
        # The data field is what follows the byte count; the count byte itself is
        # not trusted (the K78+100 example of 5.6.7 gives 6 for 8 data bytes).
        data = pdu[6:]
        echo = pdu[:5]
        rel = address - regs.base
        if rel in (CML_COMMAND, CML_COMMAND_MODBUS):
            text = decode_cml_command(data, binary_value=rel == CML_COMMAND, little=regs.little)
            # The CML inputs are their own sender: a bank upload opened here takes
            # only later CML inputs, never the register writes below.
            self.device.execute(text, origin="modbus", motor=regs.motor, session=CML_SESSION)
            return echo
        try:
            cells = regs.writable_cells(address, count)
        except RegisterError as exc:
            log.debug("modbus: FC16 ID%d: %s", regs.motor, exc)
            return exception_pdu(WRITE_MULTIPLE, ILLEGAL_ADDRESS)
        size = 2 * LONG * len(cells)
        # 5.6.7: "Enter CR (0x0D) at the end of data. Add 0x00 following CR when
        # data is an odd number." -- optional here, as standard masters send none.
        if len(data) < size or data[size:] not in (b"", b"\r", b"\r\x00"):
            return None
        for i, cell in enumerate(cells):
            raw = data[2 * LONG * i: 2 * LONG * (i + 1)]
            value = long_of((raw[0] << 8) | raw[1], (raw[2] << 8) | raw[3], regs.little)
            # The motor's own assignment: out-of-range values are not reflected
            # (ch. 3) and reported as error00 when K23 includes 16.
            self.device.execute(regs.assignment(cell, value), origin="modbus")
        return echo
