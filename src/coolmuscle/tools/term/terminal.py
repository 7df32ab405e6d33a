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

Line editing and history come from prompt_toolkit (history kept in
``$XDG_STATE_HOME/coolmuscle/term_history``).  Commands start with ``:``:

``:send FILE.cml``   upload a file with a progress bar and verify its banks (``upload``)
``:save [ID]``       ``$`` and wait for ``saved.n`` (default: the terminal's motor)
``:log FILE``        record the session as a golden transcript (docs/scripts.md);
                     ``:log off`` stops
``:motor ID``        the motor ID ``:save`` and ``:send`` use
``:help``, ``:quit`` (or Ctrl-D)
"""

from __future__ import annotations

import asyncio
import os
import re
import shlex
from collections.abc import Callable
from pathlib import Path
from typing import Any

from prompt_toolkit import PromptSession, print_formatted_text
from prompt_toolkit.formatted_text import FormattedText
from prompt_toolkit.history import FileHistory, History, InMemoryHistory
from prompt_toolkit.patch_stdout import patch_stdout
from prompt_toolkit.shortcuts import ProgressBar

from ...client import AsyncCoolMuscle, connect_async
from ...client.program import load_program
from ...client.protocol import MotorEvent
from ...errors import CoolMuscleError
from ...motor.status import Ux
from ..script.transcript import TranscriptRecorder

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
    """``$XDG_STATE_HOME/coolmuscle/term_history`` (``~/.local/state/...``)."""
    base = os.environ.get("XDG_STATE_HOME") or os.path.expanduser("~/.local/state")
    return Path(base) / "coolmuscle" / "term_history"


def show(text: str, style: str) -> None:
    """Print one line in colour above the prompt."""
    print_formatted_text(FormattedText([(STYLES.get(style, ""), text)]))


def _log_failed(text: str) -> None:
    """The log's file failed (a full disk): said once; the session goes on."""
    show(f"log: {text}; the session goes on", "error")


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

    def __init__(self, client: AsyncCoolMuscle, url: str, timeout: float = 1.0) -> None:
        self.client = client
        self.url = url
        self.motor = client.id
        self.timeout = timeout
        self.recorder: TranscriptRecorder | None = None
        self._untap: Callable[[], None] | None = None
        self.lines_in = 0             # line ends received: what came since a line was typed
        client.add_tap(self._count)

    def _count(self, direction: str, data: bytes) -> None:
        if direction == "<":
            self.lines_in += data.count(b"\r")       # K70: CR or CR LF (ch. 3)

    def on_event(self, event: MotorEvent) -> None:
        text, style = describe(event)
        show(text, style)

    async def handle(self, line: str) -> bool:
        """One input line; ``False`` ends the session."""
        if line.startswith(":"):
            return await self.command(line[1:].strip())
        self.client.write_line(line)
        self._watch(line)
        return True

    def _watch(self, line: str) -> None:
        """Say so when what a line brings does not come within the timeout: its echo
        (once the motor is known to echo, ch. 3 K23 8) and, for a query, its reply
        (a dropped reply, a dead line: docs/wire-faults.md)."""
        echo = self.client.echo is True
        expected = int(echo) + int(bool(_ASKS.match(line)))
        if expected:
            asyncio.get_running_loop().call_later(self.timeout, self._check, line,
                                                  self.lines_in, expected, echo)

    def _check(self, line: str, start: int, expected: int, echo: bool) -> None:
        got = self.lines_in - start
        if got >= expected:
            return
        if got == 0 and echo:
            show(f"no answer to {line!r} within {self.timeout:g} s, not even its echo: "
                 "is the line down?", "error")
        else:
            show(f"no reply to {line!r} within {self.timeout:g} s", "error")

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
                show(f"saved.{motor}", "message")
            elif name == "log" and len(args) == 1:
                self.log(args[0])
            elif name == "motor" and len(args) == 1 and args[0].isdigit():
                self.motor = self.client.motor(int(args[0])).id    # 1..15 (1.1)
                show(f"motor ID{self.motor}", "info")
            else:
                show(HELP, "info")
        except (CoolMuscleError, OSError, ValueError) as exc:
            show(f"{name}: {exc}", "error")
        return True

    def log(self, target: str) -> None:
        if self.recorder is not None and self._untap is not None:
            self._untap()
            self.recorder.close()
            show(f"log written: {self.recorder.path}", "info")
            self.recorder = None
        if target.lower() != "off":
            self.recorder = TranscriptRecorder(target, self.url, on_error=_log_failed)
            self._untap = self.client.add_tap(self.recorder.tap)
            show(f"logging to {target} (:log off to stop)", "info")

    async def send_file(self, path: Path) -> None:
        program = load_program(path)
        bad = [line for line in program.source_lines if line.error is not None]
        if bad:
            raise CoolMuscleError(f"{path}: {len(bad)} syntax error(s) (coolmuscle check "
                                  f"{path}); nothing sent")
        total = program.send_count()
        with ProgressBar(title=f"sending {path.name}") as bar:
            counter = bar(range(total), total=total, label="lines")

            def progress(done: int, _total: int) -> None:
                while counter.items_completed < done:
                    counter.item_completed()
            result = await self.client.motor(self.motor).upload(program, check=False,
                                                                progress=progress)
        for line in result.report():
            show(line, "error")
        verdict = "verified" if result.ok else "FAILED"
        show(f"sent {result.sent} line(s) of {path.name}; banks {', '.join(result.banks) or '-'}"
             f" {verdict}", "message" if result.ok else "error")

    def close(self) -> None:
        if self.recorder is not None:
            self.log("off")


async def _session(client: AsyncCoolMuscle, url: str, history: History,
                   timeout: float = 1.0) -> None:
    term = Terminal(client, url, timeout)
    client.subscribe(term.on_event)
    prompt: PromptSession[str] = PromptSession(history=history)
    show(f"coolmuscle term: {url} (motor ID{client.id}); :help for commands", "info")
    try:
        with patch_stdout(raw=True):
            while True:
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


async def run_term(url: str, *, baudrate: int = 38400, motor: int = 1,
                   timeout: float = 1.0, history: Path | None = None,
                   log: Path | None = None, **serial_options: Any) -> None:
    """Run the terminal on ``url`` until ``:quit`` or end of input."""
    path = history or default_history()
    store: History
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        store = FileHistory(str(path))
    except OSError:
        store = InMemoryHistory()
    client = await connect_async(url, baudrate=baudrate, motor=motor, timeout=timeout,
                                 **serial_options)
    try:
        recorder = (TranscriptRecorder(log, url, on_error=_log_failed) if log is not None
                    else None)
        if recorder is not None:
            client.add_tap(recorder.tap)
        try:
            await _session(client, url, store, timeout)
        finally:
            if recorder is not None:
                recorder.close()
    finally:
        await client.close()


def main(url: str, **options: Any) -> None:
    """Blocking entry point for the CLI."""
    asyncio.run(run_term(url, **options))
