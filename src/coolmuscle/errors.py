"""One exception tree for the whole package.

Errors raised inside the model carry the motor's own error number where there is
one (cml-users-guide.txt ch. 3, K23 function 16: ``errorNN.n: ...``).  Each front
end maps them once, at its entry point, to its protocol's form: an ``errorNN``
line, a Modbus exception, an SDO abort code, a CIP status.  Exceptions that mirror
a built-in also inherit it (``CoolMuscleTimeout`` is a ``TimeoutError``).
"""

from __future__ import annotations

#: The motor's numbered messages (K23 function 16).  ``{n}`` is the motor ID.
MOTOR_ERROR_TEXT: dict[int, str] = {
    0: "Out Of Range!!",
    1: "syntax error!!",
    2: "too many steps!!",
    3: "{xx} is not allowed in bank.1",
    4: "{xx} can not be followed by {dd}",
    5: "Program Bank does not exist!!",
    6: "Ladder Bank does not exist!!",
    7: "CW Limit!!",
    8: "CCW Limit!!",
}


class CoolMuscleError(Exception):
    """Base of every error this package raises."""


class MotorError(CoolMuscleError):
    """An error the motor itself reports as ``errorNN.n: text`` (K23 function 16)."""

    number: int = -1

    def __init__(self, message: str = "", *, xx: str = "", dd: str = "") -> None:
        self.xx = xx
        self.dd = dd
        super().__init__(message or self.motor_text())

    def motor_text(self) -> str:
        """The text after ``errorNN.n: `` as the motor prints it."""
        template = MOTOR_ERROR_TEXT.get(self.number, "")
        return template.format(xx=self.xx, dd=self.dd)

    def motor_line(self, motor_id: int) -> str:
        """The full report line, e.g. ``error00.1: Out Of Range!!``."""
        return f"error{self.number:02d}.{motor_id}: {self.motor_text()}"


class OutOfRangeError(MotorError, ValueError):
    """A K parameter or data value outside its range (error00)."""

    number = 0


class CmlSyntaxError(MotorError, SyntaxError):
    """A CML line that does not parse (error01); carries the column."""

    number = 1

    def __init__(self, message: str, *, text: str = "", position: int = 0) -> None:
        self.text_line = text
        self.position = position
        shown = text if len(text) <= 60 else text[:57] + "..."
        super().__init__(f"{message} at column {position + 1}: {shown!r}")


class TooManyStepsError(MotorError):
    """A bank upload beyond the step/command limit (error02)."""

    number = 2


class NotAllowedInBankError(MotorError):
    """A command that cannot be defined in a bank (error03)."""

    number = 3


class CannotFollowError(MotorError):
    """A command that cannot be followed by another (error04)."""

    number = 4


class NoProgramBankError(MotorError):
    """The program bank does not exist (error05)."""

    number = 5


class NoLadderBankError(MotorError):
    """The ladder bank does not exist (error06)."""

    number = 6


class CwLimitError(MotorError):
    """The CW limit sensor is on (error07)."""

    number = 7


class CcwLimitError(MotorError):
    """The CCW limit sensor is on (error08)."""

    number = 8


class InvalidArgumentError(CoolMuscleError, ValueError):
    """A call the host library refuses before sending anything (a motor ID outside
    1..15, an unknown register, K20 through ``write_param``)."""


class NoSuchMotorError(CoolMuscleError, LookupError):
    """A motor ID that is not on the chain."""


class StoreError(CoolMuscleError, OSError):
    """The persistent store could not be read or written."""


class DamagedStoreError(StoreError):
    """The store file is damaged or not a coolmuscle store at all: nothing in it can be
    read, so it can only be moved aside (``coolmuscle sim --reset`` does that).
    ``problem`` says what is wrong with it, without the file's name."""

    def __init__(self, message: str, *, problem: str = "") -> None:
        super().__init__(message)
        self.problem = problem


class TransportError(CoolMuscleError, OSError):
    """A byte transport (TCP, pty, serial) failed or was misconfigured."""


class CoolMuscleTimeout(CoolMuscleError, TimeoutError):
    """A wait for the motor ran out of time (host library)."""


class AlarmError(CoolMuscleError):
    """The motor raised an alarm; ``status`` is the Ux value (6.6 ?99)."""

    def __init__(self, status: int, message: str = "") -> None:
        self.status = status
        super().__init__(message or f"motor alarm Ux={status}")

    @property
    def flags(self) -> object:
        """The Ux value decoded (:class:`coolmuscle.motor.status.Ux`)."""
        return alarm_flags(self.status)


class ProtocolError(CoolMuscleError):
    """A reply from the motor that could not be understood (host library)."""


# -- host library (coolmuscle.client) ------------------------------------------

class MotionInterruptedError(CoolMuscleError):
    """A wait for in-position ended because the motor stopped trying: an emergency
    stop (Ux=512) or motor free (Ux=16) (6.6 ?99); ``status`` is that Ux value."""

    def __init__(self, status: int, message: str = "") -> None:
        self.status = status
        super().__init__(message or f"motion interrupted: Ux={status}")


def alarm_flags(status: int) -> object:
    """The Ux value decoded as :class:`coolmuscle.motor.status.Ux` flags (6.6 ?99)."""
    from .motor.status import Ux
    return Ux(status)


#: errorNN number -> the exception class the motor's message stands for (K23 16).
MOTOR_ERROR_CLASSES: dict[int, type[MotorError]] = {
    cls.number: cls for cls in (
        OutOfRangeError, CmlSyntaxError, TooManyStepsError, NotAllowedInBankError,
        CannotFollowError, NoProgramBankError, NoLadderBankError, CwLimitError,
        CcwLimitError)
}


def motor_error(number: int, text: str, motor: int | None = None) -> MotorError:
    """The exception for a reported ``errorNN.n: text`` line (ch. 3 K23 function 16).

    ``motor`` is the ID that reported it (kept as ``.motor``); an unknown number
    gives a plain :class:`MotorError` carrying that number.
    """
    cls = MOTOR_ERROR_CLASSES.get(number, MotorError)
    shown = f"error{number:02d}" + (f".{motor}" if motor is not None else "") + f": {text}"
    error = cls.__new__(cls)
    MotorError.__init__(error, shown)  # the motor's own words, not the class's template
    if isinstance(error, CmlSyntaxError):
        error.text_line, error.position = "", 0
    error.number = number
    error.motor = motor  # type: ignore[attr-defined]
    return error
