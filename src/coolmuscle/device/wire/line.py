"""The host line's wire faults: what the host reads of what the motor sends.

:class:`LineFaults` sits where bytes leave the model (the host line hands it every
piece it sends, :meth:`coolmuscle.device.hostline.HostLine.write`, after the K20 wire
time when pacing is on), so every transport gets the same faults: TCP, the pty, stdio,
a serial device, the ``coolmuscle://`` URL, and RFC 2217.  A *message*
is one piece the motor sends: a reply or report line with its delimiter, an echo, a
Modbus RTU frame.  The ``host-line`` kinds (:mod:`.vocabulary`):

* ``drop``, ``garble``, ``delay``, ``split``, ``duplicate``: per message; the echo of
  what the host types is a message only for a fault with ``echo = true`` (so ``count =
  1`` drops the reply the host waits for, not its echo);
* ``latency``: a USB-serial adapter's latency timer (FTDI: the chip sends what it holds
  when its timer runs out, or at once when a USB packet is full);
* ``dead``: nothing passes either way; also while ID1 is powered off (the ``chain``
  door's ``power_off``: the host line is ID1's COM0).

Bytes keep their order on a line: a delayed or split message holds back what follows
it.  Without a live fault and with nothing held back, a piece goes straight through
(the fast path costs one lookup).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from ...sim.kernel import PRIO_REPORT, Kernel, Timer, ms
from ..uart import PLAIN, Frame
from .schedule import ActiveFault, WireFaults

__all__ = ["LineFaults", "shown"]

DOOR = "host-line"
#: The per-message kinds of the host line.
MESSAGE_KINDS = frozenset({"drop", "garble", "delay", "split", "duplicate"})
#: Bytes of a message a record shows.
SHOWN = 40

#: Gives bytes to the host's listeners with the motor's rate and frame on the wire.
Hand = Callable[[bytes, int, Frame], None]


def shown(data: bytes) -> str:
    """``data`` as a record shows it: printable ASCII as is, the rest escaped, cut."""
    text = "".join(chr(b) if 32 <= b < 127 and b != 92 else
                   {13: "\\r", 10: "\\n", 92: "\\\\"}.get(b, f"\\x{b:02x}")
                   for b in data[:SHOWN])
    return f'"{text}"' + ("..." if len(data) > SHOWN else "")


def _echoes(fault: ActiveFault) -> bool:
    return bool(fault.params.get("echo"))


class LineFaults:
    """The host-line faults of one host line (see the module docstring).

    ``hand`` gives bytes to the host's listeners (``HostLine.hand_out``)."""

    def __init__(self, kernel: Kernel, faults: WireFaults, hand: Hand) -> None:
        self.kernel = kernel
        self.faults = faults
        self._hand = hand
        self._free_at = 0            # the line to the host is busy until (held pieces)
        self._held = 0               # pieces scheduled, not yet delivered
        self._adapter = bytearray()  # what the USB-serial adapter holds (latency)
        self._baud, self._frame = 0, PLAIN   # how what the adapter holds was sent
        self._tick: Timer | None = None
        faults.watch(DOOR, self._lasting)

    # -- out: motor -> host ------------------------------------------------------------------
    def deliver(self, data: bytes, baud: int, frame: Frame = PLAIN,
                echo: bool = False) -> None:
        """A piece the motor sends, at ``kernel.now``, at ``baud`` in ``frame`` (0:
        unpaced); ``echo``: the echo of what the host typed, a message only for faults
        with ``echo = true``."""
        faults = self.faults
        if not (faults.live(DOOR) or faults.live("chain")) and not self._held \
                and not self._adapter:
            self._hand(data, baud, frame)
            return
        if self._dead():
            dead = faults.lasting(DOOR, "dead") or faults.lasting("chain", "power_off", 1)
            if dead is not None:
                faults.record(dead, f"{shown(data)} lost ({len(data)} bytes)")
            return
        fault = faults.hit(DOOR, MESSAGE_KINDS, where=_echoes if echo else None)
        pieces = [(0, data)] if fault is None else self._apply(fault, data)
        self._send(pieces, baud, frame, ms(float(fault.params["ms"]))
                   if fault is not None and fault.kind == "delay" else 0)

    def _apply(self, fault: ActiveFault, data: bytes) -> list[tuple[int, bytes]]:
        """The pieces (gap before each, bytes) ``fault`` makes of ``data``."""
        kind, params = fault.kind, fault.params
        if kind == "drop":
            self.faults.record(fault, f"{shown(data)} lost")
            return []
        if kind == "garble":
            return [(0, self._garble(fault, data))]
        if kind == "delay":
            self.faults.record(fault, f"{shown(data)} {params['ms']:g} ms late")
            return [(0, data)]
        if kind == "split":
            count = min(int(params["pieces"]), len(data))
            gap = ms(float(params["gap_ms"]))
            cuts = [len(data) * i // count for i in range(count + 1)]
            self.faults.record(fault, f"{shown(data)} in {count} pieces, "
                                      f"{params['gap_ms']:g} ms apart")
            return [(gap if i else 0, data[cuts[i]:cuts[i + 1]]) for i in range(count)]
        copies = int(params["copies"])
        self.faults.record(fault, f"{shown(data)} {copies} times")
        return [(0, data)] * copies

    def _garble(self, fault: ActiveFault, data: bytes) -> bytes:
        """``data`` with one byte changed: the one ``byte`` names (default: one before
        the line end, by the fault's generator), by ``xor`` (default: one bit)."""
        body = len(data.rstrip(b"\r\n")) or len(data)
        index = fault.params.get("byte")
        where = fault.rng.below(body) if index is None else int(index) % len(data)
        xor = fault.params.get("xor")
        mask = (1 << fault.rng.below(8)) if xor is None else int(xor)
        out = bytearray(data)
        out[where] ^= mask
        self.faults.record(fault, f"{shown(data)} byte {where} 0x{data[where]:02x} -> "
                                  f"0x{out[where]:02x}")
        return bytes(out)

    def _send(self, pieces: list[tuple[int, bytes]], baud: int, frame: Frame,
              late: int) -> None:
        """Deliver ``pieces`` in order, after what is held back, ``late`` ns late."""
        now = self.kernel.now
        at = max(now + late, self._free_at)
        for gap, piece in pieces:
            at += gap
            if at <= now and not self._held:
                self._out(piece, baud, frame)
                continue
            self._held += 1
            self.kernel.schedule_at(at, partial(self._later, piece, baud, frame),
                                    priority=PRIO_REPORT, name="host-line fault")
        self._free_at = at

    def _later(self, piece: bytes, baud: int, frame: Frame) -> None:
        self._held -= 1
        self._out(piece, baud, frame)

    def _out(self, piece: bytes, baud: int, frame: Frame) -> None:
        """A piece reaches the host's end of the line: through the adapter while a
        latency fault is live."""
        latency = self.faults.lasting(DOOR, "latency")
        if latency is None:
            self._flush()
            self._hand(piece, baud, frame)
            return
        self._baud, self._frame = baud, frame
        self._adapter += piece
        packet = int(latency.params["packet"])
        while len(self._adapter) >= packet:          # a full USB packet goes at once
            block = bytes(self._adapter[:packet])
            del self._adapter[:packet]
            self._hand(block, baud, frame)
        if self._adapter and self._tick is None:
            period = max(1, ms(float(latency.params["ms"])))
            now = self.kernel.now
            due = latency.start + ((now - latency.start) // period + 1) * period
            self._tick = self.kernel.schedule_at(due, self._timer_ran, priority=PRIO_REPORT,
                                                 name="usb latency timer")

    def _timer_ran(self) -> None:
        self._tick = None
        self._flush()

    def _flush(self) -> None:
        """The adapter sends what it holds (its timer ran out, or latency ended)."""
        if self._tick is not None:
            self._tick.cancel()
            self._tick = None
        if self._adapter:
            block = bytes(self._adapter)
            self._adapter.clear()
            self._hand(block, self._baud, self._frame)

    def _lasting(self, fault: ActiveFault, on: bool) -> None:
        if fault.kind == "latency" and not on:
            self._flush()

    # -- in: host -> motor ---------------------------------------------------------------------
    def _dead(self) -> bool:
        faults = self.faults
        return (faults.lasting(DOOR, "dead") is not None
                or faults.lasting("chain", "power_off", 1) is not None)

    def swallows(self, data: bytes) -> bool:
        """Whether the bytes the host sends now are lost (the line is dead)."""
        if not (self.faults.live(DOOR) or self.faults.live("chain")) or not self._dead():
            return False
        dead = self.faults.lasting(DOOR, "dead") or self.faults.lasting("chain", "power_off", 1)
        if dead is not None:
            self.faults.record(dead, f"{shown(data)} from the host lost")
        return True
