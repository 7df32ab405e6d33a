"""Several bridges on one segment, sans IO: frames through ESCs in a line.

ETG.1000.4 3.2 (a frame passes the slaves in order and returns through the ring),
table 12 / 13 (auto-increment addressing, working counters), the ESC datasheet's DL
control 0x0100 and DL status 0x0110 (ports, links and loops); manual 1.4 (a bridge
carries four motors), 6.3 (the 1 ms cycle).
"""

from __future__ import annotations

import struct

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.bridge.segment import BridgeSegment
from coolmuscle.frontends.ethercat.engine import esc as E
from coolmuscle.frontends.ethercat.engine.segment import RETURNED, Segment
from coolmuscle.sim.kernel import Kernel
from ethercat_support import datagrams, frame

MS = 1_000_000
CODES = ("EB02", "EB12", "EB01")
LAST, INNER = 0x5613, 0x5A33       # DL status: port 1 loop closed / port 1 link, open


def one(line: Segment, cmd: int, adp: int, ado: int, data: bytes,
        now: int = 0) -> tuple[int, bytes, int]:
    out = line.process(frame((cmd, adp, ado, data)), now)
    assert out is not None
    _c, a, d, w = datagrams(out)[0]
    return a, d, w


@pytest.fixture
def segment() -> BridgeSegment:
    """Three bridges answering with their dictionaries, stations 0x1001-0x1003."""
    seg = BridgeSegment([None] * 3, CODES)
    for n in range(3):
        assert one(seg.line, E.APWR, -n & 0xFFFF, E.REG_STATION,
                   struct.pack("<H", 0x1001 + n))[2] == 1
    return seg


def test_auto_increment_counts_up_in_each_slave_and_addresses_them_in_line_order():
    seg = BridgeSegment([None] * 3, CODES)
    for n in range(4):                                  # positions 0, -1, -2 and past the end
        adp, data, wkc = one(seg.line, E.APRD, -n & 0xFFFF, E.REG_TYPE, bytes(2))
        assert adp == (-n + 3) & 0xFFFF                 # every slave counted it up
        assert (wkc, data[0]) == ((1, 0x98) if n < 3 else (0, 0))
    for n in range(3):
        one(seg.line, E.APWR, -n & 0xFFFF, E.REG_STATION, struct.pack("<H", 0x1001 + n))
    assert [app.stack.esc.station for app in seg.apps] == [0x1001, 0x1002, 0x1003]
    # each slave's SII: the identity of its own variant (SII words 8-11)
    for app, code in zip(seg.apps, CODES):
        assert struct.unpack_from("<II", app.stack.sii, 16) == (ident.VENDOR_ID,
                                                                 ident.variant(code).product_code)


def test_broadcasts_reach_every_slave_and_fixed_addresses_only_theirs(segment):
    assert one(segment.line, E.BRD, 0, E.REG_TYPE, bytes(1))[1:] == (b"\x98", 3)
    adp, _data, wkc = one(segment.line, E.BWR, 0, 0x0300, bytes(8))
    assert (adp, wkc) == (3, 3)
    for n in range(3):
        assert one(segment.line, E.FPRD, 0x1001 + n, E.REG_STATION, bytes(2))[1:] \
            == (struct.pack("<H", 0x1001 + n), 1)
    assert one(segment.line, E.FPRD, 0x1004, E.REG_STATION, bytes(2))[2] == 0
    # AL status of each: one AL control write to the second only (INIT -> INIT + ack)
    assert one(segment.line, E.FPWR, 0x1002, E.REG_AL_CONTROL, b"\x11\x00")[2] == 1
    assert one(segment.line, E.BRD, 0, E.REG_AL_STATUS, bytes(2))[1:] == (b"\x01\x00", 3)


def test_dl_status_shows_the_ports_with_a_link_and_the_last_one_closes_the_loop(segment):
    status = [struct.unpack("<H", one(segment.line, E.FPRD, 0x1001 + n, E.REG_DL_STATUS,
                                      bytes(2))[1])[0] for n in range(3)]
    assert status == [INNER, INNER, LAST]
    assert (INNER >> 4) & 3 == 0b11 and INNER >> 10 & 1 == 0      # links on 0 and 1, open
    assert (LAST >> 4) & 3 == 0b01 and LAST >> 10 & 1 == 1        # no link on 1: closed


