"""The relay of ``coolmuscle capture``: every byte both ways, passed on as it arrives.

Two threads: one waits on the motor's port and passes what comes to the host program;
one waits on the host side (a TCP connection or the pty) and passes what comes to the
motor.  Nothing waits for a line end: a byte goes on as soon as it is read, so the host
program's own pacing is kept.  Each chunk is handed to the recorder just before it is
passed on, stamped with the instant it was read (:class:`~.recording.CaptureFile` keeps
it in memory; the file is written on a thread of its own).

What the host side does not take at once waits in a buffer of at most ``MAX_PENDING``
bytes; while it is full the motor is not read (back pressure: the motor's link holds
its bytes, as a wire with flow control would), so memory does not grow with what a
host program leaves unread.  The host program's bytes are written to the motor as they
come; a motor that does not read holds the host program up the same way.  The
recording is bounded too (:class:`~.recording.CaptureFile`: a side is not read while
the file's writer catches up).  Every wait looks at least every ``POLL`` seconds
whether the relay stops, so Ctrl-C ends it at once; what the host program has not
taken by then gets ``flush`` seconds more (:meth:`Relay.close`).

Sockets are read and written as sockets, and the threads are woken through a socket
pair, not a pipe: on Windows a socket is no file descriptor and ``select`` takes
sockets only.
"""

from __future__ import annotations

import os
import select
import selectors
import socket
import threading
import time
from collections.abc import Callable

from ..script.transcript import Direction
from .ends import READ_SIZE, LinkBroken, MotorPort, PtyHostSide, TcpHostSide

__all__ = ["Relay"]

#: Bytes from the motor kept for a host program that does not read them yet; while
#: that many wait, the motor is not read.
MAX_PENDING = 4 << 20
#: Longest wait of either thread before it looks whether the relay stops (s).
POLL = 0.1

Recorder = Callable[[Direction, bytes], None]


