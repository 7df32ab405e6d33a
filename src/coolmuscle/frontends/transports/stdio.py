"""Standard input/output transport: the host line on the process's stdin and stdout.

Owns reading host bytes from a file descriptor (stdin by default) and writing the
motor's bytes to another (stdout).  Useful behind ``socat EXEC:...``, ``ssh``, or
another program's pipes.

* When stdin is a terminal it is put in raw mode for the session (restored on close)
  so the motor's own echo is the only echo and bytes reach it as typed; Ctrl-C
  still stops the simulator (output post-processing stays on, for stderr's sake).
* Output is written by a small writer thread, so a consumer that stops reading never
  blocks the motor; beyond ``max_buffer`` unwritten bytes new output is discarded.
* End of input sets ``finished``: the simulator stops (``stops_service``).
"""

from __future__ import annotations

import asyncio
import logging
import os
import termios
import threading
import time
import tty
from collections.abc import Callable
from typing import Any

from ...errors import TransportError
from .base import DEFAULT_MAX_BUFFER, Lane, Port, Transport

log = logging.getLogger(__name__)

READ_SIZE = 4096


class StdioTransport(Transport):
    """Serve the host line on a pair of file descriptors (default stdin/stdout)."""

    name = "stdio"
    stops_service = True

    def __init__(self, in_fd: int = 0, out_fd: int = 1, *, raw_tty: bool = True,
                 max_buffer: int = DEFAULT_MAX_BUFFER) -> None:
        super().__init__()
        self.in_fd = in_fd
        self.out_fd = out_fd
        self.raw_tty = raw_tty
        self.max_buffer = max_buffer
        self.bytes_discarded = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._saved_tty: list[Any] | None = None
        self._reader_added = False
        self._reader_thread: threading.Thread | None = None
        self._out = bytearray()
        self._out_cond = threading.Condition()
        self._writer_thread: threading.Thread | None = None
        self._closing = False
        self._unsubscribe: Callable[[], None] | None = None
        self._lane: Lane | None = None

    # -- life cycle -----------------------------------------------------
    async def start(self, port: Port) -> None:
        self.port = port
        self._loop = asyncio.get_running_loop()
        for fd in (self.in_fd, self.out_fd):
            try:
                os.fstat(fd)
            except OSError as exc:
                raise TransportError(f"stdio: file descriptor {fd} is not open: {exc}") from exc
        if self.raw_tty and os.isatty(self.in_fd):
            self._enter_raw()
        try:
            self._loop.add_reader(self.in_fd, self._on_readable)
            self._reader_added = True
        except (OSError, ValueError):  # regular files cannot be polled: read in a thread
            self._reader_thread = threading.Thread(target=self._read_blocking,
                                                   name="coolmuscle-stdin", daemon=True)
            self._reader_thread.start()
        self._writer_thread = threading.Thread(target=self._write_loop,
                                               name="coolmuscle-stdout", daemon=True)
        self._writer_thread.start()
        self._lane = port.open_lane("stdio")
        self._lane.set_flow(self._pause_reading, self._resume_reading)
        self._unsubscribe = port.add_listener(self._send)

    def _pause_reading(self) -> None:
        if self._reader_added and self._loop is not None:
            self._loop.remove_reader(self.in_fd)

    def _resume_reading(self) -> None:
        if self._reader_added and self._loop is not None:
            self._loop.add_reader(self.in_fd, self._on_readable)

    def _enter_raw(self) -> None:
        try:
            self._saved_tty = termios.tcgetattr(self.in_fd)
            tty.setraw(self.in_fd, termios.TCSANOW)
            attrs = termios.tcgetattr(self.in_fd)
            attrs[3] |= termios.ISIG   # keep Ctrl-C / Ctrl-\ as signals
            attrs[1] |= termios.OPOST  # keep log lines on stderr readable
            termios.tcsetattr(self.in_fd, termios.TCSANOW, attrs)
        except termios.error as exc:
            log.warning("stdio: cannot put the terminal in raw mode: %s", exc)
            self._saved_tty = None

    def describe(self) -> str:
        return "stdio: stdin/stdout" if (self.in_fd, self.out_fd) == (0, 1) \
            else f"stdio: fd {self.in_fd}/{self.out_fd}"

    async def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._reader_added and self._loop is not None:
            self._loop.remove_reader(self.in_fd)
            self._reader_added = False
        with self._out_cond:
            self._closing = True
            self._out_cond.notify_all()
        if self._writer_thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._writer_thread.join, 2.0)
            self._writer_thread = None
        if self._saved_tty is not None:
            try:
                termios.tcsetattr(self.in_fd, termios.TCSADRAIN, self._saved_tty)
            except termios.error:
                pass
            self._saved_tty = None
        self.finished.set()

    # -- input ----------------------------------------------------------
    def _on_readable(self) -> None:
        try:
            data = os.read(self.in_fd, READ_SIZE)
        except BlockingIOError:
            return
        except OSError as exc:
            log.warning("stdio: read failed: %s", exc)
            data = b""
        self._deliver(data)

    def _deliver(self, data: bytes) -> None:
        if data:
            if self._lane is not None:
                self._lane.feed(data)
            return
        if self._reader_added and self._loop is not None:
            self._loop.remove_reader(self.in_fd)
            self._reader_added = False
        self._finish_when_run()

    def _finish_when_run(self) -> None:
        """End of input: finish once every line read has had its turn."""
        if self._lane is not None and self._lane.backlog and self._loop is not None:
            self._loop.call_soon(self._finish_when_run)
            return
        log.info("stdio: end of input")
        self.finished.set()

    def _read_blocking(self) -> None:
        loop = self._loop
        assert loop is not None
        while not self._closing:
            try:
                data = os.read(self.in_fd, READ_SIZE)
            except OSError:
                data = b""
            try:
                loop.call_soon_threadsafe(self._deliver, data)
            except RuntimeError:  # loop closed
                return
            if not data:
                return

    # -- output ---------------------------------------------------------
    def _send(self, data: bytes) -> None:
        with self._out_cond:
            room = self.max_buffer - len(self._out)
            if room < len(data):
                self.bytes_discarded += len(data) - max(room, 0)
                data = data[:max(room, 0)]
            self._out += data
            self._out_cond.notify()

    def _write_loop(self) -> None:
        while True:
            with self._out_cond:
                while not self._out and not self._closing:
                    self._out_cond.wait()
                if not self._out and self._closing:
                    return
                chunk = bytes(self._out)
                self._out.clear()
            view = memoryview(chunk)
            while view:
                try:
                    written = os.write(self.out_fd, view)
                except BlockingIOError:
                    time.sleep(0.01)
                    continue
                except OSError as exc:
                    log.info("stdio: output closed: %s", exc)
                    with self._out_cond:
                        self._closing = True
                        self._out.clear()
                    return
                view = view[written:]
