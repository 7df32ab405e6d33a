"""The ``enip`` door's wire faults on the adapter's packets (docs/wire-faults.md).

The fault state is the device's (``Device.wire_faults``, in virtual time); the adapter
asks it, through the model's thread (``Port.call``), what happens to each packet:

* ``class1_loss``: an O->T packet from the scanner is lost before the connection
  table sees it (so the module's watchdog runs out after RPI x 4 x 2^multiplier, CIP
  Vol 1 3-4.5.3, and the connection closes as a silent scanner's does), or the next
  T->O packet of a connection is produced and lost (the scanner's watchdog);
* ``forward_open_refused``: a Forward_Open is answered with the chosen general and
  extended status instead of being served;
* ``serial_link``: read by the module itself (:attr:`.cm1.adapter.Cm1Module.serial`).

Only a live fault costs anything: without one the adapter asks nothing.
"""

from __future__ import annotations

from ...device import Device
from .cip import messages as cip
from .cip.connmgr import OpenRequest
from .cip.io import Call, Connection
from .cip.messages import CipError

__all__ = ["EnipFaults"]

DOOR = "enip"


class EnipFaults:
    """What the ``enip`` wire faults do to one adapter's packets."""

    def __init__(self, device: Device, call: Call) -> None:
        self.device = device
        self.call = call
        self.o2t_lost = 0
        self.t2o_lost = 0

    # -- Class 1 ------------------------------------------------------------------------
    def lose_o2t(self, datagram: bytes) -> bool:
        """Whether this O->T datagram is lost (loop thread)."""
        if not self.device.wire_faults.live(DOOR):
            return False
        lost: bool = self.call(self._lose, "o2t", f"O->T packet lost ({len(datagram)} bytes)")
        self.o2t_lost += lost
        return lost

    def lose_t2o(self, conn: Connection) -> bool:
        """Whether the next T->O packet of ``conn`` is lost (the model's thread: the
        connection table's refresh)."""
        if not self.device.wire_faults.live(DOOR):
            return False
        lost = self._lose("t2o", f"T->O packet {conn.to_seq + 1} of connection "
                                 f"{conn.to_id:08X} lost")
        self.t2o_lost += lost
        return lost

    def _lose(self, direction: str, what: str) -> bool:
        faults = self.device.wire_faults
        fault = faults.hit(DOOR, ("class1_loss",), where=lambda f: f.params.get(
            "direction") in (direction, "both"))
        if fault is None:
            return False
        faults.record(fault, what)
        return True

    def timed_out(self, conns: list[Connection]) -> None:
        """Record the connections the watchdog closed while packets were being lost."""
        if conns and self.device.wire_faults.live(DOOR):
            self.call(self._timed_out, conns)

    def _timed_out(self, conns: list[Connection]) -> None:
        faults = self.device.wire_faults
        fault = next((f for f in faults.live_faults(DOOR) if f.kind == "class1_loss"), None)
        if fault is None:
            return
        for conn in conns:
            faults.record(fault, f"connection {conn.ot_id:08X} timed out after "
                                 f"{conn.timeout_ns / 1e6:g} ms without O->T packets")

    # -- Forward_Open ---------------------------------------------------------------------
    def check_open(self, req: OpenRequest) -> None:
        """Raise the refusal a ``forward_open_refused`` fault chooses (loop thread,
        under the connection table's lock)."""
        if not self.device.wire_faults.live(DOOR):
            return
        refusal: CipError | None = self.call(self._refusal, req)
        if refusal is not None:
            raise refusal

    def _refusal(self, req: OpenRequest) -> CipError | None:
        faults = self.device.wire_faults
        fault = faults.hit(DOOR, ("forward_open_refused",))
        if fault is None:
            return None
        general, extended = int(fault.params["general"]), int(fault.params["extended"])
        words = () if extended < 0 else (extended,)
        faults.record(fault, f"Forward_Open refused: general status 0x{general:02X}"
                             + (f", extended 0x{extended:04X}" if words else ""))
        if general == cip.CONNECTION_FAILURE and words:
            error = req.failure(*words)       # with the unsuccessful reply's body
            return CipError(general, error.extended, error.data)
        return CipError(general, words)
