"""Fuzz the frame path and the mailbox: no crash, no hang, no state change not asked for.

Frames are built with scapy's ``contrib.ethercat`` layers (an independent encoder),
then mutated (bytes flipped, lengths changed, truncated) or replaced by random
bytes.  The datagrams aim at the AL, DL, SII and DC registers, the process RAM and
anywhere in the FMMU (0x0600-0x06FF) and SyncManager (0x0800-0x087F) registers, with
plausible configurations there (a SyncManager or an FMMU on the registers, past the
RAM, bit-wise, 65,535 bytes long) as well as random bytes.  The oracles, after every
frame: nothing raised; AL status (manual 5.2.2) names a state (1, 2, 4 or 8, with
the error bit or not) and its code is one of the table's; the memory keeps its size;
the AL status changed only if the frame carries a write-type datagram that reaches
this slave over AL control (0x0120) or a SyncManager's activate register (0x0806 +
8n: the firmware checks its configuration again), or a logical write (an FMMU may
map those).  Every 100 frames a fresh master (reset, configure, INIT to OP) must
reach OP, and nothing was logged as an error (no exception caught inside either).
Seeds are fixed: the run is the same every time.
"""

from __future__ import annotations

import logging
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
_FMMU_END, _SM_END = 0x0700, 0x0880
#: What a SyncManager or an FMMU may be pointed at: registers (AL control, AL status,
#: the SyncManagers themselves), the edges of the RAM, past it.
_TARGETS = [0x0000, 0x0120, 0x0130, 0x0800, 0x080D, 0x0FF8, 0x1000, 0x1080, 0x1100, 0x1180,
            0x2FF0, 0x3000, 0xFFF0]
#: Register offsets that may change the AL status when written.
_STATE_BYTES = [E.REG_AL_CONTROL, E.REG_AL_CONTROL + 1] + [E.REG_SM + 8 * n + 6
                                                            for n in range(E.N_SM)]
#: AL status codes the manual's table (5.2.2) lists that the slave gives.
_CODES = {esm.NO_ERROR, esm.INVALID_STATE_CHANGE, esm.UNKNOWN_STATE, esm.BOOT_NOT_SUPPORTED,
          esm.INVALID_MAILBOX_CONFIG, esm.SM_WATCHDOG, esm.INVALID_OUTPUT_CONFIG,
          esm.INVALID_INPUT_CONFIG, esm.INVALID_WATCHDOG_CONFIG}


def _ado(rng: random.Random) -> int:
    pick = rng.random()
    if pick < 0.2:
        return rng.randrange(E.REG_FMMU, _FMMU_END)
    if pick < 0.4:
        return rng.randrange(E.REG_SM, _SM_END)
    if pick < 0.5:
        return rng.choice((E.REG_FMMU + 16 * rng.randrange(4), E.REG_SM + 8 * rng.randrange(5)))
    return rng.choice(_ADDRESSES)


def _sm_config(rng: random.Random) -> bytes:
    return struct.pack("<HHBBBB", rng.choice(_TARGETS + [rng.randrange(1 << 16)]),
                       rng.choice([0, 1, 2, 8, 24, 128, 0x1000, 0xFFFF]),
                       rng.choice([0x22, 0x26, 0x64, 0x20, rng.randrange(256)]), 0,
                       rng.choice([0, 1, 1, 3, rng.randrange(256)]), 0)


def _fmmu_config(rng: random.Random) -> bytes:
    return struct.pack("<IHBBHBBBBH", rng.choice([0, 0x10000, rng.randrange(1 << 32)]),
                       rng.choice([1, 2, 24, 128, 0xFFFF, rng.randrange(1 << 16)]),
                       rng.randrange(8), rng.randrange(8),
                       rng.choice(_TARGETS + [rng.randrange(1 << 16)]), rng.randrange(8),
                       rng.choice([1, 2, 3, rng.randrange(256)]), rng.choice([1, 1, 0]), 0, 0)


