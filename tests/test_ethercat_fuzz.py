"""Fuzz the frame path and the mailbox: no crash, no hang, no state change not asked for.

Frames are built with scapy's ``contrib.ethercat`` layers (an independent encoder),
then mutated (bytes flipped, lengths changed, truncated) or replaced by random
bytes.  The oracle: the AL status (manual 5.2.2) may change only when the frame
carries a write-type datagram whose range covers AL control (0x0120) and that
reaches this slave.  Seeds are fixed: the run is the same every time.
"""

from __future__ import annotations

import random
import struct
import time

import pytest

from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
from coolmuscle.frontends.ethercat.engine import esc as E
from coolmuscle.frontends.ethercat.engine import esm

scapy_ecat = pytest.importorskip("scapy.contrib.ethercat")
from scapy.all import Ether, raw  # noqa: E402

_LAYERS = {E.APRD: "EtherCatAPRD", E.APWR: "EtherCatAPWR", E.APRW: "EtherCatAPRW",
           E.FPRD: "EtherCatFPRD", E.FPWR: "EtherCatFPWR", E.FPRW: "EtherCatFPRW",
           E.BRD: "EtherCatBRD", E.BWR: "EtherCatBWR", E.BRW: "EtherCatBRW",
           E.LRD: "EtherCatLRD", E.LWR: "EtherCatLWR", E.LRW: "EtherCatLRW",
           E.ARMW: "EtherCatARMW", E.FRMW: "EtherCatFRMW"}
_WRITE_CMDS = {E.APWR, E.APRW, E.FPWR, E.FPRW, E.BWR, E.BRW, E.ARMW, E.FRMW}
_ADDRESSES = [0x0000, 0x0010, 0x0110, 0x0120, 0x0130, 0x0134, 0x0502, 0x0508, 0x0600,
              0x0800, 0x0808, 0x080D, 0x0900, 0x0910, 0x1000, 0x1080, 0x1100, 0x1180, 0xFFF0]


def scapy_frame(rng: random.Random, safe: bool) -> bytes:
    """A valid frame of 1-4 random datagrams; ``safe``: none of them writes AL control."""
    layers = []
    for _ in range(rng.randint(1, 4)):
        cmd = rng.choice(list(_LAYERS))
        if safe and cmd in _WRITE_CMDS:
            cmd = rng.choice([E.APRD, E.FPRD, E.BRD, E.LRD])
        cls = getattr(scapy_ecat, _LAYERS[cmd])
        data = [rng.randrange(256) for _ in range(rng.choice([1, 2, 4, 8, 24, 128]))]
        if cmd in (E.LRD, E.LWR, E.LRW):
            layers.append(cls(adr=rng.choice([0, 0x10000, rng.randrange(1 << 32)]), data=data))
        else:
            layers.append(cls(adp=rng.choice([0, 0x1001, 0xFFFF, rng.randrange(1 << 16)]),
                              ado=rng.choice(_ADDRESSES), data=data))
    pkt = Ether(dst="ff:ff:ff:ff:ff:ff", src="01:01:01:01:01:01", type=0x88A4) / \
        scapy_ecat.EtherCat()
    for layer in layers:
        pkt = pkt / layer
    return raw(pkt)


def asks_al_control(frame: bytes, station: int) -> bool:
    """Whether some datagram of ``frame`` may write AL control of this slave."""
    if len(frame) < 16:
        return False
    end = min(len(frame), 16 + ((frame[14] | frame[15] << 8) & 0x7FF))
    pos, position = 16, 0
    while pos + 12 <= end:
        cmd, _i, adp, ado, ln = struct.unpack_from("<BBHHH", frame, pos)
        n = ln & 0x7FF
        if pos + 12 + n > end:
            return False
        covers = ado <= E.REG_AL_CONTROL + 1 and E.REG_AL_CONTROL < ado + n
        if cmd in _WRITE_CMDS and covers:
            if cmd in (E.BWR, E.BRW, E.ARMW, E.FRMW) or cmd == E.APWR or cmd == E.APRW \
                    or adp == station:
                return True
        if cmd in (E.LWR, E.LRW):
            return True               # the FMMUs could map AL control
        pos += 12 + n
        if not ln & 0x8000:
            return False
        position += 1
    return False


