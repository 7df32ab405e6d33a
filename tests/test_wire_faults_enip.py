"""EtherNet/IP wire faults (docs/wire-faults.md) as the scanners see them: the ``ethernetip``
package as a Class 1 originator, pycomm3 for Forward_Open and explicit reads.

cm1-ethernetip-interface-manual.txt 3.1.1 (communication error code), CIP Vol 1 3-4.5.3
(the inactivity watchdog: RPI x 4 x 2^multiplier), 3-5.33 (extended status), 5A-2.2
(Identity status).  Everything runs on 127.0.0.1 with free ports, the adapter in a
service thread (virtual time follows the wall clock) so the test sets the faults.
"""

from __future__ import annotations

import logging
import struct
import time

import pytest

from coolmuscle.frontends.enip.cm1.adapter import Cm1Module
from coolmuscle.sim.kernel import Kernel
from enip_support import enip_service, ports
from fixtures import wait_until

pycomm3 = pytest.importorskip("pycomm3")
from pycomm3 import CIPDriver  # noqa: E402
from pycomm3.exceptions import ResponseError  # noqa: E402

pytestmark = [pytest.mark.peer, pytest.mark.realtime]


class Scanner:
    """The ``ethernetip`` package's originator, pointed at the adapter's ports."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, tcp_port: int, io_port: int) -> None:
        import ethernetip.ethernetip as E
        monkeypatch.setattr(E, "ENIP_TCP_PORT", tcp_port)
        monkeypatch.setattr(E, "ENIP_UDP_PORT", io_port)
        self.enip = E.EtherNetIP("127.0.0.1")
        self.conn = self.enip.explicit_conn("127.0.0.1")
        self.inp = self.enip.registerAssembly(E.EtherNetIP.ENIP_IO_TYPE_INPUT, 8, 101, self.conn)
        self.out = self.enip.registerAssembly(E.EtherNetIP.ENIP_IO_TYPE_OUTPUT, 14, 102,
                                              self.conn)
        self.enip.startIO(udp_port=0)
        assert self.conn.registerSession() == 0
        self.received = 0
        original = self.enip.udpsock.recvfrom

        def counted(size: int) -> tuple[bytes, object]:
            data, addr = original(size)
            self.received += 1
            return data, addr
        self.enip.udpsock = _Socket(self.enip.udpsock, counted)

    def forward_open(self, rpi_ms: int = 10, multiplier: int = 2) -> int | None:
        return self.conn.sendFwdOpenReq(101, 102, 128, torpi=rpi_ms, otrpi=rpi_ms,
                                        multiplier=multiplier,
                                        originator_udp_port=self.enip.originator_udp_port)

    def set_output(self, data: bytes) -> None:
        for i, byte in enumerate(data):
            for bit in range(8):
                self.out[i * 8 + bit] = bool(byte >> bit & 1)

    def close(self) -> None:
        self.conn.stopProduce()
        self.enip.stopIO()


class _Socket:
    def __init__(self, sock, recvfrom) -> None:
        self.sock = sock
        self.recvfrom = recvfrom

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()


def identity_status(tcp_port: int) -> int:
    with CIPDriver(f"127.0.0.1:{tcp_port}") as d:
        tag = d.generic_message(service=0x0E, class_code=1, instance=1, attribute=5,
                                connected=False, route_path=False)
    return struct.unpack("<H", tag.value)[0]


def comm_error(tcp_port: int) -> tuple[int, int]:
    """Input assembly bytes 0-1 (3.1) and class 0x64 attribute 0x64 (3.1.1)."""
    with CIPDriver(f"127.0.0.1:{tcp_port}") as d:
        image = d.generic_message(service=0x0E, class_code=4, instance=0x65, attribute=3,
                                  connected=False, route_path=False).value
        code = d.generic_message(service=0x0E, class_code=0x64, instance=1, attribute=0x64,
                                 connected=False, route_path=False).value
    return struct.unpack_from("<H", image)[0], struct.unpack("<H", code)[0]


def faults_over(st) -> bool:
    """No wire fault installed any more (each one is forgotten when its window ends)."""
    return st.call(lambda: st.chain.wire_faults.describe() == [])


def wire_texts(st) -> list[str]:
    return st.call(lambda: list(st.wire))


@pytest.fixture
def service():
    with enip_service() as st:
        st.wire = []
        st.call(lambda: st.chain.subscribe(
            lambda e: st.wire.append(e.text) if e.kind == "wire" else None))
        yield st


def inject(st, kind: str, **params: object) -> None:
    st.call(lambda: st.chain.inject_wire_fault("enip", kind, **params))


def test_o2t_loss_times_the_connection_out_at_rpi_x_multiplier(service, monkeypatch):
    tcp, io = ports(service)
    scanner = Scanner(monkeypatch, tcp, io)
    try:
        assert scanner.forward_open(rpi_ms=10, multiplier=2) == 0
        scanner.set_output(struct.pack("<HiihBB", 1, 0, 100, 100, 0, 0))
        scanner.conn.produce()
        assert wait_until(lambda: identity_status(tcp) & 0x00F1 == 0x61, 2)   # owned, run
        inject(service, "class1_loss", direction="o2t", until=1.0)
        assert wait_until(lambda: identity_status(tcp) & 0x00F1 == 0x20, 1.0)  # faulted I/O
        texts = wire_texts(service)
        assert any("timed out after 160 ms without O->T packets" in t for t in texts), texts
        count = scanner.received
        time.sleep(0.2)
        assert scanner.received <= count + 1                 # production stopped
        assert wait_until(lambda: faults_over(service), 10)         # the fault is over
        scanner.conn.stopProduce()
        assert scanner.forward_open() == 0                    # a new connection works
        scanner.conn.produce()
        assert wait_until(lambda: scanner.received > count + 10, 2)
        assert identity_status(tcp) & 0x00F1 == 0x61
    finally:
        scanner.close()


def test_t2o_loss_starves_the_scanner_while_the_module_stays_owned(service, monkeypatch):
    tcp, io = ports(service)
    scanner = Scanner(monkeypatch, tcp, io)
    try:
        assert scanner.forward_open(rpi_ms=10, multiplier=2) == 0
        scanner.conn.produce()
        assert wait_until(lambda: scanner.received > 20, 2)
        inject(service, "class1_loss", direction="t2o", until=0.5)
        time.sleep(0.1)
        count = scanner.received
        time.sleep(0.3)
        assert scanner.received <= count + 1                  # nothing reaches the scanner
        assert identity_status(tcp) & 0x0001                  # the module still owned
        assert wait_until(lambda: scanner.received > count + 10, 2)  # back after until
        assert any("T->O packet" in t and "lost" in t for t in wire_texts(service))
    finally:
        scanner.close()


def test_forward_open_refused_with_the_chosen_status(service, monkeypatch, caplog):
    tcp, io = ports(service)
    scanner = Scanner(monkeypatch, tcp, io)
    try:
        inject(service, "forward_open_refused", count=1)      # default 0x01 / 0x0113
        assert scanner.forward_open() == 0x0113               # ethernetip: the extended code
        assert scanner.forward_open() == 0                    # count = 1: only once
    finally:
        scanner.close()
    # pycomm3 tries Large_Forward_Open, then Forward_Open: both refused
    inject(service, "forward_open_refused", general=0x01, extended=0x0106, count=2)
    caplog.set_level(logging.ERROR, logger="pycomm3")
    with CIPDriver(f"127.0.0.1:{tcp}") as d, pytest.raises(ResponseError):
        d.generic_message(service=0x0E, class_code=4, instance=0x65, attribute=3,
                          connected=True, route_path=False)
    assert "Ownership conflict  (01, 106)" in caplog.text
    texts = wire_texts(service)
    assert texts[-1].endswith("Forward_Open refused: general status 0x01, extended 0x0106")


def test_serial_link_sets_the_3_1_1_bit_and_clears_when_it_ends(service):
    tcp, _ = ports(service)
    assert comm_error(tcp) == (0, 0)
    inject(service, "serial_link", state="absent", until=1.0)
    assert comm_error(tcp) == (0x0004, 0x0004)
    assert wait_until(lambda: faults_over(service), 10)            # its window is over
    assert comm_error(tcp) == (0, 0)
    service.call(lambda: service.chain.inject_wire_fault("chain", "power_off", motor=1,
                                                         until=1.0))
    assert comm_error(tcp) == (0x0002, 0x0002)               # the motor off: timed out
    assert wait_until(lambda: faults_over(service), 10)
    assert comm_error(tcp) == (0, 0)


def test_serial_link_in_the_model(make_chain):
    chain = make_chain(firmware="cm1")
    module = Cm1Module(chain, 1)
    chain.inject_wire_fault("enip", "serial_link", state="errors", until=1.0)
    assert module.serial == "errors" and module.comm_error() == 0x0001
    assert isinstance(chain.kernel, Kernel)
    chain.kernel.run(until=2_000_000_000)
    assert module.serial == "ok" and module.comm_error() == 0