def _data(rng: random.Random, ado: int) -> list[int]:
    """Plausible SyncManager / FMMU settings where the address starts one, else random."""
    if E.REG_SM <= ado < _SM_END and ado % 8 == 0 and rng.random() < 0.7:
        body = b"".join(_sm_config(rng) for _ in range(rng.randint(1, 2)))
    elif E.REG_FMMU <= ado < _FMMU_END and ado % 16 == 0 and rng.random() < 0.7:
        body = _fmmu_config(rng)
    else:
        body = bytes(rng.randrange(256) for _ in range(rng.choice([1, 2, 4, 8, 24, 128])))
    return list(body)


def scapy_frame(rng: random.Random, safe: bool) -> bytes:
    """A valid frame of 1-4 random datagrams; ``safe``: none of them writes."""
    layers = []
    for _ in range(rng.randint(1, 4)):
        cmd = rng.choice(list(_LAYERS))
        if safe and cmd in _WRITE_CMDS:
            cmd = rng.choice([E.APRD, E.FPRD, E.BRD, E.LRD])
        cls = getattr(scapy_ecat, _LAYERS[cmd])
        if cmd in (E.LRD, E.LWR, E.LRW):
            data = [rng.randrange(256) for _ in range(rng.choice([1, 2, 4, 8, 24, 128]))]
            layers.append(cls(adr=rng.choice([0, 0x10000, rng.randrange(1 << 32)]), data=data))
        else:
            ado = _ado(rng)
            layers.append(cls(adp=rng.choice([0, 0x1001, 0xFFFF, rng.randrange(1 << 16)]),
                              ado=ado, data=_data(rng, ado)))
    pkt = Ether(dst="ff:ff:ff:ff:ff:ff", src="01:01:01:01:01:01", type=0x88A4) / \
        scapy_ecat.EtherCat()
    for layer in layers:
        pkt = pkt / layer
    return raw(pkt)


def may_change_state(frame: bytes, station: int) -> bool:
    """Whether some datagram of ``frame`` may write AL control or a SyncManager's activate
    register of this slave (or, through the FMMUs, anything)."""
    if len(frame) < 16:
        return False
    end = min(len(frame), 16 + ((frame[14] | frame[15] << 8) & 0x7FF))
    pos = 16
    while pos + 12 <= end:
        cmd, _i, adp, ado, ln = struct.unpack_from("<BBHHH", frame, pos)
        n = ln & 0x7FF
        if pos + 12 + n > end:
            return False
        covers = any(ado <= at < ado + n for at in _STATE_BYTES)
        if cmd in _WRITE_CMDS and covers:
            if cmd in (E.BWR, E.BRW, E.ARMW, E.FRMW) or cmd == E.APWR or cmd == E.APRW \
                    or adp == station:
                return True
        if cmd in (E.LWR, E.LRW):
            return True               # the FMMUs could map AL control
        pos += 12 + n
        if not ln & 0x8000:
            return False
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
    """A fresh master, as SOEM starts: INIT with acknowledge, FMMUs and SyncManagers
    cleared, station address, watchdog, the four SyncManagers, INIT to OP."""
    esc = app.stack.esc

    def w(ado: int, data: bytes) -> None:
        assert esc.write(ado, data)
    w(E.REG_AL_CONTROL, struct.pack("<H", esm.INIT | esm.ACK))
    w(E.REG_FMMU, bytes(16 * E.N_FMMU))
    w(E.REG_SM, bytes(8 * E.N_SM))
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
        assert esc.al_status == state, (hex(esc.al_status), hex(esc.al_code))


def assert_sane(esc: E.Esc) -> None:
    """AL status names a state with a code from the manual's table; memory keeps its size."""
    status = esc.al_status
    assert status & 0x0F in (esm.INIT, esm.PREOP, esm.SAFEOP, esm.OP), hex(status)
    assert status & ~0x1F == 0, hex(status)
    assert esc.al_code in _CODES, hex(esc.al_code)
    assert len(esc.mem) == E.MEM_SIZE


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fuzzed_frames_never_crash_hang_or_change_state_unasked(seed, caplog):
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
            frame = mutate(rng, scapy_frame(rng, safe=rng.random() < 0.3))
        else:
            frame = b"\xff" * 12 + b"\x88\xa4" + bytes(rng.randrange(256)
                                                      for _ in range(rng.randint(2, 200)))
        before = esc.al_status
        out = esc.process(frame, 0)
        assert out is None or len(out) == len(frame)
        assert_sane(esc)
        if esc.al_status != before:
            assert may_change_state(frame, esc.station), frame.hex()
        if n % 100 == 99 or esc.al_status != before:
            to_op(app)                # a fresh master still reaches OP
    assert time.perf_counter() - started < 30
    assert not [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]


