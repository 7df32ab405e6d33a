"""``coolmuscle compare``: each line the real motor said beside what the virtual one said.

The capture is replayed on the virtual motor (:mod:`.replay`); each line received from
the real motor is paired with a line of the virtual one, and judged:

* **equal**: the same bytes, within the timing tolerance;
* **within tolerance**: a polled value (6.6 ``?95``-``?98``) that differs, but by no
  more than the value tolerance below;
* **different value**: a polled value beyond its tolerance;
* **different bytes**: other bytes;
* **different timing**: the same bytes, later or earlier than the timing tolerance;
* **missing** / **extra**: a line only the real / only the virtual motor said.

Pairing: first a line with the line of the same text (a polled value: the same
quantity and motor) that follows the same line sent; then one of the same text
anywhere, in order (a report such as ``Ux.1=8`` that came after another poll); then one
of the same name before ``=`` (``Ux.1=8`` / ``Ux.1=4``).

Tolerances (docs/twin.md "Tolerances"):

* timing: ``max(time_abs, time_rel x the time since the line sent before it)`` plus the
  wire time of the bytes received since that line at the capture's baud rate (the real
  line's bytes take it; the virtual replay is unpaced);
* a polled value: the real motor read it at some instant between its query's CR and
  its reply's last byte (both stamped by the relay), so the virtual value may be
  anything the virtual quantity passes through in that window (widened by ``sample``
  seconds each side), plus 0.5 (rounding) and ``noise`` units: a value polled while
  moving moves with its timing.  The window also reaches back by the *lag* of the last
  command before the poll (the last line sent that is not a ``?`` query): the replay
  acts on a command at its stamp, the real motor somewhere before its first reply came
  back, so a motion it started may run late on the real motor by up to that reply's
  stamp less the wire time of what the motor sent after acting on the command
  (:func:`_command_lags`), measured per command from the capture.
"""

from __future__ import annotations

import base64
import html
import math
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from ...chain.machine import Machine
from .plot import Panel, Series, figure_png
from .replay import Replay, replay
from .session import POLLED, Line, Session, parse_poll

if TYPE_CHECKING:
    from ..ci.junit import Suite

__all__ = ["Tolerance", "Verdict", "Report", "compare", "compare_session", "junit_suite"]

Kind = Literal["equal", "close", "value", "bytes", "timing", "missing", "extra"]
#: The words of each verdict, the same in the rows and in the summary.
KIND_NAMES: dict[str, str] = {"equal": "equal", "close": "within tolerance",
                              "value": "different value", "bytes": "different bytes",
                              "timing": "different timing", "missing": "missing",
                              "extra": "extra"}
DIFFERENCES = ("value", "bytes", "timing", "missing", "extra")


@dataclass(frozen=True)
class Tolerance:
    """What ``compare`` lets pass (docs/twin.md "Tolerances")."""

    time_abs: float = 0.02      # s
    time_rel: float = 0.02      # of the time since the line sent before
    noise: float = 1.0          # units of a polled value, beyond its rounding
    sample: float = 0.001       # s each side of a poll's query-to-reply window

    def describe(self, baud: int | None, bits: int) -> str:
        wire = (f" + its bytes' wire time at {baud} baud ({bits} bits a byte)" if baud
                else " (no baud rate in the capture: no wire time)")
        return (f"timing: max({self.time_abs * 1000:g} ms, {self.time_rel * 100:g} % of "
                f"the time since the line sent before it){wire}; polled values: what the "
                f"virtual value spans from the query to the reply (±{self.sample * 1000:g} "
                f"ms, and back by the real motor's lag on the command before it) "
                f"± {0.5 + self.noise:g} units (rounding and {self.noise:g} of noise)")


