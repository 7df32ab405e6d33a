"""The Message Router: one CIP request in, one reply out (CIP Vol 1 2-4, 5A-3).

It implements :class:`.encapsulation.Target`: ListIdentity's identity item (read
from the Identity object), unconnected requests (SendRRData) and class 3 requests
(SendUnitData).  An Unconnected_Send (0x52) is unwrapped once (its route ignored: the
adapter is the end node).  Requests to the Connection Manager (class 6 instance 1) go
to the table of :mod:`.io`; every other service goes to the object service
(:class:`.objects.ObjectService`).  Each
``CipError`` is encoded here, once; any other exception is logged and answered
general status 0x02 (resource unavailable), so no traceback reaches a client.
"""

from __future__ import annotations

import ipaddress
import logging
import struct
import time
from collections.abc import Callable

from . import messages as cip
from .encapsulation import Item, Peer, sockaddr
from .io import Call, ConnectionTable, direct, open_or_error
from .messages import CipError
from .objects import CONNECTION_MANAGER_CLASS, IDENTITY_CLASS, ObjectService

log = logging.getLogger(__name__)

Clock = Callable[[], int]


class Router:
    """Answers CIP for the encapsulation layer."""

    def __init__(self, objects: ObjectService, table: ConnectionTable, tcp_port: int,
                 clock: Clock = time.monotonic_ns, call: Call = direct) -> None:
        self.objects = objects
        self.table = table
        self.tcp_port = tcp_port
        self.clock = clock
        self.call = call
        self.requests = 0
        self.failures = 0

    # -- encapsulation Target --------------------------------------------------------------
    def identity_item(self, local: tuple[str, int]) -> bytes:
        """CIP Vol 2 2-4.3.2: version, socket address, identity (vendor, device type,
        product code, revision, status, serial, name: Identity attributes 1-7), state."""
        try:
            address = int(ipaddress.IPv4Address(local[0]))
        except ValueError:
            address = 0
        identity = self.call(self._identity)
        return struct.pack("<H", 1) + sockaddr(self.tcp_port, address) + identity + b"\x03"

    def _identity(self) -> bytes:
        return b"".join(self.objects.get(IDENTITY_CLASS, 1, n) for n in range(1, 8))

    def unconnected(self, request: bytes, peer: Peer,
                    nested: bool = False) -> tuple[bytes, list[Item]]:
        service = request[0] if request else 0
        try:
            req = cip.parse_request(request)
            if (req.path.class_id == CONNECTION_MANAGER_CLASS
                    and req.service == cip.UNCONNECTED_SEND and not nested):
                return self.unconnected(_embedded(req.data), peer, nested=True)
            if req.path.class_id == CONNECTION_MANAGER_CLASS and req.service in (
                    cip.FORWARD_OPEN, cip.LARGE_FORWARD_OPEN, cip.FORWARD_CLOSE):
                return self._connection_manager(req, peer)
            return self._answer(req), []
        except CipError as exc:
            return cip.encode_error(service, exc), []
        except Exception:
            return self._internal(service, request), []

    def connected(self, conn_id: int, data: bytes, peer: Peer) -> tuple[int, bytes] | None:
        try:
            return self.table.connected(conn_id, data, peer.session, self.clock(), self.answer)
        except Exception:
            log.exception("enip: class 3 request failed")
            return None

    def session_closed(self, session: int) -> None:
        self.table.session_closed(session)

    # -- answering ----------------------------------------------------------------------------
    def answer(self, request: bytes) -> bytes:
        """A complete reply for one explicit request (class 3 path)."""
        service = request[0] if request else 0
        try:
            req = cip.parse_request(request)
            if req.path.class_id == CONNECTION_MANAGER_CLASS and req.service in (
                    cip.FORWARD_OPEN, cip.LARGE_FORWARD_OPEN):
                raise CipError(cip.SERVICE_NOT_SUPPORTED)   # not over a connection
            if req.path.class_id == CONNECTION_MANAGER_CLASS and req.service == cip.FORWARD_CLOSE:
                return cip.encode_reply(req.service, data=self.table.close(req.data))
            return self._answer(req)
        except CipError as exc:
            return cip.encode_error(service, exc)
        except Exception:
            return self._internal(service, request)

    def _answer(self, req: cip.Request) -> bytes:
        self.requests += 1
        if req.service & cip.REPLY_BIT:
            raise CipError(cip.SERVICE_NOT_SUPPORTED)
        data = self.call(self.objects.handle, req)
        return cip.encode_reply(req.service, data=data)

    def _connection_manager(self, req: cip.Request, peer: Peer) -> tuple[bytes, list[Item]]:
        self.requests += 1
        if req.path.instance not in (None, 1):
            raise CipError(cip.PATH_DESTINATION_UNKNOWN)
        if req.service == cip.FORWARD_CLOSE:
            return cip.encode_reply(req.service, data=self.table.close(req.data)), []
        body, extra = open_or_error(self.table, req, peer.address[0], peer.session,
                                    peer.items, self.clock())
        return cip.encode_reply(req.service, data=body), extra

    def _internal(self, service: int, request: bytes) -> bytes:
        self.failures += 1
        log.exception("enip: request %s failed inside", request[:32].hex(" "))
        return cip.encode_reply(service & 0x7F, cip.RESOURCE_UNAVAILABLE)


def _embedded(data: bytes) -> bytes:
    """The request inside an Unconnected_Send (CIP Vol 1 3-5.5.2); its route is ignored:
    this adapter is the end node."""
    if len(data) < 4:
        raise CipError(cip.NOT_ENOUGH_DATA)
    size = struct.unpack_from("<H", data, 2)[0]
    if len(data) < 4 + size:
        raise CipError(cip.NOT_ENOUGH_DATA)
    return data[4:4 + size]
