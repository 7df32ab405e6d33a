"""A sans-IO bench for the bridge's drive: a chain of four motors in virtual time, the
bridge application, and the master's two doors into it (SDO through the dictionary /
the CoE server, the 24-byte RxPDO image), with no network.

``Bench.cycles(n)`` runs n bridge cycles of 1 ms: the application's cycle is a kernel
event every millisecond (``BridgeApp.start_cycles``, what the transport starts in
``sim --ethercat``), and the kernel runs n milliseconds on.
"""

from __future__ import annotations

import struct
from typing import Any

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.engine.dictionary import SdoAbort
from coolmuscle.frontends.ethercat.engine.od import STRING
from coolmuscle.sim.kernel import Kernel

MS = 1_000_000
OFFSET = 0x800


def idx(index: int, axis: int) -> int:
    """ID1's ``index`` for ``axis`` (Appendix 6: + 0x800 per ID)."""
    return index + OFFSET * (axis - 1)


class Bench:
    """Bridge + chain in virtual time, driven by hand."""

    def __init__(self, bridge: str = "EB02", machine: Any = None, firmware: str | None = None,
                 **chain: Any) -> None:
        from coolmuscle.frontends.ethercat.bridge import identity as ident
        fw = firmware or ",".join(ident.variant(bridge).firmware)
        self.kernel = Kernel()
        self.chain = Chain(self.kernel, 4, firmware=fw, machine=machine, **chain)
        self.ticks = [0]
        self.app = BridgeApp(self.chain, bridge)
        self.app.drive.clock = lambda: self.kernel.now
        self.od = self.app.dictionary
        self.rx = bytearray(24)
        self.app.start_cycles(MS)
        self.cycles(1)

    @property
    def drive(self) -> Any:
        return self.app.drive

    def axis(self, n: int) -> Any:
        return self.app.drive.axes[n]

    # -- time ------------------------------------------------------------------------
    def cycles(self, n: int = 1) -> None:
        self.kernel.run(until=self.kernel.now + n * MS)

    def until(self, predicate: Any, limit_ms: int) -> int:
        """Cycles until ``predicate()``; how many it took (AssertionError past the limit)."""
        for i in range(limit_ms):
            if predicate():
                return i
            self.cycles(1)
        raise AssertionError(f"not reached within {limit_ms} ms")

    # -- PDO (6.3.1) --------------------------------------------------------------------
    def pdo(self, axis: int, controlword: int, target: int | None = None) -> None:
        """Set one axis' part of the RxPDO image and deliver it as an SM2 write would."""
        off = 6 * (axis - 1)
        struct.pack_into("<H", self.rx, off, controlword & 0xFFFF)
        if target is not None:
            struct.pack_into("<i", self.rx, off + 2, target)
        self.od.unpack_outputs(bytes(self.rx))
        self.app.outputs(bytes(self.rx))

    def status(self, axis: int = 1) -> int:
        return struct.unpack_from("<H", self.tx(), 6 * (axis - 1))[0]

    def position(self, axis: int = 1) -> int:
        return struct.unpack_from("<i", self.tx(), 6 * (axis - 1) + 2)[0]

    def tx(self) -> bytes:
        return self.od.pack_inputs()

    # -- SDO (5.4) -------------------------------------------------------------------------
    def write(self, index: int, sub: int, value: int | str) -> None:
        _obj, entry = self.od.lookup(index, sub)
        self.od.write(index, sub, entry.dtype.encode(value))

    def read(self, index: int, sub: int = 0) -> int | str:
        _obj, entry = self.od.lookup(index, sub)
        data = self.od.read(index, sub)
        return data.decode("latin-1") if entry.dtype is STRING else entry.dtype.decode(data)

    def abort(self, index: int, sub: int, value: int | str | bytes | None = None) -> int:
        """The abort code of a write (or, ``value`` None, a read); 0 when accepted."""
        try:
            if value is None:
                self.read(index, sub)
            elif isinstance(value, bytes):
                self.od.write(index, sub, value)
            else:
                self.write(index, sub, value)
        except SdoAbort as exc:
            return exc.code
        return 0

    def switch_mode(self, mode: int, axis: int = 1) -> int:
        """Appendix 3: 6060h by SDO, then 6061h every 5 ms until it shows; ms taken."""
        self.write(idx(0x6060, axis), 0, mode)
        waited = 0
        while self.read(idx(0x6061, axis)) != mode:
            self.cycles(5)
            waited += 5
            assert waited < 100, "6061h never showed the mode"
        return waited

    def enable(self, axes: tuple[int, ...] = (1, 2, 3, 4)) -> None:
        """6.1.2: 06h, 07h, 0Fh with the target at the actual position."""
        for cw in (0x06, 0x07, 0x0F):
            for a in axes:
                self.pdo(a, cw, self.position(a))
            self.cycles(2)