@dataclass(frozen=True)
class Verdict:
    """One line of the real motor (or an extra one of the virtual motor), judged."""

    kind: Kind
    real: Line | None
    virtual: Line | None
    tolerance_s: float = 0.0                 # the timing tolerance used
    band: tuple[float, float] | None = None  # a polled value: what passes
    off: float = 0.0                         # a polled value: units outside the band

    @property
    def differs(self) -> bool:
        return self.kind in DIFFERENCES

    @property
    def dt(self) -> float | None:
        """Virtual minus real instant (s)."""
        if self.real is None or self.virtual is None:
            return None
        return self.virtual.time - self.real.time

    def describe(self) -> str:
        """One line: where, what the real motor said, what the virtual one said, by how much."""
        real, virtual = self.real, self.virtual
        if real is None:
            assert virtual is not None
            return (f"{virtual.time:.3f} s: extra: the virtual motor said "
                    f"{_show(virtual)} and the real one nothing like it")
        where = f"line {real.line_no} ({real.time:.3f} s)"
        if virtual is None:
            return f"{where}: missing: the real motor said {_show(real)}, the virtual one not"
        said = f"the real motor said {_show(real)}, the virtual one {_show(virtual)}"
        if self.kind == "timing":
            dt = virtual.time - real.time
            return (f"{where}: different timing: {_show(real)} {abs(dt) * 1000:.1f} ms "
                    f"{'later' if dt > 0 else 'earlier'} on the virtual motor (tolerance "
                    f"{self.tolerance_s * 1000:.1f} ms)")
        if self.band is not None:
            lo, hi = self.band
            name = KIND_NAMES[self.kind]
            return (f"{where}: {name}: {said}: {self.off:g} outside {lo:.1f}..{hi:.1f}"
                    if self.off else f"{where}: {name}: {said} (tolerance {lo:.1f}..{hi:.1f})")
        return f"{where}: {KIND_NAMES[self.kind]}: {said} at {virtual.time:.3f} s"


def _show(line: Line) -> str:
    from ..script.runner import escape
    shown = escape(line.data.rstrip(b"\r\n"))
    return f'"{shown}"'


@dataclass
class Report:
    """The outcome of :func:`compare`."""

    session: Session
    machine: str
    tolerance: Tolerance
    verdicts: list[Verdict]
    replay: Replay
    panels: list[Panel] = field(default_factory=list)

    @property
    def differences(self) -> list[Verdict]:
        return [v for v in self.verdicts if v.differs]

    @property
    def ok(self) -> bool:
        return not self.differences and self.replay.failure is None

    def counts(self) -> dict[str, int]:
        out = {kind: 0 for kind in KIND_NAMES}
        for verdict in self.verdicts:
            out[verdict.kind] += 1
        return out

    def heading(self) -> str:
        s = self.session
        return (f"{Path(s.source).name} ({s.duration:.1f} s, {len(s.sent)} lines sent, "
                f"{len(s.received)} received) on {self.machine}")

    def summary(self) -> str:
        counts = self.counts()
        return ", ".join(f"{KIND_NAMES[k]} {n}" for k, n in counts.items())

    def verdict_line(self) -> str:
        if self.replay.failure is not None:
            return f"FAIL the virtual motor stopped: {self.replay.failure}"
        if self.ok:
            return f"ok: {len(self.verdicts)} line(s) received within tolerance"
        return f"FAIL {len(self.differences)} difference(s) beyond tolerance"

    def quantity_rows(self) -> list[tuple[str, int, float, float]]:
        """Per polled quantity: (name, polls, largest |real - virtual|, RMS)."""
        rows = []
        for panel in self.panels:
            real = next(s for s in panel.series if s.style == "real")
            virtual = next(s for s in panel.series if s.style == "virtual")
            diffs = [r - v for r, v in zip(real.values, virtual.values, strict=True)]
            if diffs:
                rms = math.sqrt(sum(d * d for d in diffs) / len(diffs))
                rows.append((panel.title, len(diffs), max(abs(d) for d in diffs), rms))
        return rows

    # -- reports ------------------------------------------------------------
    def to_markdown(self, plot: str | None = None) -> str:
        out = [f"# coolmuscle compare: {Path(self.session.source).name}", "",
               f"Capture {self.heading()}.", "",
               f"**Verdict: {self.verdict_line()}**", "",
               f"Tolerance: {self._tolerance_text()}.", "",
               "| verdict | lines |", "|---|---|"]
        out += [f"| {KIND_NAMES[k]} | {n} |" for k, n in self.counts().items()]
        rows = self.quantity_rows()
        if rows:
            out += ["", "## Polled values", "",
                    "| quantity | polls | largest difference | RMS |", "|---|---|---|---|"]
            out += [f"| {name} | {n} | {worst:g} | {rms:.2f} |" for name, n, worst, rms in rows]
        if plot:
            out += ["", f"![real and virtual curves]({plot})"]
        out += ["", "## Differences", ""]
        diffs = self.differences
        if not diffs:
            out.append("None beyond tolerance.")
        else:
            out += ["| line | real s | verdict | real motor | virtual motor | virtual s | "
                    "by | tolerance |", "|---|---|---|---|---|---|---|---|"]
            out += ["| " + " | ".join(_cells(v)) + " |" for v in diffs]
        return "\n".join(out) + "\n"

    def to_html(self) -> str:
        esc = html.escape
        rows = "".join(f"<tr><td>{esc(KIND_NAMES[k])}</td><td>{n}</td></tr>"
                       for k, n in self.counts().items())
        quantities = "".join(f"<tr><td>{esc(name)}</td><td>{n}</td><td>{worst:g}</td>"
                             f"<td>{rms:.2f}</td></tr>"
                             for name, n, worst, rms in self.quantity_rows())
        png = base64.b64encode(figure_png(self.panels, self.heading())).decode("ascii")
        diffs = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in _cells(v)) + "</tr>"
                        for v in self.differences) or \
            '<tr><td colspan="8">None beyond tolerance.</td></tr>'
        verdict_class = "ok" if self.ok else "fail"
        return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>coolmuscle compare: {esc(Path(self.session.source).name)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 70em; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }}