def _one(cmd: int, **fields: object) -> bytes:
    layer = getattr(scapy_ecat, _LAYERS[cmd])(**fields)
    return raw(Ether(dst="ff:ff:ff:ff:ff:ff", src="01:01:01:01:01:01", type=0x88A4)
               / scapy_ecat.EtherCat() / layer)


def _sdo_upload(rng: random.Random) -> list[int]:
    """A CoE SDO upload request in a whole 128-byte mailbox (its last byte fills SM0)."""
    body = struct.pack("<HBHB", 0x2000, 0x40, rng.choice([0x1000, 0x1008, 0x1018, 0x6041]),
                       rng.randrange(3)) + bytes(4)
    return list((struct.pack("<HHBB", len(body), 0, 0, 0x03) + body).ljust(128, b"\0"))


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_fuzzed_syncmanager_and_fmmu_settings_with_mailbox_traffic_keep_the_esm_sane(seed,
                                                                                    caplog):
    """A master at the slave's station reconfigures SyncManagers and FMMUs at random
    (on the registers, past the RAM, deactivating first or not) between SDO requests,
    mailbox reads, logical datagrams and state requests."""
    rng = random.Random(seed)
    app = BridgeApp(None)
    to_op(app)
    esc = app.stack.esc
    for step in range(1500):
        pick = rng.random()
        if pick < 0.25:
            n = rng.randrange(E.N_SM)
            if rng.random() < 0.5:
                esc.process(_one(E.FPWR, adp=esc.station, ado=E.REG_SM + 8 * n + 6,
                                 data=[0]), 0)
            frame = _one(E.FPWR, adp=esc.station, ado=E.REG_SM + 8 * n,
                         data=list(_sm_config(rng)))
        elif pick < 0.35:
            frame = _one(E.FPWR, adp=esc.station, ado=E.REG_FMMU + 16 * rng.randrange(3),
                         data=list(_fmmu_config(rng)))
        elif pick < 0.55:
            frame = _one(E.FPWR, adp=esc.station, ado=ident.MBX_OUT_START,
                         data=_sdo_upload(rng))
        elif pick < 0.7:
            frame = _one(E.FPRD, adp=esc.station, ado=ident.MBX_IN_START, data=[0] * 128)
        elif pick < 0.85:
            cmd = rng.choice([E.LRD, E.LWR, E.LRW])
            frame = _one(cmd, adr=rng.choice([0, 0x10000, rng.randrange(1 << 17)]),
                         data=[rng.randrange(256) for _ in range(rng.choice([1, 4, 24, 64]))])
        else:
            value = rng.choice([esm.INIT, esm.PREOP, esm.SAFEOP, esm.OP, rng.randrange(32)])
            frame = _one(E.FPWR, adp=esc.station, ado=E.REG_AL_CONTROL,
                         data=list(struct.pack("<H", value | rng.choice([0, esm.ACK]))))
        out = esc.process(frame, 0)
        assert out is not None and len(out) == len(frame)
        assert_sane(esc)
        if step % 100 == 99:
            to_op(app)
    assert not [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]


def test_fuzz_reaches_the_syncmanager_and_fmmu_registers():
    """The generator aims at every SyncManager and FMMU register byte, and points
    SyncManagers and FMMUs at the registers (what a careless master may do)."""
    rng = random.Random(5)
    hit: set[int] = set()
    aimed = 0
    for _ in range(3000):
        ado = _ado(rng)
        data = bytes(_data(rng, ado))
        hit.update(range(ado, ado + len(data)))
        if ado % 8 == 0 and E.REG_SM <= ado < E.REG_SM + 8 * E.N_SM and len(data) >= 8:
            aimed += struct.unpack_from("<H", data)[0] < E.RAM_START
    assert set(range(E.REG_FMMU, _FMMU_END)) <= hit
    assert set(range(E.REG_SM, _SM_END)) <= hit
    assert aimed > 20


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
