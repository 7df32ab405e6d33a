"""Fuzz the SDO service of the drive's objects through the CoE layer: random indexes
(the drive's 6000h-7FFFh and F5xxh objects and their neighbours), subindexes, sizes,
transfer types and values.  No request may crash the slave or the bridge cycle; every
refusal is an abort code of ethercat-bridge-users-guide.txt 5.4.1; and the SDO writes
change nothing the drive did not accept (the motor still answers, the cycle runs).
Seeds are fixed: the run is the same every time.
"""

from __future__ import annotations

import random
import struct

import pytest

from coolmuscle.frontends.ethercat.engine import dictionary as D
from coolmuscle.frontends.ethercat.engine.coe import SDO_REQUEST, SDO_RESPONSE, coe_header
from ethercat_drive_support import Bench

#: Manual 5.4.1, every code.
ABORT_CODES = {v for k, v in vars(D).items() if k.isupper() and isinstance(v, int)
               and v >= 0x05000000}

DRIVE_INDEXES = [0x6040, 0x6041, 0x6060, 0x6061, 0x6064, 0x607A, 0x607C, 0x607D, 0x6098,
                 0x6099, 0x609A, 0x60E3, 0x60F6, 0x60FB, 0x60FD, 0x60FE, 0x6502, 0xF511,
                 0xF530, 0xF540, 0xF550, 0xF581, 0xF591, 0xF570]


def rand_index(rng: random.Random) -> int:
    pick = rng.random()
    if pick < 0.8:
        base = rng.choice(DRIVE_INDEXES)
        if base < 0x8000:
            return base + 0x800 * rng.randrange(4)     # ID1..ID4
        return base + rng.randrange(4) if base in (0xF511, 0xF581, 0xF591) else base
    return rng.randrange(0x10000)


def sdo_request(rng: random.Random, index: int, sub: int) -> bytes:
    kind = rng.choice(["upload", "expedited", "normal", "segment", "garbage"])
    if kind == "upload":
        cmd = 0x40 | (0x10 if rng.random() < 0.1 else 0)
        body = struct.pack("<BHBI", cmd, index, sub, 0)
    elif kind == "expedited":
        size = rng.randrange(4)
        body = struct.pack("<BHB", 0x23 | size << 2, index, sub) + rng.randbytes(4)
    elif kind == "normal":
        data = rng.randbytes(rng.choice([0, 1, 2, 4, 8, 63, 64, 65, 90]))
        declared = len(data) if rng.random() < 0.8 else rng.randrange(200)
        body = struct.pack("<BHBI", 0x21, index, sub, declared) + data
    elif kind == "segment":
        body = bytes([rng.choice([0x00, 0x10, 0x60, 0x70, 0x01])]) + rng.randbytes(7)
    else:
        body = rng.randbytes(rng.randrange(1, 12))
    return coe_header(SDO_REQUEST) + body


@pytest.mark.parametrize("seed", range(4))
def test_sdo_fuzz_of_the_drive_objects_answers_or_aborts_never_crashes_5_4_1(seed):
    rng = random.Random(seed)
    b = Bench(rng.choice(["EB01", "EB02", "EB12"]))
    coe = b.app.stack.coe
    seen = {SDO_REQUEST: 0, SDO_RESPONSE: 0}
    for i in range(600):
        index = rand_index(rng)
        sub = rng.choice([0, 1, 2, 0x16, 0x4F, 0x50, rng.randrange(256)])
        answers = coe.handle(sdo_request(rng, index, sub))
        for answer in answers:
            service = answer[1] >> 4
            seen[service] = seen.get(service, 0) + 1
            if service == SDO_REQUEST:                   # an abort
                assert answer[2] >> 5 == 4
                code, = struct.unpack_from("<I", answer, 6)
                assert code in ABORT_CODES, hex(code)
                assert code != D.GENERAL, f"a hook failed on {index:04X}h.{sub}"
            else:
                assert service == SDO_RESPONSE
        if i % 10 == 0:
            b.cycles(1)                                  # the model thread keeps going
    assert seen[SDO_REQUEST] > 50 and seen[SDO_RESPONSE] > 20, seen   # both paths taken
    b.cycles(5)
    assert b.chain.execute("?99.1", origin="host")       # the motor still answers
    assert b.status(1) & 0x0200                          # and the drive still publishes
