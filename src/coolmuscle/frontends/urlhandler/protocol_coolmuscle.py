"""pyserial URL handler ``coolmuscle://``: an in-process virtual chain as a serial port.

URL format::

    coolmuscle://[?option[&option...]]

options:

- ``motors=N``                   motors on the chain, 1..15 (default 1)
- ``firmware=cm2|rt3|cm1``       firmware profile (default cm2)
- ``state=PATH``                 state directory of the persistent store (default: none)
- ``machine=PATH``               a machine file installed before power-up
  (docs/machine-file.md): the load, sensors, faults, and wire faults (docs/wire-faults.md)
- ``mode=realtime|fast``         ``realtime`` (default): virtual time follows the wall
  clock while the port is used.  ``fast``: virtual time moves only inside ``read``:
  a read with timeout T advances virtual time by up to T instantly, stopping as soon
  as the requested bytes are there (deterministic, no waiting)
- ``pacing=on|off``              bytes take their K20 wire time (default off)
- ``scale=X``                    realtime only: virtual seconds per wall second (default 1)
- ``logging=debug|info|warning|error``  log handler activity

Registered with pyserial by :func:`coolmuscle.register_url_handler`
(``serial.protocol_handler_packages``; :mod:`coolmuscle.frontends.urlhandler`)::

    import coolmuscle, serial
    coolmuscle.register_url_handler()
    port = serial.serial_for_url("coolmuscle://?motors=2&mode=fast", timeout=1)
    port.write(b"?96.1\\r")

Every port has its own chain (``port.chain``, ``port.kernel``); closing the port
closes the chain (and its store).  Calls from several threads are serialised by a
lock.  The baud rate set on the port is not checked against K20 (as with ``loop://``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from serial.serialutil import (  # type: ignore[attr-defined]  # to_bytes: not in its stubs
    PortNotOpenError,
    SerialBase,
    SerialException,
    to_bytes,
)

from ...device.api import Device
from ...errors import CoolMuscleError
from ...sim.kernel import NS_PER_S, Kernel, seconds
from ...sim.realtime import FastClock, RealtimeClock
from ..transports.base import split_after_line_ends

if TYPE_CHECKING:
    from typing_extensions import Buffer

log = logging.getLogger("coolmuscle.frontends.urlhandler")

URL_FORMAT = ("coolmuscle://[?motors=N][&firmware=cm2|rt3|cm1][&state=PATH][&machine=PATH]"
              "[&mode=realtime|fast][&pacing=on|off][&scale=X]"
              "[&logging=debug|info|warning|error]")

FIRMWARES = ("cm2", "rt3", "cm1")
MODES = ("realtime", "fast")
LOGGER_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO,
                 "warning": logging.WARNING, "error": logging.ERROR}
_BOOL = {"on": True, "1": True, "true": True, "yes": True,
         "off": False, "0": False, "false": False, "no": False}


def _default_chain_factory(kernel: Kernel | None, motors: int, *, firmware: str,
                           state_dir: Path | None, pacing: bool,
                           machine: Path | None = None) -> Device:
    from ...chain.daisy import Chain
    return Chain(kernel, motors, firmware=firmware, state_dir=state_dir, pacing=pacing,
                 machine=machine)


#: Builds the chain behind each port: ``factory(kernel, motors, firmware=..., state_dir=...,
#: pacing=...)`` (and ``machine=...`` when the URL names one).  Tests and embedders may
#: replace it.
chain_factory: Callable[..., Device] = _default_chain_factory


def parse_url(url: str) -> dict[str, Any]:
    """Options of a ``coolmuscle://`` URL; raises ``SerialException`` showing the form."""
    def bad(reason: str) -> SerialException:
        return SerialException(f'expected a string in the form "{URL_FORMAT}": {reason}')

    parts = urllib.parse.urlsplit(url)
    if parts.scheme.lower() != "coolmuscle":
        raise bad(f"not starting with coolmuscle:// ({parts.scheme!r})")
    if parts.netloc or parts.path not in ("", "/"):
        raise bad(f"unexpected {parts.netloc + parts.path!r} before '?'")
    options: dict[str, Any] = {"motors": 1, "firmware": "cm2", "state": None, "machine": None,
                               "mode": "realtime", "pacing": False, "scale": 1.0,
                               "logging": None}
    try:
        query = urllib.parse.parse_qs(parts.query, keep_blank_values=True, strict_parsing=False)
    except ValueError as exc:
        raise bad(str(exc)) from None
    for option, values in query.items():
        value = values[-1]
        if option == "motors":
            if not value.isdigit() or not 1 <= int(value) <= 15:
                raise bad(f"motors must be 1..15, not {value!r}")
            options["motors"] = int(value)
        elif option == "firmware":
            if value.lower() not in FIRMWARES:
                raise bad(f"unknown firmware {value!r}")
            options["firmware"] = value.lower()
        elif option == "state":
            if not value:
                raise bad("state needs a directory")
            options["state"] = Path(value).expanduser()
        elif option == "machine":
            if not value:
                raise bad("machine needs a file")
            options["machine"] = Path(value).expanduser()
        elif option == "mode":
            if value not in MODES:
                raise bad(f"unknown mode {value!r}")
            options["mode"] = value
        elif option == "pacing":
            if value.lower() not in _BOOL:
                raise bad(f"pacing must be on or off, not {value!r}")
            options["pacing"] = _BOOL[value.lower()]
        elif option == "scale":
            try:
                scale = float(value)
            except ValueError:
                scale = math.nan
            if not (scale > 0 and math.isfinite(scale)):
                raise bad(f"scale must be a positive number, not {value!r}")
            options["scale"] = scale
        elif option == "logging":
            if value not in LOGGER_LEVELS:
                raise bad(f"unknown logging level {value!r}")
            options["logging"] = value
        else:
            raise bad(f"unknown option: {option!r}")
    return options