def test_lrw_spans_the_fmmus_of_every_slave_and_adds_their_counters(segment):
    """Each slave maps its 24 output bytes at 24 n and its 24 input bytes at 72 + 24 n."""
    for n, app in enumerate(segment.apps):
        station = 0x1001 + n
        app.stack.esc.set_inputs(3, bytes([n + 1]) * 24)
        for f, (logical, phys, kind) in enumerate(((24 * n, 0x1100, 2),
                                                   (72 + 24 * n, 0x1180, 1))):
            one(segment.line, E.FPWR, station, E.REG_FMMU + 16 * f,
                struct.pack("<IHBBHBBB3x", 0x10000 + logical, 24, 0, 7, phys, 0, kind, 1))
        for s, (start, ctl) in enumerate(((0x1100, 0x64), (0x1180, 0x20))):
            one(segment.line, E.FPWR, station, E.REG_SM + 8 * (s + 2),
                struct.pack("<HHBBBB", start, 24, ctl, 0, 1, 0))
    outputs = bytes(range(72))
    _a, data, wkc = one(segment.line, E.LRW, 0x0000, 0x0001, outputs + bytes(72))
    assert wkc == 3 * 3
    assert data[72:] == b"\x01" * 24 + b"\x02" * 24 + b"\x03" * 24
    for n, app in enumerate(segment.apps):
        assert bytes(app.stack.esc.mem[0x1100:0x1118]) == outputs[24 * n:24 * n + 24]
    assert one(segment.line, E.LRD, 0x0000 + 72 + 24, 0x0001, bytes(24))[2] == 1   # 2nd only


def test_an_unplugged_bridge_takes_the_segment_behind_it_away_and_back(segment):
    line = segment.line
    segment.unplug(2)
    assert one(line, E.BRD, 0, E.REG_TYPE, bytes(1))[2] == 1 and line.reached == 1
    assert struct.unpack("<H", one(line, E.FPRD, 0x1001, E.REG_DL_STATUS, bytes(2))[1]) \
        == (LAST,)                                       # its port 1 lost the link
    assert one(line, E.FPRD, 0x1003, E.REG_STATION, bytes(2))[2] == 0
    adp, _d, wkc = one(line, E.APRD, 0xFFFF, E.REG_TYPE, bytes(1))
    assert (adp, wkc) == (0, 0)                          # the frame came back from the first
    assert segment.line.visible() == 1
    segment.plug(2)
    assert one(line, E.BRD, 0, E.REG_TYPE, bytes(1))[2] == 3 and line.visible() == 3
    assert struct.unpack("<H", one(line, E.FPRD, 0x1001, E.REG_DL_STATUS, bytes(2))[1]) \
        == (INNER,)
    segment.unplug(1)                                    # the master's own cable
    assert line.process(frame((E.BRD, 0, E.REG_TYPE, bytes(1)))) is None
    with pytest.raises(ValueError):
        segment.unplug(4)


def test_the_watchdog_of_a_bridge_behind_a_pulled_cable_expires(segment):
    """No frame reaches it, but it still runs: its SM watchdog (100 ms) runs out."""
    line = segment.line
    station = 0x1003
    one(line, E.FPWR, station, E.REG_SM + 16, struct.pack("<HHBBBB", 0x1100, 24, 0x64, 0, 1, 0))
    one(line, E.FPWR, station, 0x1100, bytes(24), now=MS)          # an output buffer
    esc = segment.apps[2].stack.esc
    assert esc.mem[E.REG_WD_STATUS] & 1
    segment.unplug(2)
    line.tick(50 * MS)
    assert esc.mem[E.REG_WD_STATUS] & 1
    line.tick(102 * MS)
    assert not esc.mem[E.REG_WD_STATUS] & 1 and esc.mem[E.REG_WD_COUNT_SM] == 1


def test_a_master_that_closes_a_port_ends_the_line_there(segment):
    line = segment.line
    one(line, E.FPWR, 0x1001, E.REG_DL_PORT, b"\x0c")             # port 1: loop closed
    assert one(line, E.BRD, 0, E.REG_TYPE, bytes(1))[2] == 1
    one(line, E.FPWR, 0x1001, E.REG_DL_PORT, b"\x00")             # auto again
    assert one(line, E.BRD, 0, E.REG_TYPE, bytes(1))[2] == 3


