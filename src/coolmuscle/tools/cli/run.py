"""What ``coolmuscle run`` does, without the command-line library (docs/scripts.md).

:mod:`.cli` declares the ``run`` command with typer and calls :func:`run_command`;
:mod:`.entry` calls it directly when the arguments are plain (:func:`parse_run_args`),
so that running a script, the floor of every batch run, imports neither typer, rich,
asyncio, matplotlib nor pymodbus unless the run needs them (docs/performance.md).
Anything :func:`parse_run_args` does not recognise goes to typer, which gives the
usual help and error messages.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...device.api import ChainFactory, Device
from ..script.record import LineWriter
from ..script.runner import ScriptError, load_script, run_script
from .usage import UsageError

if TYPE_CHECKING:
    from ...chain.machine import Machine

EXIT_FAILED = 1
FIRMWARES = ("cm2", "rt3", "cm1")

#: Options of ``run`` that take a value -> the key of :func:`run_command`.
_VALUED = {"--until": "until", "--trace": "trace", "--trace-step": "trace_step",
           "--plot": "plot", "--xy": "xy",
           "--motors": "motors", "--firmware": "firmware", "--state": "state",
           "--record": "record", "--machine": "machine", "--junit": "junit"}
_FLAGS = {"--check": "check", "--pace": "pace"}
_PLAIN_NUMBER = re.compile(r"[0-9]+(\.[0-9]+)?\Z")
_PLAIN_INT = re.compile(r"[0-9]{1,2}\Z")


def parse_run_args(argv: list[str]) -> dict[str, Any] | None:
    """The keyword arguments of :func:`run_command` for ``run ARGS``, or ``None`` when
    the arguments are anything but plain (help, an unknown or repeated option, a value
    typer would check or refuse): typer then parses them and says what is wrong."""
    if not argv or argv[0] != "run":
        return None
    out: dict[str, Any] = {}
    files: list[str] = []
    args = argv[1:]
    i = 0
    while i < len(args):
        arg = args[i]
        i += 1
        if not arg.startswith("-"):
            files.append(arg)
            continue
        name, eq, value = arg.partition("=")
        if name in _FLAGS and not eq:
            key = _FLAGS[name]
            if key in out:
                return None
            out[key] = True
            continue
        if name not in _VALUED:
            return None
        if not eq:
            if i >= len(args):
                return None
            value = args[i]
            i += 1
        key = _VALUED[name]
        if key in out or not value or value.startswith("-"):
            return None
        out[key] = value
    if len(files) != 1:
        return None
    if "until" in out:
        if not _PLAIN_NUMBER.match(out["until"]):
            return None
        out["until"] = float(out["until"])
    if "trace_step" in out:
        if not _PLAIN_NUMBER.match(out["trace_step"]):
            return None
        out["trace_step"] = float(out["trace_step"])
    if "motors" in out:
        if not _PLAIN_INT.match(out["motors"]) or not 1 <= int(out["motors"]) <= 15:
            return None
        out["motors"] = int(out["motors"])
    if out.get("firmware", "cm2") not in FIRMWARES:
        return None
    for key in ("trace", "plot", "state", "record", "machine", "junit"):
        if key in out:
            out[key] = Path(out[key])
    out["file"] = Path(files[0])
    return out


def stderr_line(text: str) -> None:
    """One line on stderr, as the typer command prints it (rich, no markup)."""
    from rich.console import Console
    Console(stderr=True, soft_wrap=True, highlight=False).print(text, markup=False)


def setup_logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, stream=sys.stderr,
                        format="coolmuscle: %(message)s")


def xy_pairs(text: str | None, motors: int) -> list[tuple[int, int]] | None:
    """``--xy 1,2`` -> [(1, 2)]; ``none`` -> []; absent -> None (automatic)."""
    if text is None:
        return None
    if text.strip().lower() == "none":
        return []
    parts = text.split(",")
    try:
        x, y = (int(p) for p in parts)
    except ValueError:
        raise UsageError(f"--xy takes two motor IDs as X,Y, not {text!r}") from None
    if not (1 <= x <= motors and 1 <= y <= motors) or x == y:
        raise UsageError(f"--xy {text}: two different IDs of the chain (1..{motors})")
    return [(x, y)]


def make_chain(factory: ChainFactory, motors: int, firmware: str, state: Path | None,
               pace: bool, machine: Path | Machine | None = None) -> Device:
    """The chain of a run or a served simulation (``--state`` made when missing;
    ``machine`` a file, or one read already)."""
    from ...errors import TransportError
    if state is not None:
        try:
            state.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise TransportError(f"cannot use state directory {state}: "
                                 f"{exc.strerror or exc}") from exc
    extra: dict[str, Any] = {}
    if isinstance(machine, Path):
        from ...chain.machine import load_machine
        extra["machine"] = load_machine(machine)
    elif machine is not None:
        extra["machine"] = machine
    return factory(None, motors, firmware=firmware, state_dir=state, pacing=pace, **extra)


def default_chain(*args: Any, **kwargs: Any) -> Device:
    from ...chain.daisy import Chain
    return Chain(*args, **kwargs)


def header_defaults(file: Path, motors: int | None, firmware: str | None,
                    machine: Path | None) -> tuple[int, str, Path | None]:
    """``# coolmuscle: motors=2 firmware=rt3 machine=axis.toml`` in a script gives the
    defaults (``machine`` relative to the script); ``# chain:`` (the golden
    transcripts' header, which ``batch`` reads too) alike.  An option given on the
    command line wins, with a note when it differs from the header (docs/scripts.md)."""
    header: dict[str, str] = {}
    try:
        with file.open(encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith(("# coolmuscle:", "# chain:")):
                    for item in line.split(":", 1)[1].split():
                        key, _, value = item.partition("=")
                        header[key.lower()] = value
    except OSError:
        pass                               # load_script has reported a missing file
    given_motors = header.get("motors")
    if given_motors is not None and not (given_motors.isdigit() and 1 <= int(given_motors) <= 15):
        raise UsageError(f"{file}: '# coolmuscle: motors={given_motors}' is not 1..15")
    given_fw = header.get("firmware")
    if given_fw is not None and given_fw.lower() not in FIRMWARES:
        raise UsageError(f"{file}: '# coolmuscle: firmware={given_fw}' is not cm2, rt3 or cm1")
    for option, given, key in (("--motors", motors, "motors"), ("--firmware", firmware,
                                                                 "firmware")):
        if given is not None and header.get(key) not in (None, str(given)):
            stderr_line(f"coolmuscle: note: {option} {given} overrides the script's "
                        f"{key}={header[key]}")
    if motors is None:
        motors = int(given_motors) if given_motors else 1
    if firmware is None:
        firmware = given_fw.lower() if given_fw else "cm2"
    if machine is None and header.get("machine"):
        machine = file.parent / header["machine"]
    return motors, firmware, machine


#: The longest virtual time a run goes on to (``--until``): 30 years of a machine.
MAX_UNTIL_S = 1e9
#: The trace grid (``--trace-step``): from 10 µs (a row every 10 µs is finer than any
#: signal the motor reports) to a day.
TRACE_STEP_RANGE = (1e-5, 86400.0)


def check_run_times(until: float | None, trace_step: float = 0.001) -> None:
    """``--until`` and ``--trace-step`` as a usage error (exit 2) when they cannot be
    run: not a finite number, negative, a step too fine to end (a 1e-12 s step never
    advanced) or a time beyond what the kernel's nanoseconds hold."""
    import math
    if until is not None and not (math.isfinite(until) and 0 <= until <= MAX_UNTIL_S):
        raise UsageError(f"--until must be 0..{MAX_UNTIL_S:g} seconds, not {until!r}")
    lo, hi = TRACE_STEP_RANGE
    if not (math.isfinite(trace_step) and lo <= trace_step <= hi):
        raise UsageError(f"--trace-step must be {lo:g}..{hi:g} seconds, not {trace_step!r}")


