"""What the page's desk asks of a motor, as sans-IO client operations.

The same operations serve the virtual page and the page of a real motor: each is a
generator of :mod:`coolmuscle.client.ops` that only sends CML lines and reads their
answers, run by the in-process link of a served chain (:class:`.deskpage.ChainRunner`)
or by the asyncio driver on a serial line (:class:`.line.LineDevice`).  No motor
behaviour is here: the motor answers, the operation reports what it said.

* :func:`k_table`: ``?90.n`` (6.6) beside the catalogue of the firmware (table 6.1,
  RT3 3.5, CM1 Appendix A): meaning, unit, range, factory value, the firmware that
  define each K, and whether the motor's value differs from the factory one;
* :func:`k_write`: ``K#.n=v`` (ch. 3) refused before sending when the catalogue says
  the value is out of range, then read back (the motor's own ``errorNN`` when it
  refuses); the line's own parameters (K20 rate, K81 COM0 protocol, K82 parity) are
  refused: writing them would cut the page off from the motor;
* :func:`motion`: the buttons (jog, enable ``(``, free ``)``, stop ``]``, alarm reset),
  each followed by ``?99.n`` (docs/fidelity.md "Web dashboard");
* :func:`find_motors` and :func:`read_images`: the scan of a chain without a wire, and
  the reading of a backup (:func:`coolmuscle.tools.desk.reading.read_motor`).
"""

from __future__ import annotations

from typing import Any

from ...client.banks import save
from ...client.commands import move, write_param
from ...client.ops import Op, Session, fenced, param, params
from ...errors import CoolMuscleTimeout, InvalidArgumentError, MotorError
from ...motor.state.catalogue import catalogue, defined_on, k_parameter
from ...motor.status import ALARM_BITS, Ux
from ..desk.image import ChainImage, MotorImage
from ..desk.linescan import FoundMotor
from ..desk.reading import read_motor, version_title

__all__ = ["LINE_KS", "MOTIONS", "k_table", "k_write", "save_params", "motion",
           "status_text", "find_motors", "read_images"]

#: K parameters that change how the host reaches the motor (ch. 3 K20 the rate, K81
#: COM0 to Modbus RTU (5.6), K82 the parity): the page does not write them.
LINE_KS = {20: "K20 changes the baud rate of this very line (ch. 3 K20)",
           81: "K81 other than 0 hands COM0 to Modbus RTU (5.6): CML stops",
           82: "K82 changes the parity of this very line (ch. 3 K82)"}

#: The buttons of a motor card and the CML each sends (cml-users-guide.txt 6.5;
#: ``alarm_reset``: ``(`` clears a latched alarm, docs/fidelity.md "Web dashboard").
MOTIONS = {"enable": "(.{n}", "free": ").{n}", "stop": "]", "alarm_reset": "(.{n}"}

_UX_NAMES = ((1, "position error overflow"), (2, "over speed"), (4, "overload"),
             (8, "in position"), (16, "free"), (32, "push"), (64, "over current"),
             (128, "temperature"), (256, "push error"), (512, "emergency stop"))


def status_text(ux: int) -> str:
    """``Ux=8 in position`` (6.6 ?99)."""
    names = [name for bit, name in _UX_NAMES if ux & bit]
    return f"Ux={ux} " + (", ".join(names) if names else "moving")


def k_table(session: Session, motor: int, firmware: str) -> Op[dict[str, Any]]:
    """Every K the firmware defines, with the motor's value (``?90.n``)."""
    values = yield from params(session, motor)
    rows: list[dict[str, Any]] = []
    for entry in catalogue(firmware):
        if not entry.defined:
            continue
        value = values.get(entry.k)
        rows.append({"k": entry.k, "name": entry.name, "unit": entry.unit,
                     "range": entry.range_text(), "default": entry.default,
                     "meaning": entry.meaning, "value": value,
                     "changed": value is not None and value != entry.default,
                     "firmware": list(defined_on(entry.k)),
                     "line": LINE_KS.get(entry.k)})
    source = catalogue(firmware)[0].source
    return {"motor": motor, "firmware": firmware, "source": source, "rows": rows}


def check_k(firmware: str, k: int, value: int) -> str | None:
    """Why ``K{k}={value}`` is not written from the page (``None``: it may be)."""
    try:
        entry = k_parameter(firmware, k)
    except LookupError as exc:
        return str(exc)
    if k in LINE_KS:
        return (f"{LINE_KS[k]}: the page would lose the motor; change it with "
                "coolmuscle term or a restore, which follow the line")
    return entry.problem(value)


def k_write(session: Session, motor: int, firmware: str, k: int,
            value: int) -> Op[dict[str, Any]]:
    """``K#.n=v`` read back; refused unsent when :func:`check_k` says why."""
    problem = check_k(firmware, k, value)
    if problem is not None:
        raise InvalidArgumentError(problem)
    yield from write_param(session, motor, k, value)        # read back in its fence
    got = session.cache(motor).params[k]
    return {"motor": motor, "k": k, "value": got,
            "changed": got != k_parameter(firmware, k).default}


def save_params(session: Session, motor: int) -> Op[dict[str, Any]]:
    """``$.n``, waiting for ``saved.n`` (2.1.2)."""
    yield from save(session, motor)
    return {"motor": motor, "saved": True}


def motion(session: Session, motor: int, what: str, step: int = 0,
           speed: int | None = None) -> Op[dict[str, Any]]:
    """A button of the motor card; the status after it (``?99.n``)."""
    if what in ("jog+", "jog-"):
        distance = step if what == "jog+" else -step
        moved = yield from move(session, motor, distance, relative=True, speed=speed)
        sent = f"P.{motor}{'+' if distance >= 0 else '-'}={abs(distance)}, ^.{motor}"
        return {"motor": motor, "sent": sent, "status": int(moved),
                "text": status_text(int(moved))}
    line = MOTIONS[what].format(n=motor)
    answer = yield from fenced(session, motor, (line,), status=True)
    ux = answer[-1].int_value()
    result: dict[str, Any] = {"motor": motor, "sent": line, "status": ux,
                              "text": status_text(ux)}
    if what == "alarm_reset" and ux & ALARM_BITS:
        result["note"] = (f"the alarm is back at once ({status_text(ux)}): its cause is "
                          "still there")
    return result


def find_motors(session: Session, ids: tuple[int, ...] = tuple(range(1, 16))
                ) -> Op[list[FoundMotor]]:
    """``?85.n`` and ``K20.n`` for ID1, ID2 ... up to the first that is silent (the scan
    of :mod:`coolmuscle.tools.desk.linescan` on a line without a wire)."""
    found: list[FoundMotor] = []
    for motor in ids:
        try:
            title = yield from version_title(session, motor)
            k20: int | None = yield from param(session, motor, 20)
        except (CoolMuscleTimeout, MotorError):
            break
        found.append(FoundMotor(motor, title, k20))
    return found


def read_images(session: Session, ids: tuple[int, ...], source: str,
                baud: int | None, taken: str) -> Op[ChainImage]:
    """Every motor of ``ids`` read whole (what a backup holds)."""
    motors: list[MotorImage] = []
    for motor in ids:
        motors.append((yield from read_motor(session, motor)))
    return ChainImage(tuple(motors), source, baud, taken)


def at_rest(ux: int) -> bool:
    """ch. 3 "Do not change parameters during motion": in position, free, an alarm or
    a stop (6.6 ?99)."""
    return bool(ux & (Ux.IN_POSITION | Ux.MOTOR_FREE | ALARM_BITS | Ux.EMERGENCY_STOP
                      | Ux.PUSH_ERROR))