def test_the_tap_sees_each_port_in_order_and_may_lose_or_alter_the_frame(segment):
    line = segment.line
    seen: list[int] = []

    def watch(position: int, buf: bytearray) -> bytearray | None:
        seen.append(position)
        return buf
    line.tap = watch
    one(line, E.BRD, 0, E.REG_TYPE, bytes(1))
    assert seen == [0, 1, 2, RETURNED]

    def lose_at_second(position: int, buf: bytearray) -> bytearray | None:
        return None if position == 1 else buf
    line.tap = lose_at_second
    assert line.process(frame((E.BWR, 0, 0x0300, bytes(2)))) is None
    assert line.reached == 1                             # the first slave had processed it

    def wkc_off_by_one(position: int, buf: bytearray) -> bytearray | None:
        if position == RETURNED:
            buf[-2] += 1
        return buf
    line.tap = wkc_off_by_one
    assert one(line, E.BRD, 0, E.REG_TYPE, bytes(1))[2] == 4


def test_the_bridges_of_a_segment_share_one_kernel():
    with pytest.raises(ValueError, match="one kernel"):
        BridgeSegment([Chain(Kernel(), 4), Chain(Kernel(), 4)], ("EB02", "EB02"))


# -- the model behind: one kernel, each bridge its chain -------------------------------
def _image(cw: int, targets: list[int]) -> bytes:
    return b"".join(struct.pack("<Hi", cw, t) for t in targets)


def _targets(bridge: int, i: int) -> list[int]:
    """Bridge ``bridge``'s four csp targets of cycle ``i``: a triangle on one axis."""
    phase = i % 400
    ramp = (3 + bridge) * (phase if phase < 200 else 400 - phase)
    return [ramp if axis == bridge % 4 else 0 for axis in range(4)]


def _run(apps: list[BridgeApp], advance: object, cycles: int, first: int) -> list[bytes]:
    """The 6.1.2 enable, then csp cycles; every input image and motor position."""
    seen: list[bytes] = []
    for i in range(cycles):
        cw = 0x06 if i < 5 else 0x07 if i < 10 else 0x0F
        for n, app in enumerate(apps):
            data = _image(cw, _targets(first + n, max(0, i - 10)))
            app.dictionary.unpack_outputs(data)
            app.outputs(data)
        advance()                                         # type: ignore[operator]
        for app in apps:
            assert app.device is not None
            seen.append(app.dictionary.pack_inputs() + b"".join(
                struct.pack("<d", app.device.motor(m).axis.raw_actual())  # type: ignore[union-attr]
                for m in range(1, 5)))
    return seen


def test_each_axis_moves_as_it_does_behind_a_bridge_alone():
    """Three bridges on one kernel and each bridge alone on its own, the same output
    images: the same input images and the same positions, to the last bit."""
    cycles = 600
    kernel = Kernel()
    chains = [Chain(kernel, 4, firmware=",".join(ident.variant(c).firmware)) for c in CODES]
    seg = BridgeSegment(chains, CODES)
    seg.start_cycles()
    together = _run(list(seg.apps), lambda: kernel.advance(MS), cycles, 0)
    assert all(app.drive is not None and app.drive.cycles == cycles for app in seg.apps)
    for n, code in enumerate(CODES):
        alone_kernel = Kernel()
        app = BridgeApp(Chain(alone_kernel, 4, firmware=",".join(ident.variant(code).firmware)),
                        code)
        app.start_cycles()
        alone = _run([app], lambda k=alone_kernel: k.advance(MS), cycles, n)
        assert together[n::3] == alone, code
    moved = [struct.unpack_from("<i", together[-3 + n], 6 * (n % 4) + 2)[0] for n in range(3)]
    assert all(abs(p) > 100 for p in moved), moved


def test_the_cycles_run_every_bridge_once_a_millisecond_in_line_order():
    kernel = Kernel()
    chains = [Chain(kernel, 4, firmware="cm2") for _ in range(3)]
    seg = BridgeSegment(chains, ("EB02",) * 3)
    order: list[tuple[int, int]] = []
    for n, app in enumerate(seg.apps):
        real = app.cycle

        def cycle(n: int = n, real: object = real) -> None:
            order.append((kernel.now, n))
            real()                                        # type: ignore[operator]
        app.cycle = cycle                                 # type: ignore[method-assign]
    starts: list[int] = []
    seg.start_cycles(on_start=lambda: starts.append(kernel.now))
    kernel.run(until=3 * MS)
    assert starts == [MS, 2 * MS, 3 * MS]
    assert order == [(t, n) for t in starts for n in range(3)]
    seg.stop_cycles()
    kernel.run(until=6 * MS)
    assert len(starts) == 3