def run_command(file: Path, until: float | None = None, trace: Path | None = None,
                trace_step: float = 0.001, plot: Path | None = None, xy: str | None = None,
                motors: int | None = None, firmware: str | None = None,
                state: Path | None = None, check: bool = False, pace: bool = False,
                record: Path | None = None, machine: Path | None = None,
                chain_factory: ChainFactory = default_chain,
                junit: Path | None = None) -> int:
    """Run a script in fast virtual time, print every line, check expectations.

    Returns the exit status (0, or :data:`EXIT_FAILED` for a failed run); bad usage
    and bad scripts raise (:class:`UsageError`, :class:`ScriptError`).  ``junit``:
    also write the verdict as JUnit XML (:func:`write_run_junit`)."""
    setup_logging(False)
    if junit is not None:
        from ..ci.junit import path_problem
        problem = path_problem(junit)
        if problem is not None:
            raise UsageError(f"cannot write --junit {junit}: {problem}")
    started = time.perf_counter()
    script = load_script(file)
    motors, firmware, machine = header_defaults(file, motors, firmware, machine)
    if check and not script.expectations:
        raise UsageError(f"{file}: --check needs a script with '<<' expectations")
    check_run_times(until, trace_step)
    pairs = xy_pairs(xy, motors)
    if trace is not None:
        from ..trace.recorder import TraceFormatError, check_trace_path
        try:
            check_trace_path(trace)
        except TraceFormatError as exc:
            raise UsageError(str(exc)) from None
    if plot is not None:
        from ..trace.plot import PlotFormatError, check_plot_path
        try:
            check_plot_path(plot)
        except PlotFormatError as exc:
            raise UsageError(str(exc)) from None
    chain = make_chain(chain_factory, motors, firmware, state.expanduser() if state else None,
                       pace, machine)
    try:
        if plot is not None:
            from ..trace.recorder import NoTraceRecorderError
            from ..trace.recorder import record as record_trace
            try:
                record_trace(chain)
            except NoTraceRecorderError as exc:
                raise ScriptError(f"cannot plot to {plot}: {exc}") from None

        show = LineWriter(sys.stdout.write)       # compiled: a call per line received

        def warn(text: str) -> None:
            stderr_line(f"coolmuscle: warning: {text}")

        from ..trace.recorder import DEFAULT_WARN_BYTES
        # the transcript goes to stdout and --record's file as it comes and nothing of
        # it is kept: a run of any length in bounded memory
        golden = _Recording(record) if record is not None else None
        try:
            result = run_script(script, chain, until=until, trace=trace,
                                on_entry=None if check else show, trace_step=trace_step,
                                trace_warn_bytes=DEFAULT_WARN_BYTES, on_warning=warn,
                                keep=False, record=golden.write if golden else None)
        except BaseException:
            if golden is not None:
                golden.discard()              # a run that did not end leaves the file be
            raise
        if golden is not None:
            golden.close()
        sys.stdout.flush()
        if plot is not None:
            from ..trace.plot import plot as plot_chain
            title = f"{file.name} (virtual time)"     # the script's name, not a generic one
            if pairs is None:
                plot_chain(chain, plot, title=title)
            else:
                plot_chain(chain, plot, title=title, xy=pairs)
    finally:
        chain.close()
    if junit is not None:
        write_run_junit(junit, file, result, time.perf_counter() - started)
    if not result.ok:
        stderr_line(f"coolmuscle: {result.summary()}")
        return EXIT_FAILED
    if check:
        sys.stdout.write(f"coolmuscle: {result.summary()}\n")
    elif script.expectations:
        stderr_line(f"coolmuscle: {result.summary()}")
    return 0