def on_chain(chain: Any, *, mode: str = "fast", timeout: float | None = 1.0) -> Serial:
    """An open port whose far end is ``chain``, a chain the caller built and keeps:
    closing the port leaves the chain open (the test plug-in's ``cm_chain.port()``)."""
    port = Serial(timeout=timeout)
    port._given_chain = chain
    port.port = f"coolmuscle://?mode={mode}"
    port.open()
    return port


class Serial(SerialBase):
    """A pyserial port whose far end is a virtual Cool Muscle chain."""

    BAUDRATES = (9600, 19200, 38400, 57600, 115200, 230400)
    # SerialBase keeps the settings here (its stubs name only the public properties)
    _port: str | None
    _baudrate: int
    _timeout: float | None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.chain: Device | None = None
        self.options: dict[str, Any] = {}
        self._clock: RealtimeClock | FastClock | None = None
        self._cond = threading.Condition(threading.RLock())
        self._rx = bytearray()
        self._unsubscribe: Callable[[], None] | None = None
        self._cancel = False
        self._given_chain: Any = None        # on_chain(): the caller's chain, kept open
        super().__init__(*args, **kwargs)

    # -- open / close ---------------------------------------------------
    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.options = options = parse_url(self._port)
        if options["logging"]:
            logging.basicConfig()
            log.setLevel(LOGGER_LEVELS[options["logging"]])
        if options["state"] is not None:
            try:
                options["state"].mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise SerialException(f"coolmuscle: cannot use state directory: {exc}") from exc
        extra = {"machine": options["machine"]} if options["machine"] is not None else {}
        try:
            chain = self._given_chain or chain_factory(
                None, options["motors"], firmware=options["firmware"],
                state_dir=options["state"], pacing=options["pacing"], **extra)
        except (CoolMuscleError, OSError, ValueError) as exc:
            raise SerialException(f"coolmuscle: cannot start the virtual chain: {exc}") from exc
        with self._cond:
            self.chain = chain
            self._rx.clear()
            self._cancel = False
            if options["mode"] == "fast":
                self._clock = FastClock(chain.kernel)
            else:
                self._clock = RealtimeClock(chain.kernel, scale=options["scale"])
            self._unsubscribe = chain.host_line.add_listener(self._on_bytes)
        self._reconfigure_port()
        self.is_open = True
        log.info("opened %s", self._port)

    def close(self) -> None:
        with self._cond:
            if self._unsubscribe is not None:
                self._unsubscribe()
                self._unsubscribe = None
            chain, self.chain = self.chain, None
            self.is_open = False
            self._cond.notify_all()
        if chain is not None and chain is not self._given_chain:
            try:
                chain.close()
            except Exception:
                log.exception("closing the virtual chain failed")
        super().close()

    def _reconfigure_port(self) -> None:
        if not isinstance(self._baudrate, int) or not 0 < self._baudrate < 2 ** 32:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")

    @property
    def kernel(self) -> Kernel | None:
        """The chain's kernel (``kernel.now`` is the virtual time in ns)."""
        return self.chain.kernel if self.chain is not None else None

    # -- model side -----------------------------------------------------
    def _on_bytes(self, data: bytes) -> None:
        with self._cond:
            self._rx += data
            self._cond.notify_all()

    def _catch_up(self) -> None:
        assert self._clock is not None
        try:
            self._clock.catch_up()
        except Exception:  # a model bug must not surface as a serial error
            log.exception("virtual chain failed while running")

    # -- pyserial API ---------------------------------------------------
    @property
    def in_waiting(self) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        with self._cond:
            self._catch_up()
            return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        if not self.is_open:
            raise PortNotOpenError()
        if size <= 0:
            return b""
        with self._cond:
            self._cancel = False
            if isinstance(self._clock, FastClock):
                self._read_fast(size)
            else:
                self._read_realtime(size)
            data = bytes(self._rx[:size])
            del self._rx[:size]
            return data

    def _read_fast(self, size: int) -> None:
        kernel = self._clock.kernel  # type: ignore[union-attr]

        def ready() -> bool:
            return len(self._rx) >= size or self._cancel or self.chain is None
        try:
            if self._timeout is None:
                while not ready():
                    if kernel.peek() is None:
                        self._cond.wait(0.05)  # nothing scheduled: only another thread can help
                    else:
                        kernel.run_until(ready, NS_PER_S)
                        self._cond.wait(0)  # let writers in between virtual seconds
            elif self._timeout > 0 and not ready():
                kernel.run_until(ready, seconds(self._timeout))
        except Exception:
            log.exception("virtual chain failed while running")

    def _read_realtime(self, size: int) -> None:
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while True:
            self._catch_up()
            if len(self._rx) >= size or self._cancel or self.chain is None:
                return
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return
            nxt = self._clock.seconds_until_next()  # type: ignore[union-attr]
            waits = [w for w in (remaining, nxt) if w is not None]
            self._cond.wait(min(waits) if waits else None)

    def write(self, data: Buffer) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        payload: bytes = to_bytes(data)
        with self._cond:
            self._catch_up()
            chain = self.chain
            for piece in split_after_line_ends(payload):  # a failing line costs only itself
                if chain is None:             # closed by another thread meanwhile
                    break
                try:
                    chain.host_line.feed(piece)
                except Exception:  # front-end entry point: the model's failure is logged
                    log.exception("virtual chain failed on input %r", piece[:64])
            self._cond.notify_all()  # a reader may need to re-plan (pacing scheduled events)
        return len(payload)

    def flush(self) -> None:
        """Nothing to drain: written bytes are already in the motor (or on the wire)."""

    def reset_input_buffer(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        with self._cond:
            self._rx.clear()

    def reset_output_buffer(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def out_waiting(self) -> int:
        return 0

    def cancel_read(self) -> None:
        with self._cond:
            self._cancel = True
            self._cond.notify_all()

    def cancel_write(self) -> None:
        """Writes never block."""

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return True

    @property
    def dsr(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return True

    @property
    def ri(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return False

    @property
    def cd(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return False
