"""The K-parameter catalogue: what each K means, with its unit, range, factory value and
the firmware it exists on (cml-users-guide.txt ch. 3 and table 6.1; cm-banks-rt3.txt
3.5; cm1-ethernetip-interface-manual.txt Appendix A).

The numbers (name, unit, min, max, default, how a value is checked) are the firmware
tables' :class:`~.params.ParamSpec` (:mod:`.firmware`), not repeated here: this module
adds what the manuals say a parameter does, in a line, and answers the questions a
tool asks of a K (``coolmuscle params diff``, a backup's check, a parameter editor):

* :func:`k_parameter` ``(firmware, k)`` -> :class:`KParameter`: meaning, unit, range
  text, factory value, whether this firmware defines it, :meth:`KParameter.problem`
  with a value;
* :func:`catalogue` ``(firmware)``: K20..K89 in order;
* :func:`defined_on` ``(k)``: the firmware that define K``k``;
  :func:`same_parameter` whether K``k`` is the same parameter on two firmware (K85 is
  the Modbus endian on CM2 and the power-up logic bank on RT3).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache

from .firmware import FIRMWARES, Firmware, get_firmware
from .params import FIRST_K, LAST_K, ParamSpec

__all__ = ["KParameter", "k_parameter", "catalogue", "defined_on", "same_parameter"]

_INPUT_EDGE = ("0 none, 1 alarm reset / pause, 2 {two}, 3 position counter reset, 4 next "
               "bank line, 5 previous bank line, 6 program bank 1, 7 origin search, 8 jog "
               "CW, 9 jog CCW (8, 9: banks 2, 3 when K36 is 2 or 3)")
_INPUT_LEVEL = ("0 none, 1 general use, 2 origin sensor, 3 manual feed CW, 4 manual feed "
                "CCW, 5 stop the ladder bank, 6 CW limit, 7 emergency stop, 8 terminate "
                "the program bank, 9 CCW limit")
_RATES = "0 38.4 kbps, 1 9.6 kbps, 2 19.2 kbps, 3 57.6 kbps, 4 115.2 kbps, 5 230.4 kbps"

#: Table 6.1 (CM2), in a line each.
_CM2: dict[int, str] = {
    20: f"Baud rate between the motor and the host: {_RATES}; the host must be set to "
        "match (ch. 3 K20).",
    23: "Status report, a sum of: 1 in-position and alarm reports, 2 input changes, "
        "4 output changes, 8 no local echo, 16 confirmation and error messages.",
    24: "Rotation pulse output: an output (K34=7) turns on and off every this many "
        "pulses; quadrature when outputs 1 and 2 are both 7.",
    25: "Delay time of the slow response signal, a digit per input (6 5 4 3 2 1).",
    26: "Input logic, a digit per input: 0 or 2 on when the port is on, 1 or 3 on when "
        "it is off; 2 or 3 enable the pulse input (P type operation).",
    27: f"Input function at the quick response target level, a digit per input: "
        f"{_INPUT_LEVEL}.",
    28: "Input function at the rising edge of the quick response signal, a digit per "
        "input: " + _INPUT_EDGE.format(two="motor free") + ".",
    29: "Input function at the falling edge of the quick response signal, a digit per "
        "input: " + _INPUT_EDGE.format(two="enable the motor") + ".",
    30: "Input function at the slow response target level, a digit per input: as K27 "
        "(2 not used).",
    31: "Input function at the rising edge of the slow response signal, a digit per "
        "input: as K28.",
    32: "Input function at the falling edge of the slow response signal, a digit per "
        "input: as K29.",
    33: "Output logic, a digit per output (4 3 2 1): 0 the port is on when the signal is "
        "off, 1 on when it is on.",
    34: "Output function, a digit per output: 0 none, 1 in-position, 2 alarm, 3 general "
        "use, 4 origin search done, 6 in-position in merge motion, 7 rotation pulses "
        "(K24), 8 motor free, 9 push motion.",
    35: "Analog output: 0 target position, 2 current position, 4 position error, "
        "6 current speed, 8 current torque; the odd values magnified by 8.",
    36: "Command pulse format (P type): 0 or 2 CW/CCW, 1 or 3 pulse/direction; 2 and 3 "
        "also let inputs start program banks 2 and 3.",
    37: "Resolution (pulses per rotation) and speed unit: 0-10 100 pps, 20-30 10 pps, "
        "80-90 1 pps (200 to 50000 pulses); 40-70 other resolutions, no incremental "
        "motion.",
    38: "Analog input control: 0 none, 1 position, 2 speed CW, 3 speed CCW, 4 speed "
        "CW/CCW, 5 P of direct mode, 6-8 S of direct mode (+, -, +/-), 9 torque, "
        "10 torque feedback.",
    39: "Cut-off frequency of the analog input's low pass filter.",
    40: "Maximum speed; in analog speed control, the speed at the maximum voltage.",
    41: "Travel range of position control with the analog input.",
    42: "Origin search speed.",
    43: "Acceleration of origin search and manual feed.",
    44: "Deceleration as a percentage of the acceleration (100: the same).",
    45: "Ones digit: origin search direction and coordinates (0 CW, 1 CCW, 2 CW "
        "reversed, 3 CCW reversed); tens: unit of K48, hundreds: unit of K58 and K59 "
        "(0 100, 1 10, 2 1 pulse).",
    46: "Origin signal: 0 stopper, 2 origin sensor, 4 Z phase, 6 origin sensor and Z "
        "phase; the odd values also search at power-on.",
    47: "Torque at which origin search detects the stopper, % of the rated torque.",
    48: "Offset from the mechanical to the electrical origin (unit: K45 tens digit); "
        "0: the same point.",
    49: "Manual feed speed.",
    50: "Pulses of one manual jog.",
    51: "Creeping speed.",
    55: "In-position range.",
    56: "Position error overflow alarm threshold.",
    57: "Time in overload before the overload alarm.",
    58: "Software limit in the + direction from the origin (unit: K45 hundreds digit); "
        "0: none.",
    59: "Software limit in the - direction from the origin; 0: none.",
    60: "Push motion torque, % of the rated torque; an odd value never gives a push "
        "motion error.",
    61: "Push motion holding time; 0: push without end.",
    62: "Ladder bank run at power-on; 0: none.",
    63: "Ladder bank execution cycle time; 0: the ladder bank is not run.",
    64: "Status LED: 0 on, 1 off.",
    65: f"Baud rate between the motors of the daisy chain: {_RATES}; ID1's value is "
        "copied to every motor.",
    68: "At power-on: 0 motor free, 1 servo on.",
    69: "S-curve gain of positioning; 0: trapezoidal motion.",
    70: "Line end of what the motor sends: 0 CR, 1 CR LF.",
    71: "External encoder: 0 none, 1-3 index, 4 feedback, 5-7 pulse counting.",
    72: "Resolution of the external encoder.",
    73: "Output pulse width at a passing point of merge motion.",
    74: "Proportional gain of torque control with an external torque sensor.",
    75: "Integral gain of torque control with an external torque sensor.",
    76: "Input offset voltage of the external torque sensor.",
    77: "Input range of the external torque sensor.",
    78: "Input address for Modbus host communication (COM1).",
    79: "Input address for Modbus slave communication.",
    80: "Output address for Modbus slave communication.",
    81: "COM0 station address; not 0: COM0 speaks Modbus RTU instead of CML (5.6).",
    82: "Parity: 0 none, 1 even, 2 odd.",
    84: "COM1 mode: 1 Modbus host, 0 or below RS-232C.",
    85: "Modbus byte order of COM0 and COM1: 0 big/big, 1 little/big, 2 big/little, "
        "3 little/little.",
}

#: cm-banks-rt3.txt 3.5: the ladder ("logic") parameters of RT3; the rest as table 6.1.
_RT3: dict[int, str] = {
    **{k: text for k, text in _CM2.items() if k not in (62, 63, 85)},
    85: "Logic bank run at power-on; 0: none (RT3 3.5).",
    87: "Logic bank scanning interval (RT3 3.5).",
}

#: cm1-ethernetip-interface-manual.txt Appendix A.
_CM1: dict[int, str] = {
    21: "Semi or full closed loop: 0 full closed loop, 1-36 vector angle.",
    22: "Time delay of the semi closed loop.",
    23: "Event status, a sum of: 1 alarms and motor status, 2 inputs, 4 outputs, 8 no "
        "echo, 16 warnings and messages, 32 merge events (Mx); 0 polling only.",
    24: "Quadrature output interval (K34).",
    25: "Time delay of the slow signal response.",
    26: "Invert the input signals: 0 no, 1 yes.",
    27: "Input function at logical high, a digit per input (4 3 2 1): 0 none, 1 general "
        "use, 2 origin sensor, 3 manual feed CW, 4 manual feed CCW, 5 index output, 6 CW "
        "limit and origin, 7 emergency stop, 8 full stop, 9 CCW limit and origin.",
    28: "Input function at the rising edge of the quick response signal: 0 none, 1 alarm "
        "reset / pause, 2 motor free, 3 reset counter, 4 next step, 5 previous step, "
        "6 bank 1, 7 go origin, 8 jog CW, 9 jog CCW.",
    29: "Input function at the falling edge of the quick response signal: as K28, "
        "2 enable the motor.",
    30: "Input function at the slow response target level: as K27.",
    31: "Input function at the rising edge of the slow response signal: as K28.",
    32: "Input function at the falling edge of the slow response signal: as K29.",
    33: "Output logic: 0 normally open, 1 normally closed.",
    34: "Output function, a digit per output (2 1): 0 command, 1 in-position, 2 alarm, "
        "3 O1/F1, 4 O2/F2, 5 analog output, 6 merge motion, 7 quadrature, 8 motor free, "
        "9 torque limit reached (push).",
    35: "Analog output: 0 target position, 2 current position, 4 position error, "
        "6 velocity/16, 7 velocity/2, 8 Iq, 9 Iq*8; 1, 3, 5 magnified by 8.",
    36: "Pulse interface: 0 CW/CCW, 1 step/direction; 2 enables banks 2 and 3.",
    37: "Resolution and speed unit: 0-10 100 pps, 20-30 10 pps, 100 50000 pulses; "
        "40-70 other resolutions.",
    38: "Analog interface: 0 speed control, 1 position control.",
    39: "Voltage filter gain.",
    40: "Maximum speed of analog control (at 4.8 V).",
    41: "Travel range of analog control.",
    42: "Go origin speed.",
    43: "Go origin and manual feed acceleration.",
    44: "Deceleration ratio.",
    45: "Origin direction: 0 CW, 1 CCW, 2 CW reversed coordinates, 3 CCW reversed.",
    46: "Origin search: 0 stopper, 2 origin switch, 1 and 3 also at power-up; 16-19 "
        "the same with power-up disabled.",
    47: "Origin stopper voltage level.",
    48: "Offset between the machine and the mechanical origin.",
    49: "Manual feed speed.",
    50: "Manual jog travel distance.",
    51: "Creeping speed.",
    52: "Digital or serial IO 1 and 2: 0 auto detect, 1 serial, 2 digital.",
    54: "Quadrature output offset.",
    55: "In-position tolerance.",
    56: "Position error overflow alarm level.",
    57: "Overload alarm time delay.",
    58: "Software limit (+); 0 off.",
    59: "Software limit (-); 0 off.",
    60: "Push mode current level (of 80 % of full torque).",
    61: "Push time; 30001 pushes without end.",
    63: "External encoder input: 0 none, 1 phase A, 2 phases A and B, 3 Fx and Cx.",
    64: "Analog input function: 0 none, 1 S0, 2 P0, 3 S13, 4 P24, 5 S14, 6 P25, 7 speed, "
        "8 position multiplier, 9 analog control only (K38).",
    66: "Data streaming: 0 none, 1 speed target, 2 position, 3 speed, 4 current Iq, "
        "5 position real, 6 velocity real.",
    67: "Data streaming sample timing.",
    68: "S curve: 0 fixed timing, 1 without timing.",
    69: "S curve gain.",
    70: "Send a line feed after the carriage return: 0 no, 1 yes.",
    71: "Temperature limit.",
    72: "Regeneration voltage return level.",
    73: "Merge motion output signal length.",
    74: "External torque feedback P gain.",
    75: "External torque feedback I gain.",
    77: "External torque feedback mean value.",
    78: "External torque feedback gain.",
    85: "Logic bank started at power-up; 0 none.",
    86: "Coordinated motion, synchronise the motors: 0 off, 1 on.",
    87: "Logic bank scan period.",
    88: "External encoder resolution.",
}

_MEANINGS: Mapping[str, Mapping[int, str]] = {"cm2": _CM2, "rt3": _RT3, "cm1": _CM1}
_SOURCES = {"cm2": "table 6.1", "rt3": "RT3 3.5 / table 6.1", "cm1": "CM1 Appendix A"}


@dataclass(frozen=True, slots=True)
class KParameter:
    """One K parameter of one firmware: its spec (the numbers) and its meaning."""

    firmware: str
    spec: ParamSpec
    meaning: str
    source: str

    @property
    def k(self) -> int:
        return self.spec.k

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def unit(self) -> str:
        return self.spec.unit

    @property
    def default(self) -> int:
        """The factory value (table 6.1 "Default"; docs/fidelity.md where it is silent)."""
        return self.spec.default

    @property
    def defined(self) -> bool:
        """Whether this firmware has the parameter (not a reserved number)."""
        return not self.spec.reserved

    def range_text(self) -> str:
        """The values it takes, as a reader wants them: ``10..50000``, ``000..223 digit by
        digit``, ``one of 0, 1, 2 ...``, ``not defined (reads 0)``."""
        spec = self.spec
        if spec.kind == "reserved":
            return f"not defined (reads {spec.default})"
        if spec.kind == "choice":
            return "one of " + _runs(sorted(spec.choices))
        if spec.kind == "digits":
            width = len(spec.digit_ranges)
            return f"{spec.min:0{width}d}..{spec.max:0{width}d} digit by digit"
        return f"{spec.min}..{spec.max}"

    def problem(self, value: int) -> str | None:
        """Why ``value`` cannot be written (``None``: it can)."""
        if not self.defined:
            return None if value == self.spec.default else \
                f"K{self.k} is not defined on {self.firmware} (it reads {self.spec.default})"
        if self.spec.accepts(value):
            return None
        return f"K{self.k}={value} is out of range ({self.range_text()})"

    def describe(self) -> str:
        """``Rotation Pulse Output (pulses; 10..50000; factory 1000)``."""
        unit = f"{self.unit}; " if self.unit not in ("", "-") else ""
        return f"{self.name} ({unit}{self.range_text()}; factory {self.default})"


def _runs(values: list[int]) -> str:
    """``0..8, 10, 20..28``: consecutive values as a range."""
    runs: list[list[int]] = []
    for value in values:
        if runs and value == runs[-1][-1] + 1:
            runs[-1].append(value)
        else:
            runs.append([value])
    return ", ".join(f"{r[0]}..{r[-1]}" if len(r) > 2 else ", ".join(map(str, r))
                     for r in runs)


def _profile(firmware: str | Firmware) -> Firmware:
    return firmware if isinstance(firmware, Firmware) else get_firmware(firmware)


@cache
def _entries(name: str) -> tuple[KParameter, ...]:
    fw = get_firmware(name)
    meanings = _MEANINGS[fw.name]
    return tuple(KParameter(fw.name, fw.spec(k),
                            meanings.get(k, "") if not fw.spec(k).reserved else "",
                            _SOURCES[fw.name])
                 for k in range(FIRST_K, LAST_K + 1))


def catalogue(firmware: str | Firmware) -> tuple[KParameter, ...]:
    """K20..K89 of ``firmware`` (``cm2``, ``rt3``, ``cm1`` or a profile), in order."""
    fw = _profile(firmware)
    if fw.name not in _MEANINGS:
        raise LookupError(f"no catalogue for firmware {fw.name!r}")
    if fw is FIRMWARES.get(fw.name):
        return _entries(fw.name)
    return tuple(KParameter(fw.name, fw.spec(k), e.meaning, e.source)
                 for k, e in zip(range(FIRST_K, LAST_K + 1), _entries(fw.name)))


def k_parameter(firmware: str | Firmware, k: int) -> KParameter:
    """K``k`` of ``firmware``; ``LookupError`` outside K20..K89 (6.6 ?90)."""
    if isinstance(k, bool) or not isinstance(k, int) or not FIRST_K <= k <= LAST_K:
        raise LookupError(f"K{k} does not exist (K{FIRST_K}..K{LAST_K})")
    return catalogue(firmware)[k - FIRST_K]


def defined_on(k: int) -> tuple[str, ...]:
    """The firmware (``cm2``, ``rt3``, ``cm1``) that define K``k``."""
    return tuple(name for name in FIRMWARES if k_parameter(name, k).defined)


def same_parameter(k: int, a: str | Firmware, b: str | Firmware) -> bool:
    """Whether K``k`` is the same parameter on firmware ``a`` and ``b``: defined on both,
    with the same name, or undefined on both."""
    pa, pb = k_parameter(a, k), k_parameter(b, k)
    if pa.defined != pb.defined:
        return False
    return not pa.defined or pa.name.casefold() == pb.name.casefold()
