"""``coolmuscle term URL``: the interactive terminal, as a CoolWorks Lite user expects it.

Type CML lines; they go to the motor as typed (2.1 "Like chatting online").  What the
motor says appears as it arrives, also between lines you type, in colour:

* replies (``Px.1=10000``) green, K23 reports (``Ux.1=8`` with its flags decoded,
  ``IN.1=``, ``OUT.1=``) cyan, messages (``saved.1``, ``End.1``) yellow, errors
  (``error01.1: syntax error!!``, no answer, a lost connection) red, unreadable bytes
  magenta.  The echo is not shown twice: you see what you typed at the prompt.  A
  query whose reply does not come within the timeout (``--timeout``, 1 s) is said so
  (``no reply to '?96.1' within 1 s``), and a line whose echo does not come either
  (the line is down).

Line editing and history come from prompt_toolkit (the ``term`` extra; history kept in
``$XDG_STATE_HOME/coolmuscle/term_history``).  When the input is not a terminal (a
file or a pipe: ``coolmuscle term URL < lines.txt``, on any system) each line is sent
as it is read, what the motor says is printed plainly, and at the end of the input the
terminal waits until the motor has said nothing for ``--timeout`` seconds; this needs
no prompt_toolkit.  Commands start with ``:``:

``:send FILE.cml``   upload a file with a progress bar and verify its banks (``upload``)
``:save [ID]``       ``$`` and wait for ``saved.n`` (default: the terminal's motor)
``:log FILE``        record the session as a golden transcript (docs/scripts.md);
                     ``:log off`` stops
``:motor ID``        the motor ID ``:save`` and ``:send`` use (one that answers)
``:help``, ``:quit`` (or Ctrl-D)

A lost connection (the peer closed it, the cable was pulled) is said at once, in red,
and ends the terminal with exit status 1: no line typed after it is lost silently.
"""

from __future__ import annotations

import asyncio
import os
import re
import shlex
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...client import AsyncCoolMuscle, connect_async
from ...client.program import load_program
from ...client.protocol import MotorEvent
from ...errors import CoolMuscleError, CoolMuscleTimeout, TransportError
from ...motor.status import Ux
from ...needs import needs_extra
from ..script.transcript import TranscriptRecorder

if TYPE_CHECKING:
    from prompt_toolkit.history import History

__all__ = ["run_term", "STYLES", "HELP"]

#: Colours (prompt_toolkit ANSI names) by what is shown.
STYLES = {"reply": "ansigreen", "status": "ansicyan", "input": "ansicyan",
          "output": "ansicyan", "message": "ansiyellow", "error": "ansired",
          "garbled": "ansimagenta", "info": "ansiblue"}

#: A line the motor answers with a reply: a query (6.6) or a K parameter read alone.
_ASKS = re.compile(r"\s*(\?|K\d+(\.\d+)?\s*$)", re.IGNORECASE)

HELP = """commands: :send FILE.cml   :save [ID]   :log FILE | :log off   :motor ID
          :help   :quit (or Ctrl-D); anything else is sent to the motor as typed"""


def default_history() -> Path:
    """``$XDG_STATE_HOME/coolmuscle/term_history`` (``~/.local/state/...``; on Windows
    in ``%LOCALAPPDATA%``)."""
    local = os.environ.get("LOCALAPPDATA") if os.name == "nt" else None
    base = os.environ.get("XDG_STATE_HOME") or local or os.path.expanduser("~/.local/state")
    return Path(base) / "coolmuscle" / "term_history"


#: How a line is shown: ``show(text, style)`` (a key of :data:`STYLES`).
Show = Callable[[str, str], None]


def show(text: str, style: str) -> None:
    """Print one line in colour above the prompt (prompt_toolkit)."""
    from prompt_toolkit import print_formatted_text
    from prompt_toolkit.formatted_text import FormattedText

    print_formatted_text(FormattedText([(STYLES.get(style, ""), text)]))


