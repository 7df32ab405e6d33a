"""The slave stack: the firmware beside the ESC (what SOES is for a real chip).

:class:`SlaveStack` is the ESC's :class:`~.esc.Pdi`, configured by a
:class:`~.description.SlaveDescription`: it writes the SII image from it, runs the
state machine (:mod:`.esm`) with the configuration checks of ETG.1000.6 (the
SyncManagers a master sets up must be the description's: mailbox addresses and
sizes, process-data sizes, an SM watchdog not shorter than its cycle; checked again
when the master (de)activates a SyncManager in PRE-OP and above), serves the
mailbox (CoE through :class:`~.coe.CoeServer`, a mailbox error for the rest), moves
the process images, and trips to SAFE-OP with 001Bh when the SM watchdog expires.
It runs in the frame thread and never waits for the application.

The application plugs in through :class:`Application`: state change requests,
the object dictionary (the mailbox service), output images in; it hands input
images back with :meth:`SlaveStack.set_inputs` from any thread.
"""

from __future__ import annotations

import logging
import struct
from collections import deque
from typing import Protocol

from . import esm
from .coe import CoeServer, UnsupportedService
from .description import SlaveDescription, SyncManagerLayout
from .dictionary import Dictionary
from .esc import Esc, SyncManager
from .sii import build_sii

log = logging.getLogger(__name__)

MBX_ERR, MBX_COE = 0x00, 0x03
#: Answers kept for a master that has not read them; then SM0 is not taken.
MAX_QUEUED = 32
# Mailbox error codes (ETG.1000.4 table 29).
MBXERR_SYNTAX, MBXERR_UNSUPPORTED_PROTOCOL, MBXERR_SERVICE = 0x01, 0x02, 0x04
MBXERR_SIZE_TOO_SHORT, MBXERR_INVALID_SIZE = 0x06, 0x08


class Application(Protocol):
    """What the device behind the slave provides (its application, or a test double)."""

    dictionary: Dictionary

    def state_change(self, current: int, requested: int) -> int:
        """A valid transition is about to happen; return 0 or an AL status code to refuse."""

    def outputs(self, image: bytes) -> None:
        """A new output image arrived in OP (already unpacked into the dictionary)."""

    def safe_outputs(self) -> None:
        """OP was left (request, watchdog): the outputs go to their safe state."""