class _Recording:
    """``--record``'s file, written as the run goes into a temporary file beside it that
    replaces it when the run has ended (a run stopped by an error or Ctrl-C leaves the
    file as it was); a file that cannot be written is a :class:`ScriptError` (exit 2)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if not path.name or path.is_dir():      # checked before the run, not after it
            raise ScriptError(f"cannot write {path}: it is a directory (--record names "
                              "a file)")
        self.part = path.with_name(f".{path.name}.part")
        try:
            self.file = self.part.open("w", encoding="utf-8")
        except OSError as exc:
            raise self.failed(exc) from exc

    def failed(self, exc: OSError) -> ScriptError:
        return ScriptError(f"cannot write {self.path}: {exc.strerror or exc}")

    def write(self, text: str) -> None:
        try:
            self.file.write(text)
        except OSError as exc:
            raise self.failed(exc) from exc

    def close(self) -> None:
        """The run has ended: the file in place."""
        try:
            self.file.close()
            os.replace(self.part, self.path)
        except OSError as exc:
            self.discard()
            raise self.failed(exc) from exc

    def discard(self) -> None:
        """The run did not end: the temporary file removed, the file left as it was."""
        try:
            self.file.close()
        except OSError:
            pass
        self.part.unlink(missing_ok=True)


def write_run_junit(path: Path, file: Path, result: Any, wall_s: float) -> Path:
    """``run --junit``: one case for the script; a failed expectation, extra output or an
    ``@until`` timeout is a ``<failure>``, a model error an ``<error>``, each naming the
    script and the line of the expectation (docs/scripts.md)."""
    from ..ci.junit import Case, Suite, write_junit
    failure = result.failure
    if failure is None:
        case = Case(file.name, "coolmuscle.run", wall_s, file=str(file),
                    output=result.summary())
    else:
        message = re.sub(r"^line \d+: ", "", failure.message)
        where = f"{file}:{failure.line_no}" if failure.line_no else str(file)
        case = Case(file.name, "coolmuscle.run", wall_s,
                    "error" if failure.kind == "error" else "failure",
                    f"{where}: {message}", failure.kind, file=str(file),
                    line=failure.line_no)
    return write_junit(path, [Suite("coolmuscle.run", [case])])
