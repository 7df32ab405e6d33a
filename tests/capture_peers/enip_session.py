"""One EtherNet/IP session of the usual peers (ethernetip, pycomm3), for the capture test.

Run where ``coolmuscle sim --firmware cm1 --enip`` serves on the standard ports
(TCP/UDP 44818, UDP 2222: test_wireshark.py runs both in a network namespace of
its own): ``python enip_session.py``.  Prints JSON: what was sent and what came back.
ListIdentity over UDP and TCP, RegisterSession, Get/Set_Attribute_Single with their
refusals, Forward_Open 101/102/128 at RPI 10 ms, a move through O->T until T->O says
in position, Forward_Close (cm1-ethernetip-interface-manual.txt 3.1, 3.2, ch. 4).
"""

from __future__ import annotations

import json
import struct
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import ethernetip.ethernetip as E  # type: ignore[import-untyped]
from pycomm3 import CIPDriver

from fixtures import wait_until
from test_enip_peers import _Scanner, generic_status, get, set_

HOST = "127.0.0.1"
IDLE = struct.pack("<HiihBB", 1, 0, 100, 100, 0, 0)
MOVE = struct.pack("<HiihBB", 1, 4000, 100, 100, 1, 0)      # 3.2: P0 4000, start
#: (service, class, instance, attribute, data) and the CIP general status expected
REFUSALS = [((0x0E, 4, 0x67, 3, b""), 0x05), ((0x0E, 4, 0x65, 9, b""), 0x14),
            ((0x10, 4, 0x65, 3, bytes(8)), 0x0E), ((0x4B, 1, 1, None, b""), 0x08)]


class _Patch:
    """Stands in for pytest's monkeypatch: the ports are the standard ones already."""

    def setattr(self, target: Any, name: str, value: Any) -> None:
        setattr(target, name, value)


def explicit() -> dict[str, Any]:
    out: dict[str, Any] = {
        "udp_identity": E.EtherNetIP(HOST).listIDUDP(HOST, timeout=3).product_name.decode(),
        "tcp_identity": (CIPDriver.list_identity(HOST) or {})["product_name"]}
    requests: list[list[int | None]] = []
    with CIPDriver(HOST) as d:
        name = get(d, 1, 1, 7).value
        requests.append([0x0E, 1, 1, 7, 0])
        assert set_(d, 4, 0x66, 3, IDLE).error is None
        requests.append([0x10, 4, 0x66, 3, 0])
        image = get(d, 4, 0x66, 3).value
        requests.append([0x0E, 4, 0x66, 3, 0])
        for (service, cls, inst, attr, data), _expected in REFUSALS:
            kw: dict[str, Any] = {"service": service, "class_code": cls, "instance": inst}
            if attr is not None:
                kw["attribute"] = attr
            if data:
                kw["request_data"] = data
            requests.append([service, cls, inst, attr, generic_status(d, **kw)])
    out.update(name=name[1:].decode(), image=image.hex(), requests=requests,
               expected=[status for _r, status in REFUSALS])
    return out


def class1() -> dict[str, Any]:
    scanner = _Scanner(_Patch(), E.ENIP_TCP_PORT, E.ENIP_UDP_PORT)
    try:
        out: dict[str, Any] = {"forward_open": scanner.forward_open(rpi_ms=10)}
        out.update(ot_id=scanner.conn.otconnid, to_id=scanner.conn.toconnid,
                   originator_port=scanner.enip.originator_udp_port)
        scanner.set_output(MOVE)
        scanner.conn.produce()
        out["moved"] = wait_until(lambda: scanner.input() == (0, 8, 4000), 10)
        out["input"] = list(scanner.input())
        time.sleep(0.3)                                    # some cycles at rest
        scanner.conn.stopProduce()
        out["forward_close"] = scanner.conn.sendFwdCloseReq(101, 102, 128)
        out["move"] = MOVE.hex()
    finally:
        scanner.close()
    with CIPDriver(HOST) as d:
        out["after"] = list(struct.unpack("<HHi", get(d, 4, 0x65, 3).value))
    return out


def main() -> None:
    result = explicit()
    result.update(class1())
    print(json.dumps(result))


if __name__ == "__main__":
    main()