.ok {{ color: #2ca02c; }} .fail {{ color: #d62728; }}
img {{ max-width: 100%; }}
</style></head><body>
<h1>coolmuscle compare: {esc(Path(self.session.source).name)}</h1>
<p>Capture {esc(self.heading())}.</p>
<p class="{verdict_class}" id="verdict"><strong>Verdict: {esc(self.verdict_line())}</strong></p>
<p>Tolerance: {esc(self._tolerance_text())}.</p>
<table id="summary"><tr><th>verdict</th><th>lines</th></tr>{rows}</table>
<h2>Polled values</h2>
<table id="quantities"><tr><th>quantity</th><th>polls</th><th>largest difference</th>
<th>RMS</th></tr>{quantities}</table>
<img alt="real and virtual curves" src="data:image/png;base64,{png}">
<h2>Differences</h2>
<table id="differences"><tr><th>line</th><th>real s</th><th>verdict</th><th>real motor</th>
<th>virtual motor</th><th>virtual s</th><th>by</th><th>tolerance</th></tr>{diffs}</table>
</body></html>
"""

    def _tolerance_text(self) -> str:
        return self.tolerance.describe(self.session.baud, self.session.bits_per_byte)


def _cells(v: Verdict) -> list[str]:
    """line, real s, verdict, real, virtual, virtual s, by, tolerance."""
    from ..script.runner import escape

    def text(line: Line | None) -> str:
        return escape(line.data.rstrip(b"\r\n")) if line is not None else "(nothing)"

    name = KIND_NAMES[v.kind]
    if v.kind == "timing" and v.dt is not None:
        by, tol = f"{v.dt * 1000:+.1f} ms", f"{v.tolerance_s * 1000:.1f} ms"
    elif v.band is not None:
        by, tol = f"{v.off:g}", f"{v.band[0]:.1f}..{v.band[1]:.1f}"
    else:
        by, tol = "", ""
    return [str(v.real.line_no) if v.real else "", f"{v.real.time:.6f}" if v.real else "",
            name, text(v.real), text(v.virtual),
            f"{v.virtual.time:.6f}" if v.virtual else "", by, tol]


# -- pairing ------------------------------------------------------------------
def _key(line: Line) -> tuple[str, ...]:
    found = parse_poll(line.text)
    if found is not None:
        return ("poll", found[0], str(found[1]))
    return ("text", line.data.decode("latin-1"))


def _name(line: Line) -> str | None:
    text = line.text
    return text.split("=", 1)[0] if "=" in text else None


def pair_lines(real: list[Line], real_after: list[int], virtual: list[Line],
               virtual_after: list[int]) -> list[tuple[int | None, int | None]]:
    """(real index, virtual index) pairs; an index alone is a line the other lacks."""
    pairs: list[tuple[int | None, int | None]] = []
    free_real = set(range(len(real)))
    free_virtual = set(range(len(virtual)))

    def match(group: Callable[[Line, int], object]) -> None:
        queues: dict[object, list[int]] = {}
        for j in sorted(free_virtual):
            key = group(virtual[j], virtual_after[j])
            if key is not None:
                queues.setdefault(key, []).append(j)
        cursor = {key: 0 for key in queues}
        for i in sorted(free_real):
            key = group(real[i], real_after[i])
            queue = queues.get(key) if key is not None else None
            if queue is None or cursor[key] >= len(queue):
                continue
            j = queue[cursor[key]]
            cursor[key] += 1
            pairs.append((i, j))
            free_real.discard(i)
            free_virtual.discard(j)

    match(lambda line, after: (after, _key(line)))          # after the same line sent
    match(lambda line, after: _key(line))                   # the same text, in order
    match(lambda line, after: _name(line))                  # the same name before '='
    pairs += [(i, None) for i in sorted(free_real)]
    pairs += [(None, j) for j in sorted(free_virtual)]

    def when(pair: tuple[int | None, int | None]) -> float:
        i, j = pair
        return real[i].time if i is not None else virtual[j].time if j is not None else 0.0
    pairs.sort(key=when)
    return pairs


# -- judging ------------------------------------------------------------------
class _Bands:
    """What the virtual quantity passes through in a window (from the trace recorder)."""

    def __init__(self, rep: Replay) -> None:
        self.rep = rep
        self.recorder = rep.recorder
        self.changes = self.recorder.change_times() if self.recorder is not None else []

    def span(self, motor: int, quantity: str, lo_s: float, hi_s: float) -> list[float]:
        recorder = self.recorder
        if recorder is None or motor not in recorder.motor_ids:
            return []
        lo, hi = self.rep.kernel_ns(lo_s), self.rep.kernel_ns(hi_s)
        times = {lo, hi, (lo + hi) // 2}
        times.update(self.changes[bisect_left(self.changes, lo):bisect_right(self.changes, hi)])
        unit = self.rep.speed_units.get(motor, 1)
        out = []
        for t in sorted(times)[:200]:
            s = recorder.sample(motor, max(t, recorder.start))
            out.append({"Px": s.position, "Pe": s.command - s.position, "Sx": s.speed / unit,
                        "Ix": s.torque}[quantity])
        return out


def compare(session: Session, rep: Replay, tolerance: Tolerance = Tolerance(),
            machine: str = "the default machine") -> Report:
    """Judge every line of ``session`` against the replay ``rep``."""
    real_after = session.sent_before()
    wire = _wire_times(session, real_after)
    lags = _command_lags(session, real_after)
    bands = _Bands(rep)
    verdicts: list[Verdict] = []
    poll_pairs: list[tuple[Line, Line, bool]] = []
    for i, j in pair_lines(session.received, real_after, rep.lines, rep.after):
        if i is None:
            assert j is not None
            verdicts.append(Verdict("extra", None, rep.lines[j]))
            continue
        real = session.received[i]
        if j is None:
            verdicts.append(Verdict("missing", real, None))
            continue
        virtual = rep.lines[j]
        before = session.sent[real_after[i]].time if real_after[i] >= 0 else 0.0
        tol = max(tolerance.time_abs, tolerance.time_rel * (real.time - before)) + wire[i]
        timely = abs(virtual.time - real.time) <= tol
        lag = lags[real_after[i]] if real_after[i] >= 0 else 0.0
        verdict = _judge(real, virtual, tol, timely, session, real_after[i], rep.exact.get(j),
                         bands, tolerance, lag)
        verdicts.append(verdict)
        if verdict.band is not None:
            poll_pairs.append((real, virtual, verdict.differs))
    return Report(session, machine, tolerance, verdicts, rep, _panels(poll_pairs))


def _judge(real: Line, virtual: Line, tol: float, timely: bool, session: Session,
           before: int, exact: float | None, bands: _Bands, tolerance: Tolerance,
           lag: float) -> Verdict:
    found_real, found_virtual = parse_poll(real.text), parse_poll(virtual.text)
    if found_real is not None and found_virtual is not None \
            and found_real[:2] == found_virtual[:2]:
        quantity, motor, value = found_real
        asked = session.sent[before].time if before >= 0 else real.time
        span = bands.span(motor, quantity, asked - tolerance.sample - lag,
                          real.time + tolerance.sample)
        span += [found_virtual[2]] + ([exact] if exact is not None else [])
        margin = 0.5 + tolerance.noise
        band = (min(span) - margin, max(span) + margin)
        off = round(max(band[0] - value, value - band[1], 0.0), 3)
        if off > 0:
            return Verdict("value", real, virtual, tol, band, off)
        if not timely:
            return Verdict("timing", real, virtual, tol, band)
        return Verdict("equal" if real.data == virtual.data else "close", real, virtual, tol,
                       band)
    if real.data != virtual.data:
        return Verdict("bytes", real, virtual, tol)
    return Verdict("equal" if timely else "timing", real, virtual, tol)


def _command_lags(session: Session, after: list[int]) -> list[float]:
    """Per line sent: the lag of the last command up to it (itself, or the last line
    before it that is not a ``?`` query): how much later than its stamp the real motor
    may have acted on it.  That is the stamp of the first line received after it, less
    the command's CR on the wire and the wire time of what the motor sent after acting:
    of its echo only the line end (K23 8: the motor echoes each byte as it arrives, and
    acts on the line at its CR), of a reply the whole line.  0 when nothing came back
    before the next line was sent; without a baud rate no wire time is taken off."""
    baud = session.baud
    byte_s = session.bits_per_byte / baud if baud else 0.0
    first: dict[int, float] = {}
    for line, sent in zip(session.received, after, strict=True):
        if sent >= 0 and sent not in first:
            command = session.sent[sent]
            echo = line.text == command.text
            after_acting = len(line.data) - (len(line.data.rstrip(b"\r\n")) if echo else 0)
            first[sent] = max(0.0, line.time - command.time - byte_s - after_acting * byte_s)
    out: list[float] = []
    lag = 0.0
    for index, line in enumerate(session.sent):
        if not line.text.lstrip().startswith("?"):
            lag = first.get(index, 0.0)
        out.append(lag)
    return out


def _wire_times(session: Session, after: list[int]) -> list[float]:
    """Per line received: the wire time of the bytes received since the line sent before
    it, up to and including it (0 without a baud rate)."""
    baud = session.baud
    out: list[float] = []
    total, group = 0, -2
    for line, sent in zip(session.received, after, strict=True):
        if sent != group:
            total, group = 0, sent
        total += len(line.data)
        out.append(total * session.bits_per_byte / baud if baud else 0.0)
    return out


def _panels(pairs: Iterable[tuple[Line, Line, bool]]) -> list[Panel]:
    found: dict[tuple[int, str], Panel] = {}
    for real, virtual, differs in pairs:
        rq, vq = parse_poll(real.text), parse_poll(virtual.text)
        assert rq is not None and vq is not None
        key = (rq[1], rq[0])
        panel = found.get(key)
        if panel is None:
            panel = found[key] = Panel(rq[1], rq[0], [Series("real motor", [], [], "real"),
                                                      Series("virtual motor", [], [],
                                                             "virtual"),
                                                      Series("beyond tolerance", [], [],
                                                             "differs")])
        r, v, d = panel.series
        r.times.append(real.time)
        r.values.append(rq[2])
        v.times.append(virtual.time)
        v.values.append(vq[2])
        if differs:
            d.times.append(real.time)
            d.values.append(rq[2])
    order = list(POLLED)
    return [found[k] for k in sorted(found, key=lambda k: (k[0], order.index(k[1])))]


def compare_session(path: str | Path, machine: str | Path | Machine | None = None,
                    tolerance: Tolerance = Tolerance()) -> Report:
    """Read the capture at ``path``, replay it on ``machine`` (a path, a Machine, or None:
    the capture's ``# chain: machine=`` or the default load) and compare."""
    from .session import read_session
    session = read_session(path)
    loaded, name = load_machine_arg(machine, session)
    return compare(session, replay(session, loaded, record=True), tolerance, name)


def load_machine_arg(machine: str | Path | Machine | None,
                     session: Session) -> tuple[Machine | None, str]:
    """The machine to replay on and how to name it: the argument, else the capture's
    own, else none (the default load)."""
    from ...chain.machine import load_machine
    if isinstance(machine, Machine):
        return machine, machine.source
    path = Path(machine) if machine is not None else session.machine
    if path is None:
        return None, "the default machine"
    return load_machine(path), str(path)


def junit_suite(report: Report, path: str | Path) -> Suite:
    """``compare --junit``: a case per line the real motor said (named by its line in
    the capture, ``file`` and ``line`` set), a ``<failure>`` when it differs beyond the
    tolerance; an extra line of the virtual motor is a failing case of its own, and a
    replay the model stopped an ``<error>``."""
    from ..ci.junit import Case, Suite
    where = str(path)
    cases = []
    for verdict in report.verdicts:
        real = verdict.real
        name = (f"line {real.line_no}: {_show(real)}" if real is not None else
                f"extra at {verdict.virtual.time:.3f} s: {_show(verdict.virtual)}"
                if verdict.virtual is not None else "extra")
        if verdict.differs:
            cases.append(Case(name, where, None, "failure", verdict.describe(),
                              KIND_NAMES[verdict.kind], file=where,
                              line=real.line_no if real is not None else None))
        else:
            cases.append(Case(name, where, None, file=where,
                              line=real.line_no if real is not None else None))
    if report.replay.failure is not None:
        cases.append(Case("replay", where, None, "error",
                          f"the virtual motor stopped: {report.replay.failure}", "replay",
                          file=where))
    return Suite(f"coolmuscle compare {Path(where).name}", cases)
