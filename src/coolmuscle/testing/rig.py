"""``cm_chain``: a chain in virtual time for one test, recorded, with its assertions.

:class:`ChainRig` holds a :class:`~coolmuscle.chain.daisy.Chain` (built by
:func:`build_chain`) and everything a test of a bank set or a host program needs:

* drive it: :meth:`~ChainRig.send` a CML line through the device API, :meth:`~ChainRig.run`
  virtual seconds, :meth:`~ChainRig.wait_for` something the motor says, set inputs and
  the analog input, :meth:`~ChainRig.load` a ``.cml`` file (its banks stored and checked,
  :mod:`.banks`), or hand a host program a pyserial port on the chain
  (:meth:`~ChainRig.port`: fast virtual time, the same chain, so the assertions see
  what the program did);
* read it: the trace recorder from the first instant, every bank line that ran (through
  :meth:`~coolmuscle.chain.daisy.Chain.observe_bank_lines`), the driver temperature after
  each kernel event, :meth:`~ChainRig.reply` bytes;
* check it: :meth:`~ChainRig.expect` (:class:`.expect.MotorExpect`) and
  :meth:`~ChainRig.expect_reply`;
* on :meth:`~ChainRig.close`: the lines that ran go to the run's bank coverage
  (:mod:`.coverage`) and the chain is closed.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..chain.daisy import Chain
from ..chain.machine import Machine
from ..device.banklines import BankLine
from ..sim.kernel import NS_PER_MS, NS_PER_S, Kernel, seconds
from .banks import BankFile, BankKey, BankMap, bank_label, load_bank_file

if TYPE_CHECKING:
    from ..tools.trace.recorder import TraceRecorder
    from .coverage import BankCoverage
    from .expect import MotorExpect

__all__ = ["ChainRig", "build_chain", "escape"]

#: Driver temperature readings are at most this far apart (°C changes in seconds).
TEMPERATURE_EVERY_NS = 10 * NS_PER_MS


def build_chain(motors: int = 1, firmware: str = "cm2", *, kernel: Kernel | None = None,
                state_dir: Path | str | None = None, machine: Path | str | Machine | None = None,
                pacing: bool = False, plant: Mapping[str, float] | None = None,
                traced: bool = False, setup: str | Iterable[str] = ()) -> Chain:
    """A chain for a test: ``plant`` sets fields of every motor's plant (a load, friction:
    motor/motion/plant.py), each line of ``setup`` runs as CML, then ``traced`` starts its
    trace recorder (``record(chain)`` gives it back)."""
    chain = Chain(kernel, motors, firmware=firmware, state_dir=state_dir, machine=machine,
                  pacing=pacing)
    for motor in chain.motors.values():
        for name, value in (plant or {}).items():
            setattr(motor.plant, name, value)
    for line in [setup] if isinstance(setup, str) else setup:
        chain.execute(line)
    if traced:
        from ..tools.trace.recorder import record
        record(chain)
    return chain


def escape(data: bytes) -> str:
    """Bytes as a script writes them (``\\r\\n`` visible)."""
    from ..tools.script.runner import escape as script_escape
    return script_escape(data)


class ChainRig:
    """One chain under test (the ``cm_chain`` fixture); see the module docstring.

    ``base``: where relative file names are looked up (the test's folder); ``root``:
    what shown file names are relative to (pytest's rootdir); ``coverage``: the run's
    bank coverage, if any; ``plot_dir`` and ``name``: where a failing assertion draws
    the trace (``name.png``)."""

    def __init__(self, chain: Chain, *, base: Path | None = None, root: Path | None = None,
                 coverage: BankCoverage | None = None, plot_dir: Path | None = None,
                 name: str = "chain") -> None:
        from ..tools.trace.recorder import record
        self.chain = chain
        self.base = base or Path.cwd()
        self.root = root or self.base
        self.coverage = coverage
        self.plot_dir = plot_dir
        self.name = name
        self.start_ns = chain.kernel.now
        self.recorder: TraceRecorder = record(chain)
        self.files: list[BankFile] = []
        self._maps: dict[BankKey, tuple[str, BankMap]] = {}
        self.program_lines: list[BankLine] = []
        self.hits: dict[tuple[int, bool, int, int], int] = {}
        self._temps: dict[int, list[tuple[int, int]]] = {m: [] for m in chain.motor_ids}
        self._ports: list[Any] = []
        self._closed = False
        self._plot: Path | None = None
        self._removers = [chain.observe_bank_lines(self._line_ran),
                          chain.kernel.add_observer(self._read_temperatures)]
        self._read_temperatures()

    # -- time ----------------------------------------------------------------------
    @property
    def now(self) -> float:
        """Virtual seconds since the rig was built."""
        return self.seconds(self.chain.kernel.now)

    def seconds(self, t: int) -> float:
        return (t - self.start_ns) / NS_PER_S

    def run(self, duration: float) -> None:
        """Let ``duration`` virtual seconds pass (instantly)."""
        self.chain.kernel.advance(seconds(duration))
        self._read_temperatures(force=True)

    def run_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Run until ``predicate()`` holds or ``timeout`` virtual seconds passed."""
        done = self.chain.kernel.run_until(predicate, seconds(timeout))
        self._read_temperatures(force=True)
        return bool(done)

    # -- driving -------------------------------------------------------------------
    def send(self, line: str, *, motor: int | None = None) -> list[str]:
        """Run a CML line through the device API; the replies it gave at once."""
        return self.chain.execute(line, motor=motor)

    def set_input(self, motor: int, number: int, on: bool) -> None:
        self.chain.set_input(motor, number, on)

    def set_analog(self, motor: int, counts: int) -> None:
        self.chain.set_analog(motor, counts)

    def wait_for(self, pattern: str, timeout: float = 10.0) -> str:
        """Run until the motor says a line matching ``pattern`` (a regular expression) on
        the host line; that line.  :class:`~.expect.MotionAssertionError` after
        ``timeout`` virtual seconds, with the trace."""
        said: list[str] = []
        regex = re.compile(pattern)
        remove = self.chain.subscribe(lambda event: said.append(event.text))
        try:
            found = self.run_until(lambda: any(regex.search(s) for s in said), timeout)
        finally:
            remove()
        if not found:
            self.expect(1).fail(f"nothing matching {pattern!r} said within {timeout:g} s "
                                f"(said: {said[-5:]})", self.chain.kernel.now)
        return next(s for s in said if regex.search(s))

    def reply(self, line: str, within: float = 0.05) -> bytes:
        """Type ``line`` on the host line (CR added) and return every byte the motor sends
        back within ``within`` virtual seconds: echo, replies, reports (6.6)."""
        received = bytearray()
        remove = self.chain.host_line.add_listener(received.extend)
        try:
            self.chain.host_line.feed(line.encode("latin-1") + b"\r")
            self.run(within)
        finally:
            remove()
        return bytes(received)

    def expect_reply(self, line: str, expected: bytes | str, within: float = 0.05) -> None:
        """The bytes the motor sends back for ``line`` are exactly ``expected``."""
        __tracebackhide__ = True     # pytest shows the test's line, not this
        from .expect import MotionAssertionError
        want = expected.encode("latin-1") if isinstance(expected, str) else expected
        got = self.reply(line, within)
        if got != want:
            diff = next((i for i, (a, b) in enumerate(zip(want, got)) if a != b),
                        min(len(want), len(got)))
            raise MotionAssertionError(
                f'reply to {line!r}: expected "{escape(want)}" but the motor sent '
                f'"{escape(got)}" (differs at byte {diff}, at {self.now:.3f} s)')

    def load(self, path: str | Path) -> BankFile:
        """Send a ``.cml`` file (relative to the test's folder, then the rootdir): its
        direct lines run, its banks are stored and read back (:mod:`.banks`)."""
        found = self._find(Path(path))
        loaded = load_bank_file(self.chain, found, shown=self._shown(found))
        self.files.append(loaded)
        for key, bank in loaded.banks.items():
            self._maps[key] = (loaded.path, bank)
        if self.coverage is not None:
            self.coverage.add_bank_file(loaded)
        return loaded

    def port(self, timeout: float | None = 1.0) -> Any:
        """A pyserial port on this chain in fast virtual time (a read waits virtual
        time, instantly): hand it to a host program (``coolmuscle.connect(port)``)."""
        from ..frontends.urlhandler.protocol_coolmuscle import on_chain
        port = on_chain(self.chain, mode="fast", timeout=timeout)
        self._ports.append(port)
        return port

    def _find(self, path: Path) -> Path:
        for candidate in (path, self.base / path, self.root / path):
            if candidate.is_file():
                return candidate.resolve()
        raise FileNotFoundError(f"no file {path} (looked in {self.base} and {self.root})")

    def _shown(self, path: Path) -> str:
        try:
            return path.relative_to(self.root.resolve()).as_posix()
        except ValueError:
            return str(path)

    # -- checking --------------------------------------------------------------------
    def expect(self, motor: int = 1) -> MotorExpect:
        """The assertions on ``motor`` (:class:`.expect.MotorExpect`)."""
        from .expect import MotorExpect
        return MotorExpect(self, motor)

    def temperatures(self, motor: int) -> list[tuple[int, int]]:
        """(kernel ns, °C) readings of ``motor``'s driver temperature (?71)."""
        return list(self._temps[motor])

    def where(self, line: BankLine) -> str:
        """``pick.cml:12 P2.1`` for a line from a file, else ``B1.1 line 4``."""
        key = (line.motor, line.ladder, line.bank)
        mapped = self._maps.get(key)
        if mapped is not None:
            path, bank = mapped
            if line.first < len(bank.lines):
                return f"{path}:{bank.lines[line.first]} {bank.texts[line.first]}"
        return f"{bank_label(key)} line {line.first + 1}"

    def _last_line(self, at: int, motor: int) -> BankLine | None:
        started = [line for line in self.program_lines if line.time <= at]
        own = [line for line in started if line.motor == motor]
        chosen = own or started
        return chosen[-1] if chosen else None

    def running_line(self, at: int, motor: int) -> str | None:
        """The program bank line running at ``at`` (``motor``'s own bank first), with
        where it is and when it started."""
        line = self._last_line(at, motor)
        if line is None:
            return None
        return (f"{self.where(line)}  ({bank_label((line.motor, False, line.bank))} line "
                f"{line.first + 1}, started at {self.seconds(line.time):.3f} s)")

    def line_at(self, at: int, motor: int) -> str | None:
        """The short form of :meth:`running_line` for a trace row."""
        line = self._last_line(at, motor)
        return None if line is None else self.where(line)

    def failure_plot(self) -> Path | None:
        """Draw the whole trace into the plot folder (once per rig), if there is one."""
        if self.plot_dir is None:
            return None
        if self._plot is None:
            from ..tools.trace.plot import plot
            self.plot_dir.mkdir(parents=True, exist_ok=True)
            self._plot = plot(self.chain, self.plot_dir / f"{self.name}.png",
                              title=f"{self.name} (virtual time)")
        return self._plot

    # -- observing -------------------------------------------------------------------
    def _line_ran(self, line: BankLine) -> None:
        for index in range(line.first, line.last + 1):
            key = (line.motor, line.ladder, line.bank, index)
            self.hits[key] = self.hits.get(key, 0) + 1
        if not line.ladder:
            self.program_lines.append(line)

    def _read_temperatures(self, force: bool = False) -> None:
        now = self.chain.kernel.now
        for motor, readings in self._temps.items():
            if force or not readings or now - readings[-1][0] >= TEMPERATURE_EVERY_NS:
                if not readings or readings[-1][0] != now:
                    readings.append((now, self.chain.snapshot(motor).temperature))

    # -- the end -----------------------------------------------------------------------
    def covered(self) -> dict[tuple[str, str], dict[int, int]]:
        """(file, bank label) -> {file line: times run}; banks not from a file are
        named by their label, their lines by stored index + 1."""
        from .coverage import NO_FILE
        out: dict[tuple[str, str], dict[int, int]] = {}
        for (motor, ladder, number, index), count in self.hits.items():
            key = (motor, ladder, number)
            mapped = self._maps.get(key)
            if mapped is not None and index < len(mapped[1].lines):
                where, line = (mapped[0], bank_label(key)), mapped[1].lines[index]
            else:
                where, line = (NO_FILE, bank_label(key)), index + 1
            lines = out.setdefault(where, {})
            lines[line] = max(lines.get(line, 0), count)    # "A; B": one file line
        return out

    def close(self) -> None:
        """Hand the lines that ran to the coverage, close the ports and the chain."""
        if self._closed:
            return
        self._closed = True
        for remove in self._removers:
            remove()
        for port in self._ports:
            port.close()
        if self.coverage is not None:
            for (path, label), lines in self.covered().items():
                self.coverage.add_hits(path, label, lines)
        self.recorder.stop()
        self.chain.close()