class Relay:
    """Relays between ``motor`` and ``host``; ``record`` sees every chunk first.

    ``once``: stop when the first host program disconnects (TCP).  ``say`` prints a
    one-line note (a host connected or left)."""

    def __init__(self, motor: MotorPort, host: TcpHostSide | PtyHostSide, record: Recorder,
                 *, once: bool = False, say: Callable[[str], None] = lambda _text: None
                 ) -> None:
        self.motor = motor
        self.host = host
        self.record = record
        self.once = once
        self.say = say
        self.reason: str | None = None
        self.error: str | None = None
        self.dropped = 0                   # bytes from the motor not passed on
        self._closed = False
        self._done = threading.Event()
        self._out_lock = threading.Lock()
        self._host_fd: int | None = None
        self._host_generation = 0          # a new host program, or none: watch afresh
        self._client: socket.socket | None = None
        self._pending = bytearray()
        self._room = threading.Condition(self._out_lock)    # the pending bytes went down
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._threads = [threading.Thread(target=self._from_motor, name="capture-motor",
                                          daemon=True),
                         threading.Thread(target=self._host_loop, name="capture-host",
                                          daemon=True)]

    # -- life cycle ---------------------------------------------------------
    def start(self) -> None:
        if isinstance(self.host, PtyHostSide):
            self._host_fd = self.host.master
        for thread in self._threads:
            thread.start()

    def stop(self, reason: str, error: str | None = None) -> None:
        """Stop relaying (the first reason given is kept)."""
        with self._out_lock:
            if self.reason is None:
                self.reason, self.error = reason, error
            self._done.set()
            self._room.notify_all()
        self._wake()

    def wait(self) -> str:
        """Block until the relay stops (Ctrl-C interrupts); the reason."""
        while not self._done.wait(0.2):
            pass
        return self.reason or "closed"

    def close(self, flush: float = 1.0) -> None:
        """Stop and release both ends (once; later calls do nothing); what the host
        program has not taken yet gets ``flush`` seconds to go on."""
        if self._closed:
            return
        self._closed = True
        self.stop("closed")
        for thread in self._threads:
            if thread.ident is not None:
                thread.join(timeout=2)
        self._flush_before_close(flush)
        self._detach()
        for wake in (self._wake_r, self._wake_w):
            wake.close()
        self.host.close()
        self.motor.close()

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"!")
        except OSError:        # full (a wake is pending anyway) or closed (stopping)
            pass

    # -- motor -> host ------------------------------------------------------
    def _from_motor(self) -> None:
        try:
            while not self._done.is_set():
                data = self.motor.read(POLL)
                if data:
                    self.record("<", data)
                    self._to_host(data)
        except LinkBroken as exc:
            self.stop("link-broken", str(exc))
        except Exception as exc:           # a bug: the relay stops, said in one line
            self.stop("error", f"the relay failed: {type(exc).__name__}: {exc}")

    def _to_host(self, data: bytes) -> None:
        with self._out_lock:
            fd = self._host_fd
            if fd is None:                  # no host program connected: recorded only
                self.dropped += len(data)
                return
            if not self._pending:
                try:
                    data = data[self._write_host(fd, data):]
                except BlockingIOError:
                    pass
                except OSError:
                    return                  # the host left; its thread notices
            if not data:
                return
            self._pending += data
            self._wake()                    # the host thread waits until it can write
            while (len(self._pending) >= MAX_PENDING and self._host_fd == fd
                   and not self._done.is_set()):
                self._room.wait(POLL)       # the motor is not read meanwhile

    def _flush_pending(self) -> None:
        with self._out_lock:
            if self._host_fd is None or not self._pending:
                return
            try:
                del self._pending[:self._write_host(self._host_fd, self._pending)]
            except BlockingIOError:
                pass
            except OSError:
                self._pending.clear()
            if len(self._pending) < MAX_PENDING:
                self._room.notify_all()

    def _flush_before_close(self, limit: float = 1.0) -> None:
        """What the host program has not taken yet goes on (for ``limit`` s at most):
        the motor's last words before it closed its side reach the program."""
        deadline = time.monotonic() + limit
        while self._pending and self._host_fd is not None:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([], [self._host_fd], [], left)[1]:
                return
            self._flush_pending()
        if isinstance(self.host, PtyHostSide):      # closing it would discard what it holds
            quiet_since = time.monotonic()
            while time.monotonic() < deadline and time.monotonic() - quiet_since < 0.05:
                if self.host.unread():                # (bytes in flight to the reading
                    quiet_since = time.monotonic()    # side show up a moment later)
                time.sleep(0.005)

    # -- host -> motor ------------------------------------------------------
    def _host_loop(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        if isinstance(self.host, TcpHostSide):
            selector.register(self.host.server, selectors.EVENT_READ, "accept")
        watched: tuple[int, int, int] | None = None  # (generation, fd, events) watched
        try:
            while not self._done.is_set():
                for key, mask in selector.select(POLL):
                    if key.data == "wake":
                        self._drain_wake()
                    elif key.data == "accept":
                        self._accept()
                    else:
                        if mask & selectors.EVENT_WRITE:
                            self._flush_pending()
                        if mask & selectors.EVENT_READ:
                            self._from_host()
                watched = self._watch(selector, watched)
        except LinkBroken as exc:
            self.stop("link-broken", str(exc))
        except Exception as exc:           # a bug: the relay stops, said in one line
            self.stop("error", f"the relay failed: {type(exc).__name__}: {exc}")
        finally:
            selector.close()

    def _watch(self, selector: selectors.BaseSelector,
               watched: tuple[int, int, int] | None) -> tuple[int, int, int] | None:
        """Keep the selector on the host's fd: reading, and writing while output waits."""
        with self._out_lock:
            fd = self._host_fd
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if self._pending else 0)
            wanted = (self._host_generation, fd, events) if fd is not None else None
        if wanted == watched:
            return watched
        if watched is not None:
            try:
                selector.unregister(watched[1])
            except (KeyError, ValueError):
                pass
        if wanted is not None:
            selector.register(wanted[1], wanted[2], "host")
        return wanted

    def _write_host(self, fd: int, data: bytes | bytearray) -> int:
        """Write to the host program (the lock held): its socket, or the pty's fd."""
        client = self._client
        return client.send(data) if client is not None else os.write(fd, data)

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except OSError:
            pass

    def _accept(self) -> None:
        assert isinstance(self.host, TcpHostSide)
        accepted = self.host.accept()
        if accepted is None:
            return
        conn, peer = accepted
        if self._client is not None:            # a serial port has one host at a time
            try:
                conn.send(b"coolmuscle capture: another host program is connected\r\n")
            except OSError:
                pass
            conn.close()
            return
        with self._out_lock:
            self._client = conn
            self._host_fd = conn.fileno()
            self._host_generation += 1
            self._pending.clear()
        self.say(f"host program connected from {peer}")

    def _from_host(self) -> None:
        fd, client = self._host_fd, self._client
        if fd is None:
            return
        try:
            data = client.recv(READ_SIZE) if client is not None else os.read(fd, READ_SIZE)
        except BlockingIOError:
            return
        except OSError:
            data = b""                          # reset by the peer: it left
        if not data:
            if isinstance(self.host, TcpHostSide):
                self._detach()
                self.say("host program disconnected")
                if self.once:
                    self.stop("host-closed")
            return
        self.record(">", data)
        self.motor.write(data)

    def _detach(self) -> None:
        with self._out_lock:
            client, self._client = self._client, None
            if client is not None:
                self._host_fd = None
                self._host_generation += 1
                self.dropped += len(self._pending)
                self._pending.clear()
                self._room.notify_all()
        if client is not None:
            client.close()