class SlaveStack:
    """ESM, mailbox and process data between an :class:`Esc` and an :class:`Application`."""

    def __init__(self, app: Application, description: SlaveDescription) -> None:
        self.app = app
        self.description = description
        self.od = app.dictionary
        self.sii = build_sii(description)
        self.esc = Esc(self, self.sii)
        self.coe = CoeServer(self.od, description.mailbox_in.size)
        self._queue: deque[bytes] = deque()
        self._waiting: bytes | None = None
        self._counter = 0
        self.transitions: list[tuple[int, int, int]] = []    # (from, to, code), for tests

    # -- state ---------------------------------------------------------------
    @property
    def state(self) -> int:
        return self.esc.al_status & 0x0F

    def al_control(self, value: int) -> None:
        before = self.esc.al_status
        out = esm.request(before, self.esc.al_code, value, self._check)
        self._apply(before, out)

    def _apply(self, before: int, out: esm.Outcome) -> None:
        old = before & 0x0F
        if out.changed:
            self._entered(old, out.state)
        self.esc.set_al_status(out.al_status, out.code)
        if out.al_status != before or out.code:
            self.transitions.append((old, out.state, out.code))
            log.info("AL %s -> %s%s", esm.NAMES.get(old, old), esm.NAMES.get(out.state),
                     f" (error 0x{out.code:04X})" if out.error else "")

    def _entered(self, old: int, new: int) -> None:
        if old == esm.OP:
            self._call_safe_outputs()
        if new == esm.INIT:
            self._queue.clear()
            self._waiting = None

    def _call_safe_outputs(self) -> None:
        try:
            self.app.safe_outputs()
        except Exception:
            log.exception("application failed to make its outputs safe")

    def _check(self, current: int, requested: int) -> int:
        code = self._config_check(current, requested)
        if code:
            return code
        try:
            return self.app.state_change(current, requested)
        except Exception:
            log.exception("application refused a state change by failing")
            return esm.UNSPECIFIED

    def _config_check(self, current: int, requested: int) -> int:
        sm, d = self.esc.sm, self.description
        if (current, requested) == (esm.INIT, esm.PREOP):
            if not (_matches(sm[0], d.mailbox_out, d.mailbox_out.size, True)
                    and _matches(sm[1], d.mailbox_in, d.mailbox_in.size, False)
                    and sm[0].mailbox and sm[1].mailbox):
                return esm.INVALID_MAILBOX_CONFIG
        if (current, requested) == (esm.PREOP, esm.SAFEOP):
            code = self._process_data_check()
            if code:
                return code
            wd = self.esc.watchdog_ns()
            if sm[2].control & 0x40 and 0 < wd < d.cycle_ns:
                return esm.INVALID_WATCHDOG_CONFIG
        return 0

    def _process_data_check(self) -> int:
        sm, d = self.esc.sm, self.description
        if not (_matches(sm[2], d.outputs, d.output_size, True) and not sm[2].mailbox):
            return esm.INVALID_OUTPUT_CONFIG
        if not (_matches(sm[3], d.inputs, d.input_size, False) and not sm[3].mailbox):
            return esm.INVALID_INPUT_CONFIG
        return 0

    def watchdog_expired(self) -> None:
        if self.state != esm.OP:
            return
        before = self.esc.al_status
        self._apply(before, esm.fault(before, esm.SAFEOP, esm.SM_WATCHDOG))

    def sm_changed(self, sm: int) -> None:
        """The master (de)activated a SyncManager: in PRE-OP and above the configuration
        the state rests on is checked again (ETG.1000.6; what SOES does on the AL event
        "SM change").  A mailbox SyncManager that no longer matches takes the device to
        INIT with 0016h, a process data one (SAFE-OP, OP) to PRE-OP with 001Dh / 001Eh."""
        state = self.state
        if state not in (esm.PREOP, esm.SAFEOP, esm.OP):
            return
        code = self._config_check(esm.INIT, esm.PREOP)
        to_state = esm.INIT
        if not code and state != esm.PREOP:
            code = self._process_data_check()
            to_state = esm.PREOP
        if code:
            before = self.esc.al_status
            self._apply(before, esm.fault(before, to_state, code))

    # -- process data -------------------------------------------------------
    def outputs_written(self, sm: int, data: bytes) -> None:
        if sm != 2 or self.state != esm.OP:
            return                      # SAFE-OP: outputs are not taken (ETG.1000.6 6.4.1)
        self.od.unpack_outputs(data)
        try:
            self.app.outputs(data)
        except Exception:
            log.exception("application failed on an output image")

    def set_inputs(self, image: bytes) -> None:
        """The application's new input image (SM3); safe from any thread."""
        self.esc.set_inputs(3, image)

    # -- mailbox ------------------------------------------------------------
    def mailbox_received(self, sm: int, data: bytes) -> None:
        if sm != 0 or self.state == esm.INIT:
            self.esc.take_mailbox(sm)
            return
        if len(self._queue) >= MAX_QUEUED:
            self._waiting = data       # answers not read yet: SM0 stays full (no WKC)
            return
        self.esc.take_mailbox(sm)
        try:
            self._serve(data)
        except Exception:
            log.exception("mailbox service failed")
        self._pump()

    def _serve(self, data: bytes) -> None:
        if len(data) < 6:
            self._send(MBX_ERR, struct.pack("<HH", 0x0001, MBXERR_SIZE_TOO_SHORT))
            return
        length, _address, _channel, kind = struct.unpack_from("<HHBB", data)
        payload = data[6:6 + length]
        if length > len(data) - 6:
            self._send(MBX_ERR, struct.pack("<HH", 0x0001, MBXERR_INVALID_SIZE))
            return
        if kind & 0x0F != MBX_COE:
            self._send(MBX_ERR, struct.pack("<HH", 0x0001, MBXERR_UNSUPPORTED_PROTOCOL))
            return
        if length < 2:
            self._send(MBX_ERR, struct.pack("<HH", 0x0001, MBXERR_SIZE_TOO_SHORT))
            return
        try:
            answers = self.coe.handle(payload)
        except UnsupportedService:
            self._send(MBX_ERR, struct.pack("<HH", 0x0001, MBXERR_SERVICE))
            return
        for answer in answers:
            self._send(MBX_COE, answer)

    def _send(self, kind: int, payload: bytes) -> None:
        self._counter = self._counter % 7 + 1
        header = struct.pack("<HHBB", len(payload), 0, 0, kind | self._counter << 4)
        self._queue.append(header + payload)

    def mailbox_read(self, sm: int) -> None:
        self._pump()

    def _pump(self) -> None:
        while self._queue and self.esc.post_mailbox(1, self._queue[0]):
            self._queue.popleft()
        if self._waiting is not None and len(self._queue) < MAX_QUEUED:
            data, self._waiting = self._waiting, None
            self.mailbox_received(0, data)


def _matches(sm: SyncManager, layout: SyncManagerLayout, length: int,
             master_writes: bool) -> bool:
    """The master set SyncManager ``sm`` up where the description has it, with ``length``."""
    return sm.enabled and sm.start == layout.start and sm.length == length \
        and sm.master_writes == master_writes
