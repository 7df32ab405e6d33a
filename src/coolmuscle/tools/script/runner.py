"""The ``coolmuscle run`` script / golden transcript format and its runner (docs/scripts.md).

This module owns:

* parsing scripts: plain lines (sent as typed + CR, blank lines too), ``# `` comments,
  directives ``@wait SECONDS``, ``@until REGEX [TIMEOUT]``, ``@send BYTES``,
  ``@input [ID.]N on|off``, ``@analog [ID] COUNTS`` and expectations ``<< BYTES``
  (escapes ``\\r \\n \\t \\0 \\e \\\\ \\xNN``);
* running a script against a chain in fast (unpaced, deterministic) virtual time,
  producing a timestamped transcript of every line sent and received, and of what each
  wire fault did (``#`` entries, docs/wire-faults.md);
* checking the received byte stream against the expectations, in order, byte for
  byte, and reporting the first mismatch with context;
* recording a run back as a golden transcript (:meth:`RunResult.to_script`).

The transcript's entries, their text and the recorder of the bytes received are
:mod:`.record` (compiled: every line a motor sends goes through it).

The runner talks to the chain only through the device API
(:class:`coolmuscle.device.api.Device`): ``kernel`` and ``host_line``, ``set_input`` /
``set_analog`` for the input directives, and its trace feed for ``--trace``.
"""

from __future__ import annotations

import math
import os
import re
import string
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from ...device.api import Device
from ...errors import CoolMuscleError
from ...sim.kernel import seconds, to_seconds
from .golden import GoldenWriter
from .golden import split_lines as split_lines
from .record import Direction as Direction
from .record import Recorder
from .record import TranscriptEntry as TranscriptEntry
from .record import escape as escape

if TYPE_CHECKING:
    from ..trace.recorder import TraceFile

#: Default timeout of ``@until`` (virtual seconds).
DEFAULT_UNTIL_TIMEOUT = 10.0

StepKind = Literal["send", "raw", "wait", "until", "expect", "comment", "input", "analog"]

_ESCAPES = {"r": 13, "n": 10, "t": 9, "0": 0, "e": 27, "\\": 92}
_DIRECTIVE = re.compile(r"@([A-Za-z]\w*)(?:[ \t](.*))?$", re.S)
_NUMBER = re.compile(r"[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?$")


class ScriptError(CoolMuscleError, ValueError):
    """A script that cannot be parsed or run (bad directive, escape, trace option)."""

    def __init__(self, message: str, line_no: int | None = None) -> None:
        self.line_no = line_no
        super().__init__(f"line {line_no}: {message}" if line_no else message)


# -- escapes ------------------------------------------------------------
#: A backslash and the character after it (or nothing), or ``\\xNN``.
_ESCAPE_SEQUENCE = re.compile(r"\\(?:x[0-9A-Fa-f]{2}|.?)", re.S)
#: Every good escape -> its byte (as a latin-1 character); anything else is an error.
_UNESCAPED = {**{"\\" + name: chr(code) for name, code in _ESCAPES.items()},
              **{f"\\x{hi}{lo}": chr(int(hi + lo, 16))
                 for hi in string.hexdigits for lo in string.hexdigits}}
_NOT_A_BYTE = re.compile(r"[^\x00-\xff]")


def unescape(text: str) -> bytes:
    """``"Ux.1=8\\\\r\\\\n"`` -> ``b"Ux.1=8\\r\\n"``; raises ``ValueError`` on a bad escape
    or a character above U+00FF (the first one in the text)."""
    bad_char = _NOT_A_BYTE.search(text)

    def byte(match: re.Match[str]) -> str:
        char = _UNESCAPED.get(match.group())
        if char is not None:
            return char
        if bad_char is not None and bad_char.start() < match.start():
            raise ValueError(f"character {bad_char.group()!r} is not a byte (use \\xNN)")
        raise ValueError(f"bad escape {text[match.start():match.start() + 4]!r} "
                         "(use \\r \\n \\t \\0 \\e \\\\ \\xNN)")
    out = _ESCAPE_SEQUENCE.sub(byte, text) if "\\" in text else text
    if bad_char is not None:
        raise ValueError(f"character {bad_char.group()!r} is not a byte (use \\xNN)")
    return out.encode("latin-1")


# -- parsing ------------------------------------------------------------
@dataclass(frozen=True)
class Step:
    """One script line: what to do and where it came from."""

    line_no: int
    kind: StepKind
    source: str
    data: bytes = b""
    seconds: float = 0.0
    pattern: re.Pattern[str] | None = None
    args: tuple[int, ...] = ()