def show_plain(text: str, _style: str) -> None:
    """Print one line as it is (input from a file or a pipe)."""
    print(text, flush=True)


def describe(event: MotorEvent) -> tuple[str, str]:
    """``(text, style)`` for an event; Ux reports get their flags spelled out."""
    if event.kind == "status" and event.value is not None:
        names = [flag.name for flag in Ux if flag and event.value & flag and flag.name]
        flags = "+".join(names) if names else "RUNNING"
        return f"{event.text}  ({flags.lower().replace('_', ' ')})", "status"
    if event.kind == "garbled":
        return f"unreadable: {event.text!r}", "garbled"
    if event.kind == "unsolicited":
        return event.text, "reply"
    return event.text, event.kind


class Terminal:
    """One terminal session on one connection."""

    def __init__(self, client: AsyncCoolMuscle, url: str, show: Show = show,
                 timeout: float = 1.0) -> None:
        self.client = client
        self.url = url
        self.motor = client.id
        self.show = show
        self.timeout = timeout
        self.recorder: TranscriptRecorder | None = None
        self._untap: Callable[[], None] | None = None
        #: The loop time of the last line the motor said or the terminal sent.
        self.last_activity = 0.0
        #: why the connection was lost (``None``: it works)
        self.lost: BaseException | None = None
        self.lines_in = 0             # line ends received, echoes too
        self.events_in = 0            # lines received that are not an echo
        #: lines whose echo or reply is still awaited (:meth:`_watch`)
        self.watching = 0
        client.add_tap(self._count)

    def _count(self, direction: str, data: bytes) -> None:
        if direction == "<":
            self.lines_in += data.count(b"\r")       # K70: CR or CR LF (ch. 3)

    def _touch(self) -> None:
        try:
            self.last_activity = asyncio.get_running_loop().time()
        except RuntimeError:          # an event outside the loop (a test's direct call)
            pass

    def on_event(self, event: MotorEvent) -> None:
        self._touch()
        self.events_in += 1
        text, style = describe(event)
        self.show(text, style)

    def log_failed(self, text: str) -> None:
        """The log's file failed (a full disk): said once; the session goes on."""
        self.show(f"log: {text}; the session goes on", "error")

    async def handle(self, line: str) -> bool:
        """One input line; ``False`` ends the session."""
        if line.startswith(":"):
            return await self.command(line[1:].strip())
        self._touch()
        try:
            self.client.write_line(line)
        except TransportError as exc:
            self.connection_lost(exc)
            return False
        self._watch(line)
        return True

    def _watch(self, line: str) -> None:
        """Say so when what a line brings does not come within the timeout: its echo
        (once the motor is known to echo, ch. 3 K23 8) and, for a query, its reply
        (a dropped reply, a dead line: docs/wire-faults.md)."""
        echo = self.client.echo is True
        query = bool(_ASKS.match(line))
        if echo or query:
            self.watching += 1
            asyncio.get_running_loop().call_later(self.timeout, self._check, line,
                                                  self.lines_in, self.events_in, query, echo)

    def _check(self, line: str, lines: int, events: int, query: bool, echo: bool) -> None:
        """``lines``, ``events``: the counts when ``line`` was sent.  The echo is no
        event (the client knows it), so a reply is an event; any line end is a line."""
        self.watching -= 1
        if self.lost is not None:
            return
        if echo and self.lines_in == lines:
            self.show(f"no answer to {line!r} within {self.timeout:g} s, not even its "
                      "echo: is the line down?", "error")
        elif query and self.events_in == events:
            self.show(f"no reply to {line!r} within {self.timeout:g} s", "error")

    def connection_lost(self, error: BaseException) -> None:
        """The port failed: said once, in red; the session ends (exit status 1)."""
        if self.lost is None:
            self.lost = error
            self.show(f"connection lost: {error}; the terminal ends", "error")

    async def command(self, text: str) -> bool:
        words = shlex.split(text) if text else [""]
        name, args = words[0].lower(), words[1:]
        try:
            if name in ("quit", "exit", "q"):
                return False
            if name == "send" and len(args) == 1:
                await self.send_file(Path(args[0]))
            elif name == "save" and len(args) <= 1:
                motor = int(args[0]) if args else self.motor
                await self.client.motor(motor).save()
                self.show(f"saved.{motor}", "message")
            elif name == "log" and len(args) == 1:
                self.log(args[0])
            elif name == "motor" and len(args) == 1 and args[0].isdigit():
                await self.select_motor(int(args[0]))
            else:
                self.show(HELP, "info")
        except (CoolMuscleError, OSError, ValueError) as exc:
            self.show(f"{name}: {exc}", "error")
        return True

    async def select_motor(self, motor_id: int) -> None:
        """``:motor ID``: a motor ID of the chain (1..15, 1.1) that answers ``?99``."""
        motor = self.client.motor(motor_id)
        try:
            await motor.get_status()
        except CoolMuscleTimeout:
            raise CoolMuscleError(f"ID{motor.id} does not answer (no reply to "
                                  f"?99.{motor.id}): still ID{self.motor}") from None
        self.motor = motor.id
        self.show(f"motor ID{self.motor}", "info")

    def log(self, target: str) -> None:
        if self.recorder is not None and self._untap is not None:
            self._untap()
            self.recorder.close()
            self.show(f"log written: {self.recorder.path}", "info")
            self.recorder = None
        if target.lower() != "off":
            self.recorder = TranscriptRecorder(target, self.url, on_error=self.log_failed)
            self._untap = self.client.add_tap(self.recorder.tap)
            self.show(f"logging to {target} (:log off to stop)", "info")

    async def send_file(self, path: Path) -> None:
        program = load_program(path)
        bad = [line for line in program.source_lines if line.error is not None]
        if bad:
            raise CoolMuscleError(f"{path}: {len(bad)} syntax error(s) (coolmuscle check "
                                  f"{path}); nothing sent")
        total = program.send_count()
        upload = self.client.motor(self.motor).upload
        if self.show is show:          # on the screen: prompt_toolkit's progress bar
            from prompt_toolkit.shortcuts import ProgressBar

            with ProgressBar(title=f"sending {path.name}") as bar:
                counter = bar(range(total), total=total, label="lines")

                def progress(done: int, _total: int) -> None:
                    while counter.items_completed < done:
                        counter.item_completed()
                result = await upload(program, check=False, progress=progress)
        else:
            self.show(f"sending {path.name}: {total} line(s)", "info")
            result = await upload(program, check=False)
        self._touch()
        for line in result.report():
            self.show(line, "error")
        verdict = "verified" if result.ok else "FAILED"
        self.show(f"sent {result.sent} line(s) of {path.name}; banks "
                  f"{', '.join(result.banks) or '-'} {verdict}",
                  "message" if result.ok else "error")

    def close(self) -> None:
        if self.recorder is not None:
            self.log("off")


