"""The EtherCAT slave controller (ESC): a sans-IO core, frames in and frames out.

Owns what a real ESC does in hardware (ETG.1000.4, the ESC datasheet section II):
the register space, the 14 datagram commands with their working-counter rules and
auto-increment addressing, the FMMUs (:mod:`.fmmu`), the SyncManagers (mailbox
full/empty and repeat, buffered process data), the SII EEPROM interface, the DC
receive-time registers a master reads, and the SM watchdog.  A SyncManager guards
process RAM only: the settings of an activated one are not written (datasheet
0x0800: "r/(w)", written only while deactivated), and one whose buffer is not inside
the process RAM (0x1000 up) is not activated, so no mailbox is ever written over the
registers (docs/fidelity.md, the ESC).  No socket, no clock inside:
:meth:`Esc.process` takes a frame and the time ``now`` (ns) and returns the frame to
send on; :meth:`Esc.tick` runs the watchdog.  It knows nothing of the device behind
it: what a real chip loads from its EEPROM at power-up (PDI control, station alias)
it reads from the SII image it is given.

The firmware side (the slave stack, :mod:`.slave`) is the :class:`Pdi`: the ESC
calls it when the master writes AL control, fills the receive mailbox, empties the
send mailbox, completes an output buffer or lets the watchdog expire.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass
from typing import Protocol

from . import fmmu

log = logging.getLogger(__name__)

ETHERTYPE_ECAT = 0x88A4

# Datagram commands (ETG.1000.4 table 12).
NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW = range(15)
COMMAND_NAMES = ("NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD", "BWR", "BRW",
                 "LRD", "LWR", "LRW", "ARMW", "FRMW")
_AUTO = {APRD, APWR, APRW, ARMW}
_FIXED = {FPRD, FPWR, FPRW, FRMW}
_BCAST = {BRD, BWR, BRW}
_READS = {APRD, FPRD, BRD}
_WRITES = {APWR, FPWR, BWR}
_READ_WRITES = {APRW, FPRW, BRW}

# Register addresses (ETG.1000.4 / ESC datasheet section II).
REG_TYPE = 0x0000
REG_STATION = 0x0010
REG_ALIAS = 0x0012
REG_DL_CONTROL = 0x0100
REG_DL_STATUS = 0x0110
REG_AL_CONTROL = 0x0120
REG_AL_STATUS = 0x0130
REG_AL_CODE = 0x0134
REG_PDI_CONTROL = 0x0140
REG_ERR_COUNTERS = 0x0300
REG_WD_DIVIDER = 0x0400
REG_WD_PDI = 0x0410
REG_WD_SM = 0x0420
REG_WD_STATUS = 0x0440
REG_WD_COUNT_SM = 0x0442
REG_SII_CONFIG = 0x0500
REG_SII_CONTROL = 0x0502
REG_SII_ADDRESS = 0x0504
REG_SII_DATA = 0x0508
REG_FMMU = 0x0600
REG_SM = 0x0800
REG_DC_RECV = 0x0900
REG_DC_SYSTIME = 0x0910
REG_DC_RECV_PU = 0x0918

N_FMMU = 3          # FMMU0 outputs, FMMU1 inputs, FMMU2 mailbox status
N_SM = 4            # SM0/SM1 mailbox, SM2/SM3 process data
RAM_START = 0x1000
RAM_SIZE = 8 * 1024
MEM_SIZE = RAM_START + RAM_SIZE

#: Bytes the master may write (ECAT side), as (start, end) half-open ranges.
_WRITABLE = (
    (0x0010, 0x0012), (0x0100, 0x0104), (0x0108, 0x010A), (0x0120, 0x0122),
    (0x0138, 0x013A), (0x0200, 0x0204), (0x0300, 0x0314), (0x0400, 0x0402),
    (0x0410, 0x0412), (0x0420, 0x0422), (0x0502, 0x0510),
    (REG_FMMU, REG_FMMU + 16 * N_FMMU), (0x0900, 0x0904), (0x0910, 0x0918),
    (0x0920, 0x0938), (0x0980, 0x0982), (0x0990, 0x09B0), (RAM_START, MEM_SIZE),
)

SM_MODE_MAILBOX = 0x02


class Pdi(Protocol):
    """The firmware side of the ESC (ETG.1000.4 'PDI'): events it must react to."""

    def al_control(self, value: int) -> None:
        """The master wrote AL control (0x0120)."""

    def mailbox_received(self, sm: int, data: bytes) -> None:
        """A write mailbox SyncManager became full."""

    def mailbox_read(self, sm: int) -> None:
        """The master read a read mailbox completely (it is empty again)."""

    def outputs_written(self, sm: int, data: bytes) -> None:
        """A buffered write SyncManager received a complete buffer."""

    def watchdog_expired(self) -> None:
        """The SM watchdog expired (no output buffer within its time)."""

    def sm_changed(self, sm: int) -> None:
        """The master activated or deactivated SyncManager ``sm`` (AL event "SM change")."""


@dataclass
class SyncManager:
    """One SyncManager's registers and buffer state (ESC datasheet section II 0x0800)."""

    number: int
    start: int = 0
    length: int = 0
    control: int = 0
    status: int = 0
    activate: int = 0
    pdi_control: int = 0

    @property
    def enabled(self) -> bool:
        return bool(self.activate & 0x01) and self.length > 0 \
            and not self.pdi_control & 0x01 and self.in_ram

    @property
    def in_ram(self) -> bool:
        """Its buffer lies inside the process RAM (a SyncManager guards RAM, never the
        registers below 0x1000)."""
        return RAM_START <= self.start and self.start + self.length <= MEM_SIZE

    @property
    def mailbox(self) -> bool:
        return self.control & 0x03 == SM_MODE_MAILBOX

    @property
    def master_writes(self) -> bool:
        """Direction ECAT write / PDI read (control bits 2-3 = 01)."""
        return (self.control >> 2) & 0x03 == 0x01

    @property
    def full(self) -> bool:
        return bool(self.status & 0x08)

    @property
    def end(self) -> int:
        return self.start + self.length


