"""Replaying a capture on a virtual chain, in virtual time, at the capture's own instants.

Each line the host sent is fed to the virtual host line at the instant it reached the
real motor: its stamp (when its CR reached the relay) plus the wire time of that CR on
the relay's motor side (one byte at the capture's baud rate).  What the virtual motor
says is kept with its virtual instant on the capture's clock, with the line sent
before it, and for a polled value (6.6 ``?95``-``?98``) the exact value before the
motor rounds it (the fit needs a smooth function of its parameters).  No ``@wait`` or
``@until`` of the file is used: the stamps are the timing (docs/twin.md).

The replay goes through :func:`coolmuscle.tools.script.run_script` and the chain's
host line like any script, unpaced: a reply comes at the instant of its query.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ...chain.machine import AxisSpec, Machine
from ...device.api import ChainFactory, Device
from ...motor.state.units import resolution
from ...sim.kernel import NS_PER_S
from ..script.runner import Script, Step, TranscriptEntry, run_script
from .session import Line, Session, parse_poll

if TYPE_CHECKING:
    from ..trace.recorder import TraceRecorder

__all__ = ["Replay", "exact_value", "replay", "with_header_params"]

#: Virtual seconds the replay runs on after the last line of the capture (late replies).
TAIL_S = 1.0


def exact_value(device: Device, motor: int, quantity: str) -> float:
    """What ``?95``/``?96``/``?97``/``?98`` of ``motor`` read now, before rounding."""
    if quantity not in ("Px", "Pe", "Sx", "Ix"):
        raise ValueError(f"not a polled quantity: {quantity!r}")
    snap = device.snapshot(motor)
    if quantity == "Px":
        return snap.position_exact
    if quantity == "Pe":
        return snap.position_error_exact
    if quantity == "Sx":
        return snap.speed_pps / speed_unit_pps(device, motor)
    return snap.torque_exact


def speed_unit_pps(device: Device, motor: int) -> int:
    """Pulses per second of one ``?97`` speed unit of ``motor`` (its K37, ch. 3)."""
    return resolution(device.get_param(motor, 37)).speed_unit_pps


@dataclass
class Replay:
    """What the virtual chain said during a replay."""

    lines: list[Line]                   # received, time on the capture's clock
    after: list[int]                    # per line: index of the line sent before it (-1)
    exact: dict[int, float]             # line index -> exact polled value
    origin_ns: int                      # kernel time of the capture's t=0
    failure: str | None = None          # the model raised (the replay stopped there)
    recorder: TraceRecorder | None = None
    speed_units: dict[int, int] = field(default_factory=dict)   # motor -> pps per Sx unit

    def kernel_ns(self, seconds: float) -> int:
        """The kernel instant of a time on the capture's clock."""
        return self.origin_ns + round(seconds * NS_PER_S)


def with_header_params(machine: Machine | None, session: Session) -> Machine | None:
    """``machine`` plus the K values of the capture header (``k23=``: echo and reports,
    ch. 3 K23) on every motor that has no value of its own for them."""
    ks = {k: v for k, v in session.k_params().items() if k == 23}
    if not ks:
        return machine
    axes = {a.motor: a for a in (machine.axes if machine else [])}
    out = []
    for motor in range(1, session.motors + 1):
        spec = axes.pop(motor, None) or AxisSpec(motor=motor)
        out.append(dataclasses.replace(spec, params={**ks, **spec.params}))
    out += axes.values()             # axes beyond the chain: apply_machine names them
    return Machine(out, machine.source if machine else "<capture header>")


def _steps(session: Session) -> Script:
    """The lines sent, each at its instant, then the tail (kernel ns kept exact)."""
    steps: list[Step] = []
    byte_ns = (round(session.bits_per_byte * NS_PER_S / session.baud)
               if session.baud else 0)
    now = 0
    for index, line in enumerate(session.sent):
        at = round(line.time * NS_PER_S) + byte_ns
        if at > now:
            steps.append(Step(0, "wait", "@wait", seconds=(at - now) / NS_PER_S))
            now = at
        steps.append(Step(index + 1, "raw", "@send", data=line.data))
    end = round((session.duration + TAIL_S) * NS_PER_S)
    if end > now:
        steps.append(Step(0, "wait", "@wait", seconds=(end - now) / NS_PER_S))
    return Script(tuple(steps))


def replay(session: Session, machine: Machine | None = None, *, record: bool = False,
           chain_factory: ChainFactory | None = None) -> Replay:
    """Replay ``session`` on a fresh chain with ``machine`` (None: the default load).

    ``record``: keep a trace recorder on the chain (exact values at any instant, for
    the compare's tolerance bands).  A bad machine file raises MachineFileError."""
    if chain_factory is None:
        from ...chain.daisy import Chain
        chain_factory = Chain
    chain = chain_factory(None, session.motors, firmware=session.firmware,
                          machine=with_header_params(machine, session))
    try:
        recorder = None
        if record:
            from ..trace.recorder import record as start_recording
            recorder = start_recording(chain)
        origin = chain.kernel.now
        lines: list[Line] = []
        after: list[int] = []
        exact: dict[int, float] = {}
        sent = [-1]

        def on_entry(entry: TranscriptEntry) -> None:
            if entry.direction == ">":
                sent[0] = (entry.line_no or 0) - 1
                return
            seconds = (entry.time - origin) / NS_PER_S
            line = Line(seconds, "<", entry.data, 0)
            found = parse_poll(line.text)
            if found is not None and found[1] in chain.motor_ids:
                exact[len(lines)] = exact_value(chain, found[1], found[0])
            lines.append(line)
            after.append(sent[0])

        result = run_script(_steps(session), chain, on_entry=on_entry)
        units = {mid: speed_unit_pps(chain, mid) for mid in chain.motor_ids}
        failure = result.failure.message if result.failure is not None else None
        return Replay(lines, after, exact, origin, failure, recorder, units)
    finally:
        chain.close()