@dataclass(frozen=True)
class Script:
    """A parsed script; ``lines`` keeps comments (for recording), ``steps`` does not."""

    lines: tuple[Step, ...]

    @property
    def steps(self) -> tuple[Step, ...]:
        return tuple(s for s in self.lines if s.kind != "comment")

    @property
    def expectations(self) -> int:
        return sum(1 for s in self.lines if s.kind == "expect")


#: The longest wait a script line may ask for (as ``run --until``): 30 years.
MAX_SECONDS = 1e9


def _seconds_arg(text: str, what: str, line_no: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ScriptError(f"{what}: {text!r} is not a number of seconds", line_no) from None
    if not math.isfinite(value) or not 0 <= value <= MAX_SECONDS:
        raise ScriptError(f"{what}: seconds must be 0..{MAX_SECONDS:g}, not {text}", line_no)
    return value


_INPUT = re.compile(r"^(?:(\d+)\.)?(\d+)\s+(on|off|1|0)$", re.IGNORECASE)
_ANALOG = re.compile(r"^(?:(\d+)\s+)?(\d+)$")


def _input_args(arg: str, line_no: int) -> tuple[int, ...]:
    """``@input [ID.]N on|off``: drive the electrical level of input N of motor ID."""
    match = _INPUT.match(arg.strip())
    if not match:
        raise ScriptError("@input needs [ID.]N on|off, e.g. '@input 1.3 on'", line_no)
    motor = _motor_arg(match.group(1), "@input", line_no)
    number = int(match.group(2))
    if number < 1:
        raise ScriptError(f"@input {number}: inputs are numbered from 1 (I1..I6 on CM2, "
                          "I1..I4 on RT3 and CM1)", line_no)
    return motor, number, int(match.group(3).lower() in ("on", "1"))


def _analog_args(arg: str, line_no: int) -> tuple[int, ...]:
    """``@analog [ID] COUNTS``: set the analog input (0..1023, 6.6 ?74)."""
    match = _ANALOG.match(arg.strip())
    if not match:
        raise ScriptError("@analog needs [ID] COUNTS, e.g. '@analog 1 512'", line_no)
    counts = int(match.group(2))
    if counts > 1023:
        raise ScriptError(f"@analog {counts}: the analog input is 0..1023 counts (6.6 ?74)",
                          line_no)
    return _motor_arg(match.group(1), "@analog", line_no), counts


def _motor_arg(text: str | None, directive: str, line_no: int) -> int:
    motor = int(text or 1)
    if not 1 <= motor <= 15:
        raise ScriptError(f"{directive}: motor ID {motor} is not 1..15 (1.1)", line_no)
    return motor


def check_steps(script: Script, chain: Device) -> None:
    """The ``@input`` / ``@analog`` lines against the chain they will run on: a motor ID
    it has, an input its firmware has.  :class:`ScriptError` (bad usage, exit 2) naming
    the line and the allowed range, before anything runs."""
    steps = [step for step in script.steps if step.kind in ("input", "analog")]
    if not steps:
        return
    ids = chain.motor_ids
    inputs = chain.firmware.inputs
    for step in steps:
        motor = step.args[0]
        if motor not in ids:
            raise ScriptError(f"@{step.kind}: no motor ID{motor} on this chain (IDs "
                              f"{ids[0]}..{ids[-1]}; --motors sets how many)", step.line_no)
        if step.kind == "input" and step.args[1] > inputs:
            raise ScriptError(f"@input {step.args[1]}: the motor has inputs 1..{inputs} "
                              f"({chain.firmware.name})", step.line_no)


def _parse_directive(name: str, arg: str, line_no: int, source: str) -> Step:
    if name == "wait":
        return Step(line_no, "wait", source, seconds=_seconds_arg(arg.strip(), "@wait", line_no))
    if name == "until":
        arg = arg.strip()
        if not arg:
            raise ScriptError("@until needs a regular expression", line_no)
        timeout = DEFAULT_UNTIL_TIMEOUT
        head, sep, tail = arg.rpartition(" ")
        if sep and head.strip() and _NUMBER.match(tail):
            arg, timeout = head.rstrip(), _seconds_arg(tail, "@until timeout", line_no)
        try:
            pattern = re.compile(arg)
        except re.error as exc:
            raise ScriptError(f"@until: bad regular expression {arg!r}: {exc}", line_no) from None
        return Step(line_no, "until", source, seconds=timeout, pattern=pattern)
    if name == "send":
        try:
            data = unescape(arg)
        except ValueError as exc:
            raise ScriptError(f"@send: {exc}", line_no) from None
        if not data:
            raise ScriptError("@send needs bytes to send", line_no)
        return Step(line_no, "raw", source, data=data)
    if name == "input":
        return Step(line_no, "input", source, args=_input_args(arg, line_no))
    if name == "analog":
        return Step(line_no, "analog", source, args=_analog_args(arg, line_no))
    raise ScriptError(f"unknown directive @{name} (known: @wait, @until, @send, @input, "
                      "@analog; CML's "
                      "interpolation command is @ followed by a digit or a dot)", line_no)


def parse_line(source: str, line_no: int) -> Step:
    """Classify one script line (without its file line ending)."""
    if source == "#" or source.startswith("# "):
        return Step(line_no, "comment", source)
    if source.startswith("<<"):
        if not source.startswith("<< ") or len(source) == 3:
            raise ScriptError("an expectation is '<< ' followed by the bytes expected", line_no)
        try:
            data = unescape(source[3:])
        except ValueError as exc:
            raise ScriptError(f"expectation: {exc}", line_no) from None
        return Step(line_no, "expect", source, data=data)
    if m := _DIRECTIVE.match(source):
        return _parse_directive(m.group(1), m.group(2) or "", line_no, source)
    try:
        data = source.encode("latin-1") + b"\r"
    except UnicodeEncodeError:
        raise ScriptError(f"line {source!r} has characters that are not bytes", line_no) from None
    return Step(line_no, "send", source, data=data)


def parse_script(text: str) -> Script:
    """Parse script text; raises :class:`ScriptError` with the line number."""
    rows = text.split("\n")
    if rows and rows[-1] == "":
        rows.pop()  # the file's final newline ends the last line, it is not a blank line
    return Script(tuple(parse_line(row.removesuffix("\r"), n) for n, row in enumerate(rows, 1)))


def load_script(source: str | os.PathLike[str]) -> Script:
    """A path (``Path``, or a one-line ``str`` naming an existing file) or script text.

    A one-line ``str`` ending in ``.cml`` that names no file is a :class:`ScriptError`
    (it is a mistyped path, not a line of CML)."""
    if isinstance(source, os.PathLike) or ("\n" not in source and os.path.isfile(source)):
        path = Path(source)
        if path.is_char_device() or path.is_block_device():   # /dev/zero never ends
            raise ScriptError(f"cannot read script {path}: a device, not a file")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ScriptError(f"cannot read script {path}: {exc}") from exc
        return parse_script(text)
    if "\n" not in source and source.strip().lower().endswith(".cml"):
        # a file name, not CML: sending it to the motor would "succeed" silently
        raise ScriptError(f"no such script file: {source} (a one-line str naming a "
                          ".cml file must name an existing file; script text is sent)")
    return parse_script(source)


# -- results ------------------------------------------------------------
@dataclass(frozen=True)
class Failure:
    """Why a run failed: ``mismatch``, ``unexpected`` (extra output), ``timeout``, ``error``."""

    kind: Literal["mismatch", "unexpected", "timeout", "error"]
    message: str
    line_no: int | None
    time: int


@dataclass
class RunResult:
    """The outcome of :func:`run_script`."""

    script: Script
    transcript: list[TranscriptEntry]
    received: bytes
    failure: Failure | None
    expectations: int
    matched: int
    end_time: int
    marks: list[tuple[int, int]] = field(default_factory=list)  # (step line_no, received offset)
    tail_seconds: float = 0.0
    exception: BaseException | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None

    def format(self) -> str:
        """The transcript, one ``time dir bytes`` line per entry."""
        return "\n".join(entry.format() for entry in self.transcript)

    def summary(self) -> str:
        if self.failure is not None:
            return f"FAIL {self.failure.message}"
        checked = (f"{self.matched} expectation(s) matched" if self.expectations
                   else "no expectations")
        return f"ok: {checked}, ended at {to_seconds(self.end_time):.6f} s"

    def to_script(self) -> str:
        """The script with ``<<`` lines of what was actually received (a golden
        transcript): what ``run_script(..., record=...)`` writes as the run goes."""
        out: list[str] = []
        writer = GoldenWriter(self.script, out.append)
        start = 0
        for line_no, end in self.marks:
            writer.step(line_no)
            writer.received(self.received[start:end])
            writer.mark()
            start = end
        if start < len(self.received) or self.tail_seconds > 0:
            writer.tail(self.tail_seconds)
            writer.received(self.received[start:])
        writer.finish()
        return "".join(out) or "\n"


# -- running ------------------------------------------------------------
class _Checker:
    """Matches expectations against the received stream, in order, byte for byte."""

    def __init__(self, stream: bytearray) -> None:
        self.stream = stream
        self.pos = 0
        self.matched = 0

    def expect(self, step: Step, now: int) -> Failure | None:
        want = step.data
        got = bytes(self.stream[self.pos:self.pos + len(want)])
        if got == want:
            self.pos += len(want)
            self.matched += 1
            return None
        diff = next((i for i, (a, b) in enumerate(zip(want, got)) if a != b), len(got))
        shown = bytes(self.stream[self.pos:self.pos + max(len(want), diff + 1) + 16])
        before = bytes(self.stream[max(0, self.pos - 32):self.pos])
        sent = f'"{escape(shown)}"' if shown else "nothing (yet)"
        return Failure("mismatch",
                       f'line {step.line_no}: expected "{escape(want)}" but the motor sent '
                       f'{sent} (stream byte {self.pos + diff}, differs at offset {diff}, '
                       f'{to_seconds(now):.6f} s); before it: "{escape(before)}"',
                       step.line_no, now)

    def leftover(self, received: int, now: int) -> Failure | None:
        """The bytes after the last expectation (``received`` in all; the stream holds
        at least the first :data:`_SHOWN` of them)."""
        extra = received - self.pos
        if not extra:
            return None
        shown = bytes(self.stream[self.pos:self.pos + _SHOWN])
        return Failure("unexpected",
                       f'after the last expectation the motor sent {extra} more byte(s): '
                       f'"{escape(shown)}"{"..." if extra > _SHOWN else ""}', None, now)


#: The bytes after the last expectation that a failure shows.
_SHOWN = 80


class _Untils:
    """The ``@until`` steps' patterns, matched against each complete line as it arrives.

    Each ``@until`` looks at the lines received since the previous one matched (or
    since the start), in order, so which line meets which pattern depends only on the
    order of the lines: the first line that matches the first pattern meets it, the
    first line after it that matches the second pattern meets that, and so on.  Done
    as the lines come, no line is kept."""

    def __init__(self, steps: tuple[Step, ...]) -> None:
        self.patterns = [step.pattern for step in steps
                         if step.kind == "until" and step.pattern is not None]
        self.met = 0          # patterns met so far

    def line(self, text: str) -> None:
        if self.met < len(self.patterns) and self.patterns[self.met].search(text):
            self.met += 1


def _start_trace(chain: Device, trace: str | os.PathLike[str], step: float,
                 warn_bytes: int | None, on_warning: Callable[[str], None] | None
                 ) -> TraceFile:
    from ..trace.recorder import TraceFormatError
    from ..trace.recorder import trace as start_trace
    try:
        return start_trace(chain, Path(trace), step, warn_bytes=warn_bytes,
                           on_warning=on_warning)
    except OSError as exc:
        raise ScriptError(f"cannot write trace {os.fspath(trace)}: "
                          f"{exc.strerror or exc}") from None
    except TraceFormatError as exc:
        raise ScriptError(f"cannot write trace {os.fspath(trace)}: {exc}") from None


def run_script(source: str | os.PathLike[str] | Script, chain: Device, *,
               until: float | None = None, trace: str | os.PathLike[str] | None = None,
               on_entry: Callable[[TranscriptEntry], None] | None = None,
               trace_step: float = 0.001, trace_warn_bytes: int | None = None,
               on_warning: Callable[[str], None] | None = None,
               keep: bool = True, record: Callable[[str], object] | None = None) -> RunResult:
    """Run a script against ``chain`` in fast virtual time and check its expectations.

    ``source`` is a :class:`Script`, a path or script text (:func:`load_script`).
    ``until``: after the last line, keep running virtual time up to ``until`` seconds
    (absolute).  ``trace``: CSV (or Parquet) path the trace streams to, one grid row
    every ``trace_step`` seconds plus every change (``on_warning`` is told once the
    file passes ``trace_warn_bytes``; an interrupt leaves the rows so far).  ``on_entry`` is
    called with every transcript entry as it happens (for live display; if it raises,
    the run goes on silently and the exception is re-raised at the end).  The run stops
    at the first failure; the result says which.

    ``keep`` (the default) keeps the whole transcript and every byte received in the
    result.  Without it the run keeps neither (the result's ``transcript`` and
    ``received`` are empty; ``on_entry`` is where the transcript goes) and checks as
    the bytes come: ``@until`` looks at each line as it arrives and the received bytes
    are kept only up to the last expectation, so a run of any length stays in bounded
    memory (``coolmuscle run``).  ``record`` is given the run written back as a golden
    transcript (what :meth:`RunResult.to_script` gives) a line at a time, as it goes
    (``coolmuscle run --record``); when it raises, the run goes on and the exception
    is raised at the end.
    """
    script = source if isinstance(source, Script) else load_script(source)
    check_steps(script, chain)
    kernel = chain.kernel
    host_line = chain.host_line
    steps = script.steps
    untils = _Untils(steps)
    recorder = Recorder(kernel, on_entry, keep=keep, on_line=untils.line if untils.patterns
                        else None)
    checker = _Checker(recorder.stream)
    # without keep: the stream is kept up to the last expectation, then only what a
    # failure would show of the bytes after it
    last_expect = max((i for i, step in enumerate(steps) if step.kind == "expect"), default=-1)
    if not keep and last_expect < 0:
        recorder.stream_limit = 0
    tracer = (_start_trace(chain, trace, trace_step, trace_warn_bytes, on_warning)
              if trace is not None else None)
    remove = host_line.add_listener(recorder.on_bytes)
    golden = GoldenWriter(script, record) if record is not None else None
    unrecord = host_line.add_listener(golden.received) if golden is not None else None
    unsubscribe = chain.subscribe(lambda event: recorder.note(event.text)
                                  if event.kind == "wire" else None)
    failure: Failure | None = None
    exception: BaseException | None = None
    marks: list[tuple[int, int]] = []
    tail = 0.0
    waited_for = 0        # @until steps run so far

    try:
        for index, step in enumerate(steps):
            if golden is not None and step.kind != "expect":
                golden.step(step.line_no)
            try:
                if step.kind in ("send", "raw"):
                    recorder.sent(TranscriptEntry(kernel.now, ">", step.data, step.line_no))
                    host_line.feed(step.data)
                elif step.kind == "wait":
                    kernel.advance(seconds(step.seconds))
                elif step.kind == "input":
                    chain.set_input(step.args[0], step.args[1], bool(step.args[2]))
                elif step.kind == "analog":
                    chain.set_analog(step.args[0], step.args[1])
                elif step.kind == "until":
                    assert step.pattern is not None
                    waited_for += 1
                    wanted = waited_for
                    # the closure runs before the loop goes on (B023)
                    waited = kernel.run_until(lambda: untils.met >= wanted,  # noqa: B023
                                              seconds(step.seconds))
                    if not waited:
                        failure = Failure("timeout", f"line {step.line_no}: @until "
                                          f"{step.pattern.pattern!r} timed out after "
                                          f"{step.seconds:g} s (virtual time "
                                          f"{kernel.now_s:.6f} s)", step.line_no, kernel.now)
                    elif untils.met == len(untils.patterns):
                        recorder.on_line = None      # no @until left: lines are not looked at
                elif step.kind == "expect":
                    failure = checker.expect(step, kernel.now)
                    if not keep and index == last_expect:
                        recorder.stream_limit = checker.pos + _SHOWN
            except Exception as exc:  # a model bug: report it, never crash the runner
                exception = exc
                failure = Failure("error", f"line {step.line_no}: the motor model raised "
                                  f"{type(exc).__name__}: {exc}", step.line_no, kernel.now)
            if step.kind != "expect":
                marks.append((step.line_no, recorder.received))
                if golden is not None:
                    golden.mark()
            if failure is not None:
                break
        if failure is None and until is not None:
            target = seconds(until)
            if target > kernel.now:
                tail = to_seconds(target - kernel.now)
                if golden is not None:
                    golden.tail(tail)
                try:
                    kernel.run(until=target)
                except Exception as exc:
                    exception = exc
                    failure = Failure("error", f"the motor model raised {type(exc).__name__}: "
                                      f"{exc}", None, kernel.now)
        if failure is None and script.expectations:
            failure = checker.leftover(recorder.received, kernel.now)
    finally:
        remove()
        unsubscribe()
        recorder.finish()
        if golden is not None and unrecord is not None:
            unrecord()
            golden.finish()
        raised = sys.exc_info()[0]
        interrupted = raised is not None and not issubclass(
            raised, Exception)                # Ctrl-C, a stop signal: stop at once
        close = getattr(tracer, "abort" if interrupted else "close", None)
        if callable(close):
            close()
    if recorder.display_error is not None:
        raise recorder.display_error
    if golden is not None and golden.error is not None:
        raise golden.error
    return RunResult(script=script, transcript=recorder.entries,
                     received=bytes(recorder.stream) if keep else b"",
                     failure=failure, expectations=script.expectations, matched=checker.matched,
                     end_time=kernel.now, marks=marks, tail_seconds=tail, exception=exception)