async def _session(client: AsyncCoolMuscle, url: str, history: History,
                   timeout: float = 1.0) -> Terminal:
    """On a terminal: prompt_toolkit's prompt, history and colours."""
    from prompt_toolkit import PromptSession
    from prompt_toolkit.patch_stdout import patch_stdout

    term = Terminal(client, url, timeout=timeout)
    client.subscribe(term.on_event)
    prompt: PromptSession[str] = PromptSession(history=history)

    def lost(error: BaseException) -> None:
        term.connection_lost(error)
        if prompt.app.is_running:
            prompt.app.exit(exception=EOFError())       # the prompt ends at once
    client.add_failure_listener(lost)
    show(f"coolmuscle term: {url} (motor ID{client.id}); :help for commands", "info")
    try:
        with patch_stdout(raw=True):
            while term.lost is None:
                try:
                    line = await prompt.prompt_async(f"ID{term.motor}> ")
                except EOFError:
                    break
                except KeyboardInterrupt:
                    continue
                if not await term.handle(line):
                    break
    finally:
        term.close()
    return term


class _InputLines:
    """Lines of standard input, one asked at a time, read by a daemon thread of its own.

    Not ``asyncio.to_thread``: that read blocks until a line or the end of the input
    comes, and closing the event loop (Ctrl-C, SIGTERM) waits for the default
    executor's threads with no bound, so a pipe kept open and silent held the terminal
    open.  A daemon thread is left behind at exit; a line it reads after the session
    stopped is dropped."""

    def __init__(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._asked = threading.Semaphore(0)
        self._waiter: asyncio.Future[str] | None = None
        self._thread: threading.Thread | None = None

    async def readline(self) -> str:
        """The next line with its line end (``""``: the end of the input)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._read, name="coolmuscle-term-input",
                                            daemon=True)
            self._thread.start()
        self._waiter = self._loop.create_future()
        self._asked.release()
        return await self._waiter

    def _read(self) -> None:
        while True:
            self._asked.acquire()
            try:
                line = sys.stdin.readline()
            except (OSError, ValueError):       # closed or unreadable: the end of it
                line = ""
            try:
                self._loop.call_soon_threadsafe(self._hand, line)
            except RuntimeError:                # the loop is closed: the terminal ended
                return
            if not line:
                return

    def _hand(self, line: str) -> None:
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(line)


async def _plain_session(client: AsyncCoolMuscle, url: str, quiet: float) -> Terminal:
    """Input from a file or a pipe: each line sent as it is read; at the end of the input
    (or ``:quit``) wait until the motor has said nothing for ``quiet`` seconds and every
    line's echo or reply came or was said missing."""
    term = Terminal(client, url, show=show_plain, timeout=quiet)
    client.subscribe(term.on_event)
    client.add_failure_listener(term.connection_lost)
    loop = asyncio.get_running_loop()
    term.last_activity = loop.time()
    lines = _InputLines()
    try:
        while term.lost is None:
            line = await lines.readline()
            if not line or not await term.handle(line.rstrip("\r\n")):
                break
        while term.lost is None and ((left := term.last_activity + quiet - loop.time()) > 0
                                     or term.watching):
            await asyncio.sleep(min(max(left, 0.0), 0.05) or 0.01)
    finally:
        term.close()
    return term


def _history(path: Path) -> History:
    from prompt_toolkit.history import FileHistory, InMemoryHistory

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return FileHistory(str(path))
    except OSError:
        return InMemoryHistory()


async def run_term(url: str, *, baudrate: int = 38400, motor: int = 1,
                   timeout: float = 1.0, history: Path | None = None,
                   log: Path | None = None, interactive: bool | None = None,
                   **serial_options: Any) -> None:
    """Run the terminal on ``url`` until ``:quit`` or end of input.  ``interactive``
    (default: standard input is a terminal) chooses the prompt_toolkit session (the
    ``term`` extra) or the plain one."""
    if interactive is None:
        interactive = sys.stdin is not None and sys.stdin.isatty()
    store: History | None = None
    if interactive:
        with needs_extra("term", "the interactive terminal (line editing, history)"):
            store = _history(history or default_history())
    client = await connect_async(url, baudrate=baudrate, motor=motor, timeout=timeout,
                                 **serial_options)
    try:
        recorder: TranscriptRecorder | None = None
        if log is not None:
            said = show if store is not None else show_plain
            recorder = TranscriptRecorder(log, url, on_error=lambda text: said(
                f"log: {text}; the session goes on", "error"))
            client.add_tap(recorder.tap)
        try:
            if store is not None:
                term = await _session(client, url, store, timeout)
            else:
                term = await _plain_session(client, url, timeout)
        finally:
            if recorder is not None:
                recorder.close()
    finally:
        await client.close()
    if term.lost is not None:
        raise SystemExit(1)


def main(url: str, **options: Any) -> None:
    """Blocking entry point for the CLI."""
    asyncio.run(run_term(url, **options))