def mutate(rng: random.Random, frame: bytes) -> bytes:
    buf = bytearray(frame)
    for _ in range(rng.randint(1, 6)):
        choice = rng.random()
        if choice < 0.5:
            i = rng.randrange(14, len(buf))
            buf[i] = rng.randrange(256)
        elif choice < 0.7:
            del buf[rng.randrange(14, len(buf)):]
        elif choice < 0.85:
            buf += bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
        else:
            struct.pack_into("<H", buf, 14, rng.randrange(1 << 16))
        if len(buf) < 16:
            buf += bytes(16 - len(buf))
    return bytes(buf)


def to_op(app: BridgeApp) -> None:
    esc = app.stack.esc

    def w(ado: int, data: bytes) -> None:
        assert esc.write(ado, data)
    w(E.REG_AL_CONTROL, struct.pack("<H", esm.INIT | esm.ACK))
    w(E.REG_STATION, b"\x01\x10")
    w(E.REG_WD_DIVIDER, struct.pack("<H", 2498))
    w(E.REG_WD_SM, struct.pack("<H", 1000))
    for n, (start, size, ctl) in enumerate(((ident.MBX_OUT_START, 128, 0x26),
                                            (ident.MBX_IN_START, 128, 0x22),
                                            (ident.PD_OUT_START, 24, 0x64),
                                            (ident.PD_IN_START, 24, 0x20))):
        w(E.REG_SM + 8 * n, struct.pack("<HHBBBB", start, size, ctl, 0, 1, 0))
    for state in (esm.PREOP, esm.SAFEOP, esm.OP):
        w(E.REG_AL_CONTROL, struct.pack("<H", state))
    assert esc.al_status == esm.OP


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fuzzed_frames_never_crash_hang_or_change_state_unasked(seed):
    rng = random.Random(seed)
    app = BridgeApp(None)
    to_op(app)
    esc = app.stack.esc
    started = time.perf_counter()
    for n in range(1500):
        kind = n % 3
        if kind == 0:
            frame = scapy_frame(rng, safe=True)
        elif kind == 1:
            frame = mutate(rng, scapy_frame(rng, safe=rng.random() < 0.7))
        else:
            frame = b"\xff" * 12 + b"\x88\xa4" + bytes(rng.randrange(256)
                                                      for _ in range(rng.randint(2, 200)))
        before = esc.al_status
        out = esc.process(frame, 0)
        assert out is None or len(out) == len(frame)
        if esc.al_status != before:
            assert asks_al_control(frame, esc.station), frame.hex()
            to_op(app)
    assert time.perf_counter() - started < 20


def test_safe_scapy_frames_leave_the_slave_in_op_and_are_answered():
    rng = random.Random(7)
    app = BridgeApp(None)
    to_op(app)
    for _ in range(500):
        frame = scapy_frame(rng, safe=True)
        out = app.stack.esc.process(frame, 0)
        assert out is not None and len(out) == len(frame)
    assert app.stack.esc.al_status == esm.OP


def test_fuzzed_mailboxes_are_answered_or_ignored_never_crash_5_4():
    rng = random.Random(11)
    app = BridgeApp(None)
    to_op(app)
    esc = app.stack.esc
    answered = 0
    for _ in range(1500):
        length = rng.choice([0, 1, 2, 4, 10, 16, 40, 122, 200, 0xFFFF])
        kind = rng.choice([0x03, 0x13, 0x33, 0x01, 0x04, 0x0F, rng.randrange(256)])
        body = bytes(rng.randrange(256) for _ in range(rng.randint(0, 122)))
        if rng.random() < 0.6:            # a plausible SDO / SDO info header
            service = rng.choice([0x2000, 0x8000, 0x1000, 0x4000])
            body = struct.pack("<HBHB", service, rng.randrange(256),
                               rng.choice([0x1000, 0x1018, 0x1C12, 0x6040, 0xF581,
                                           rng.randrange(1 << 16)]),
                               rng.randrange(256)) + body
        mbx = (struct.pack("<HHBB", length, 0, 0, kind) + body)[:128].ljust(128, b"\0")
        assert esc.write(ident.MBX_OUT_START, mbx)
        if esc.read(ident.MBX_IN_START, 128) is not None:
            answered += 1
        while esc.read(ident.MBX_IN_START, 128) is not None:
            pass
    assert esc.al_status == esm.OP
    assert answered > 1000