class Esc:
    """Registers, memory and datagram processing of one emulated ESC."""

    def __init__(self, pdi: Pdi, sii: bytes, *, esc_type: int = 0x98) -> None:
        self.pdi = pdi
        self.sii = bytearray(sii)
        self.mem = bytearray(MEM_SIZE)
        self._wmask = bytearray(MEM_SIZE)
        for lo, hi in _WRITABLE:
            self._wmask[lo:hi] = b"\x01" * (hi - lo)
        for n in range(N_SM):          # SM start, length, control, activate (not status, PDI)
            base = REG_SM + 8 * n
            self._wmask[base:base + 5] = b"\x01" * 5
            self._wmask[base + 6] = 1
        self.sm = [SyncManager(i) for i in range(N_SM)]
        self._fmmu: tuple[fmmu.Fmmu, ...] = ()
        self._inputs: dict[int, bytes] = {}
        self._mbx_out: dict[int, bytes] = {}
        self._wd_last: int | None = None
        self._wd_expired = False
        self._now = 0
        self.frames = 0
        self.datagrams = 0
        self._reset_registers(esc_type)

    # -- power-up values -------------------------------------------------------
    def _reset_registers(self, esc_type: int) -> None:
        m = self.mem
        m[0x0000] = esc_type          # type (not an ET1100: an emulation, docs/fidelity.md)
        m[0x0001] = 0x01              # revision
        struct.pack_into("<H", m, 0x0002, 0x0001)   # build
        m[0x0004] = N_FMMU
        m[0x0005] = N_SM
        m[0x0006] = RAM_SIZE // 1024
        m[0x0007] = 0x0F              # ports 0 and 1: MII
        struct.pack_into("<H", m, 0x0008, 0x0000)   # features: bit FMMUs, no DC
        struct.pack_into("<H", m, REG_DL_STATUS, 0x5613)
        struct.pack_into("<H", m, REG_AL_STATUS, 0x0001)
        if len(self.sii) >= 2:
            m[REG_PDI_CONTROL:REG_PDI_CONTROL + 2] = self.sii[0:2]   # SII word 0: PDI
        struct.pack_into("<H", m, REG_WD_DIVIDER, 2498)      # 100 us units
        struct.pack_into("<H", m, REG_WD_PDI, 1000)
        struct.pack_into("<H", m, REG_WD_SM, 1000)           # 100 ms
        struct.pack_into("<H", m, REG_WD_STATUS, 0x0001)
        struct.pack_into("<H", m, REG_SII_CONTROL, 0x0040)   # 8-byte reads
        if len(self.sii) >= 10:
            m[REG_ALIAS:REG_ALIAS + 2] = self.sii[8:10]      # SII word 4: station alias
        struct.pack_into("<H", m, REG_DL_CONTROL, 0x0001)

    # -- the firmware's side (PDI) ----------------------------------------------
    def set_al_status(self, status: int, code: int | None = None) -> None:
        """Write AL status (0x0130) and, if given, the AL status code (0x0134)."""
        struct.pack_into("<H", self.mem, REG_AL_STATUS, status & 0xFFFF)
        if code is not None:
            struct.pack_into("<H", self.mem, REG_AL_CODE, code & 0xFFFF)

    @property
    def al_status(self) -> int:
        return self.mem[REG_AL_STATUS] | self.mem[REG_AL_STATUS + 1] << 8

    @property
    def al_code(self) -> int:
        return self.mem[REG_AL_CODE] | self.mem[REG_AL_CODE + 1] << 8

    @property
    def al_control_value(self) -> int:
        return self.mem[REG_AL_CONTROL] | self.mem[REG_AL_CONTROL + 1] << 8

    @property
    def station(self) -> int:
        return self.mem[REG_STATION] | self.mem[REG_STATION + 1] << 8

    def post_mailbox(self, sm: int, data: bytes) -> bool:
        """Put a message in read mailbox ``sm``; False when it is still full."""
        s = self.sm[sm]
        if not s.enabled or s.full:
            return False
        body = bytes(data[:s.length]).ljust(s.length, b"\x00")
        self.mem[s.start:s.end] = body
        self._mbx_out[sm] = body
        s.status |= 0x08
        self._sync_sm_regs(s)
        return True

    def take_mailbox(self, sm: int) -> None:
        """The firmware has read write mailbox ``sm``: it is empty again."""
        s = self.sm[sm]
        s.status &= ~0x08 & 0xFF
        self._sync_sm_regs(s)

    def set_inputs(self, sm: int, data: bytes) -> None:
        """New contents of the buffered read SyncManager ``sm`` (thread-safe swap)."""
        self._inputs[sm] = bytes(data)

    # -- time ------------------------------------------------------------------
    def watchdog_ns(self) -> int:
        """SM watchdog time: 0x0420 x (0x0400 + 2) x 40 ns; 0 = disabled."""
        divider: int
        time_sm: int
        divider, = struct.unpack_from("<H", self.mem, REG_WD_DIVIDER)
        time_sm, = struct.unpack_from("<H", self.mem, REG_WD_SM)
        return time_sm * (divider + 2) * 40

    def _wd_sm(self) -> SyncManager | None:
        for s in self.sm:
            if s.enabled and not s.mailbox and s.master_writes and s.control & 0x40:
                return s
        return None

    def tick(self, now: int) -> None:
        """Run the SM watchdog at time ``now`` (ns)."""
        self._now = now
        if self._wd_last is None or self._wd_expired:
            return
        limit = self.watchdog_ns()
        if limit and self._wd_sm() is not None and now - self._wd_last > limit:
            self._wd_expired = True
            self.mem[REG_WD_STATUS] &= 0xFE
            self.mem[REG_WD_COUNT_SM] = min(0xFF, self.mem[REG_WD_COUNT_SM] + 1)
            self.pdi.watchdog_expired()

    # -- frames ----------------------------------------------------------------
    def process(self, frame: bytes | bytearray | memoryview, now: int = 0) -> bytearray | None:
        """Process one Ethernet frame; return the frame to send on, None if not EtherCAT."""
        self._now = now
        if len(frame) < 16 or frame[12] != 0x88 or frame[13] != 0xA4:
            return None
        buf = bytearray(frame)
        buf[6] |= 0x02                 # ESC marks the source MAC on its way back (ETG.1000.4)
        header = buf[14] | buf[15] << 8
        if header >> 12 != 1:          # not a datagram frame: passes through untouched
            return buf
        self.frames += 1
        end = min(16 + (header & 0x7FF), len(buf))
        pos = 16
        while pos + 12 <= end:
            length = (buf[pos + 6] | buf[pos + 7] << 8) & 0x7FF
            more = buf[pos + 7] & 0x80
            data_end = pos + 10 + length
            if data_end + 2 > end:
                break                  # truncated datagram: the rest is not processed
            self.datagrams += 1
            self._datagram(buf, pos, length)
            pos = data_end + 2
            if not more:
                break
        self.tick(now)
        return buf

    def _datagram(self, buf: bytearray, pos: int, length: int) -> None:
        cmd = buf[pos]
        adp = buf[pos + 2] | buf[pos + 3] << 8
        ado = buf[pos + 4] | buf[pos + 5] << 8
        data = pos + 10
        wkc_at = data + length
        inc = 0
        if cmd in _AUTO or cmd in _BCAST:
            struct.pack_into("<H", buf, pos + 2, (adp + 1) & 0xFFFF)
        if cmd in (APRD, APWR, APRW):
            ours = adp == 0
        elif cmd == ARMW or cmd == FRMW:
            ours = True                # the addressed slave reads, every other one writes
        elif cmd in _FIXED:
            ours = adp == self.station or (adp == self._alias() and adp != 0)
        elif cmd in _BCAST:
            ours = True
        elif cmd in (LRD, LWR, LRW):
            inc = self._logical(cmd, buf, struct.unpack_from("<I", buf, pos + 2)[0], data, length)
            ours = False
        else:
            ours = False
        if ours:
            inc = self._physical(cmd, buf, ado, data, length, adp)
        if inc:
            wkc = (buf[wkc_at] | buf[wkc_at + 1] << 8) + inc
            struct.pack_into("<H", buf, wkc_at, wkc & 0xFFFF)

    def _alias(self) -> int:
        if not self.mem[REG_DL_CONTROL + 3] & 0x01:
            return -1
        return self.mem[REG_ALIAS] | self.mem[REG_ALIAS + 1] << 8

    def _physical(self, cmd: int, buf: bytearray, ado: int, data: int, length: int,
                  adp: int) -> int:
        if cmd in _READS:
            got = self.read(ado, length)
            if got is None:
                return 0
            if cmd == BRD:
                old = buf[data:data + length]
                got = bytes(a | b for a, b in zip(old, got))
            buf[data:data + length] = got
            return 1
        if cmd in _WRITES:
            return 1 if self.write(ado, bytes(buf[data:data + length])) else 0
        if cmd in _READ_WRITES:
            incoming = bytes(buf[data:data + length])
            got = self.read(ado, length)
            inc = 0
            if got is not None:
                buf[data:data + length] = bytes(a | b for a, b in zip(incoming, got)) \
                    if cmd == BRW else got
                inc += 1
            if self.write(ado, incoming):
                inc += 2
            return inc
        if cmd == ARMW:
            if adp == 0:
                got = self.read(ado, length)
                if got is None:
                    return 0
                buf[data:data + length] = got
                return 1
            return 1 if self.write(ado, bytes(buf[data:data + length])) else 0
        if cmd == FRMW:
            if adp == self.station:
                got = self.read(ado, length)
                if got is None:
                    return 0
                buf[data:data + length] = got
                return 1
            return 1 if self.write(ado, bytes(buf[data:data + length])) else 0
        return 0

    # -- FMMU ------------------------------------------------------------------
    def _logical(self, cmd: int, buf: bytearray, addr: int, data: int, length: int) -> int:
        """LRD/LWR/LRW through the FMMUs decoded when they were configured: each one
        costs the bits it shares with the datagram."""
        incoming = bytes(buf[data:data + length]) if cmd != LRD else b""
        read_done = write_done = False
        for f in self._fmmu:
            lo, hi = f.overlap(addr, length)
            if lo >= hi:
                continue
            if f.reads and cmd != LWR and self._map_read(f, buf, data, addr, lo, hi):
                read_done = True
            if f.writes and cmd != LRD and self._map_write(f, incoming, addr, lo, hi):
                write_done = True
        if cmd == LRW:
            return (1 if read_done else 0) + (2 if write_done else 0)
        return 1 if (read_done or write_done) else 0

    def _map_read(self, f: fmmu.Fmmu, buf: bytearray, data: int, addr: int, lo: int,
                  hi: int) -> bool:
        """Logical bits ``[lo, hi)`` of the datagram at ``data`` from physical memory."""
        count, phys = hi - lo, f.pbit + lo - f.lbit
        if f.aligned:
            got = self.read(phys // 8, count // 8)
            if got is None:
                return False
            buf[data + lo // 8 - addr:data + hi // 8 - addr] = got
            return True
        first = phys // 8
        got = self.read(first, (phys + count - 1) // 8 - first + 1)
        if got is None:
            return False
        fmmu.copy_bits(got, phys - first * 8, buf, (data - addr) * 8 + lo, count)
        return True

    def _map_write(self, f: fmmu.Fmmu, incoming: bytes, addr: int, lo: int, hi: int) -> bool:
        """Logical bits ``[lo, hi)`` of the datagram's data ``incoming`` to physical memory
        (the physical bits around them keep their values)."""
        count, phys = hi - lo, f.pbit + lo - f.lbit
        if f.aligned:
            return self.write(phys // 8, incoming[lo // 8 - addr:hi // 8 - addr])
        first, last = phys // 8, (phys + count - 1) // 8
        cur = bytearray(bytes(self.mem[first:last + 1]).ljust(last + 1 - first, b"\x00"))
        fmmu.copy_bits(incoming, lo - addr * 8, cur, phys - first * 8, count)
        return self.write(first, bytes(cur))

    # -- physical memory ---------------------------------------------------------
    def _sm_hits(self, addr: int, length: int) -> list[SyncManager]:
        end = addr + length
        return [s for s in self.sm if s.enabled and s.start < end and addr < s.end]

    def read(self, addr: int, length: int) -> bytes | None:
        """ECAT read of ``length`` bytes at ``addr``; None when the ESC refuses (no WKC)."""
        end = addr + length
        hits = self._sm_hits(addr, length) if end > RAM_START else []
        for s in hits:
            if s.mailbox:
                if s.master_writes or not s.full:
                    return None
            elif not s.master_writes:
                image = self._inputs.get(s.number)
                if image is not None:
                    self.mem[s.start:s.end] = image[:s.length].ljust(s.length, b"\x00")
        if addr < REG_DC_RECV_PU + 8 and end > REG_DC_SYSTIME:
            struct.pack_into("<Q", self.mem, REG_DC_SYSTIME, self._now & (2**64 - 1))
        if addr >= MEM_SIZE:
            out = bytes(length)
        else:
            out = bytes(self.mem[addr:min(end, MEM_SIZE)]).ljust(length, b"\x00")
        for s in hits:
            if s.mailbox and addr <= s.end - 1 < end:
                s.status &= ~0x08 & 0xFF
                self._sync_sm_regs(s)
                self.pdi.mailbox_read(s.number)
        return out

    def write(self, addr: int, data: bytes) -> bool:
        """ECAT write; False when the ESC refuses it (a full mailbox: no WKC)."""
        end = addr + len(data)
        hits = self._sm_hits(addr, len(data)) if end > RAM_START else []
        for s in hits:
            if s.mailbox and (not s.master_writes or s.full):
                return False
        mem, mask = self.mem, self._wmask
        touched_regs = addr < RAM_START
        for i, byte in enumerate(data, addr):
            if i >= MEM_SIZE:
                break
            if mask[i]:
                mem[i] = byte
        if touched_regs:
            self._register_written(addr, min(end, RAM_START), data)
        for s in hits:
            if addr <= s.end - 1 < end:
                body = bytes(mem[s.start:s.end])
                if s.mailbox:
                    s.status |= 0x08
                    self._sync_sm_regs(s)
                    self.pdi.mailbox_received(s.number, body)
                else:
                    if s.control & 0x40:
                        self._wd_last = self._now
                        if self._wd_expired:
                            self._wd_expired = False
                            self.mem[REG_WD_STATUS] |= 0x01
                    self.pdi.outputs_written(s.number, body)
        return True

    # -- register side effects --------------------------------------------------
    def _register_written(self, lo: int, hi: int, data: bytes) -> None:
        def hit(a: int, b: int) -> bool:
            return lo < b and a < hi
        if hit(REG_SM, REG_SM + 8 * N_SM):
            self._sm_written(lo, hi)
        if hit(REG_FMMU, REG_FMMU + fmmu.FMMU_SIZE * N_FMMU):
            self._fmmu = fmmu.decode(self.mem, REG_FMMU, N_FMMU)
        if hit(REG_SII_CONTROL, REG_SII_CONTROL + 2):
            self._sii_command()
        if hit(REG_ERR_COUNTERS, REG_ERR_COUNTERS + 0x14):
            self.mem[max(lo, REG_ERR_COUNTERS):min(hi, REG_ERR_COUNTERS + 0x14)] = \
                bytes(min(hi, REG_ERR_COUNTERS + 0x14) - max(lo, REG_ERR_COUNTERS))
        if hit(REG_DC_RECV, REG_DC_RECV + 4):
            t = self._now & 0xFFFFFFFF
            struct.pack_into("<IIII", self.mem, REG_DC_RECV, t, t, 0, 0)
            struct.pack_into("<Q", self.mem, REG_DC_RECV_PU, self._now & (2**64 - 1))
        if hit(REG_AL_CONTROL, REG_AL_CONTROL + 2):
            self.pdi.al_control(self.al_control_value)

    def _sm_written(self, lo: int, hi: int) -> None:
        """The master wrote SyncManager registers.  As an ESC does (datasheet section II
        0x0800: start, length and control are "r/(w)"): those of an activated SyncManager
        are not written (they keep their values); an activation whose buffer is not
        inside the process RAM does not take (the activate bit reads 0).  A change of
        the activate bit is an SM change event for the firmware."""
        for s in self.sm:
            base = REG_SM + 8 * s.number
            if not (lo < base + 8 and base < hi):
                continue
            was_enabled = s.enabled
            old_activate = s.activate
            if old_activate & 0x01:
                struct.pack_into("<HHB", self.mem, base, s.start, s.length, s.control)
            else:
                s.start, s.length, s.control = struct.unpack_from("<HHB", self.mem, base)
            s.activate = self.mem[base + 6]
            if s.activate & 0x01 and not s.in_ram:
                s.activate &= 0xFE
            if not s.enabled:
                s.status &= ~0x08 & 0xFF
            elif not was_enabled:
                s.status &= ~0x08 & 0xFF
                if not s.mailbox and s.master_writes and s.control & 0x40:
                    self._wd_last = self._now
                    self._wd_expired = False
                    self.mem[REG_WD_STATUS] |= 0x01
            if s.enabled and s.mailbox and not s.master_writes \
                    and (s.activate ^ old_activate) & 0x02:
                self._repeat(s)
            self._sync_sm_regs(s)
            if (s.activate ^ old_activate) & 0x01:
                self.pdi.sm_changed(s.number)

    def _repeat(self, s: SyncManager) -> None:
        """Repeat request (activate bit 1 toggled): send the last message again."""
        last = self._mbx_out.get(s.number)
        if last is not None:
            self.mem[s.start:s.end] = last[:s.length].ljust(s.length, b"\x00")
            s.status |= 0x08
        s.pdi_control = (s.pdi_control & ~0x02 & 0xFF) | (s.activate & 0x02)

    def _sync_sm_regs(self, s: SyncManager) -> None:
        base = REG_SM + 8 * s.number
        status = s.status & 0x08
        if s.mailbox:
            status |= 0x01 if s.full and s.master_writes else 0
            status |= 0x02 if s.full and not s.master_writes else 0
        self.mem[base + 5] = status
        self.mem[base + 6] = s.activate
        self.mem[base + 7] = s.pdi_control

    # -- SII EEPROM interface ---------------------------------------------------
    def _sii_command(self) -> None:
        control, = struct.unpack_from("<H", self.mem, REG_SII_CONTROL)
        command = (control >> 8) & 0x07
        address, = struct.unpack_from("<I", self.mem, REG_SII_ADDRESS)
        status = 0x0040                # 8-byte reads supported, not busy, no error
        if command == 0x01:            # read
            at = (address & 0xFFFF) * 2
            chunk = bytes(self.sii[at:at + 8]).ljust(8, b"\xff")
            self.mem[REG_SII_DATA:REG_SII_DATA + 8] = chunk
        elif command == 0x02:          # write one word (needs the write enable bit)
            at = (address & 0xFFFF) * 2
            if control & 0x01 and at + 2 <= len(self.sii):
                self.sii[at:at + 2] = self.mem[REG_SII_DATA:REG_SII_DATA + 2]
            elif not control & 0x01:
                status |= 0x4000       # write enable error
            else:
                status |= 0x2000
        elif command == 0x04:          # reload
            self.mem[REG_ALIAS:REG_ALIAS + 2] = self.sii[8:10]
        elif command:
            status |= 0x2000           # command error
        struct.pack_into("<H", self.mem, REG_SII_CONTROL, status)
