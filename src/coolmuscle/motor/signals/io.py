"""Digital inputs and outputs of one motor (cml-users-guide.txt ch. 3 K26, K33, K34; 6.6 ?50, ?70).

Inputs: the electrical level of each input is driven from outside (device API,
machine file); the input *signal* applies the logic of K26 (digit odd = on when the
port is off).  Outputs: each output's *signal* comes from its K34 function (general
use = the ``O``/``F`` commands); the *port* applies the logic of K33 (CM2: 1 = high
active; CM1: 0 = normally open).  ?70 and ?50 report the input signals and the output
ports as hex words.

A K34 digit names an output *function* through the firmware's table
(:mod:`coolmuscle.motor.state.output_functions`): the same digit is not the same
function on CM1 (cm1-ethernetip-interface-manual.txt Appendix A K34).
The input functions (K27–K32) and the output functions other than the commanded
ones are evaluated by the motor, which passes a ``function_signal`` callback.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Final

from ..state.output_functions import (
    CML_OUTPUT_FUNCTIONS,
    OUT_ANALOG,
    OUT_FOLLOWS_O1,
    OUT_FOLLOWS_O2,
    OUT_GENERAL,
    OUT_NONE,
)
from ..state.param_table import ParamTable

#: 10 ** n for the digits a K parameter has (compiled, ``**`` is a generic power call;
#: Final: a compiled module holds it in a static, not a module dictionary lookup a digit).
_POWERS: Final[tuple[int, ...]] = tuple(10 ** n for n in range(12))


def digit(value: int, position: int) -> int:
    """Digit ``position`` (1 = rightmost) of a digit-wise parameter such as K27 or K34."""
    power = _POWERS[position - 1] if 1 <= position <= len(_POWERS) else 10 ** (position - 1)
    if value < 0:               # not abs(): compiled, that is a builtins lookup and a call
        value = -value
    return (value // power) % 10


def _follows(fn: int, number: int) -> int | None:
    """The ``O#``/``F#`` number an output of function ``fn`` follows, or ``None``."""
    if fn == OUT_GENERAL:
        return number
    if fn == OUT_FOLLOWS_O1:
        return 1
    if fn == OUT_FOLLOWS_O2:
        return 2
    return None


class DigitalIO:
    """Input levels, general output states, and the words reported by ?70 / ?50."""

    def __init__(self, inputs: int, outputs: int, params: ParamTable,
                 function_signal: Callable[[int, int], bool] = lambda fn, n: False,
                 functions: Sequence[int] = CML_OUTPUT_FUNCTIONS, one_logic: bool = False,
                 inverting_logic: int = 0) -> None:
        """``functions``: K34 digit -> output function (the firmware's table).
        ``one_logic``: K26 and K33 are one value for every input / output (CM1: "K33
        Output Logic 0:Normally open 1: Normally closed"), not a digit each.
        ``inverting_logic``: the K33 value whose port is the inverse of its signal
        (CM2 0, "Low Active"; CM1 1, "Normally closed")."""
        self.input_count = inputs
        self.output_count = outputs
        #: the motor's K table, read at each word (compiled, a call of the table's own
        #: method: no generic call of a stored callable a fieldbus cycle)
        self._params = params
        self._function_signal = function_signal
        self._functions = tuple(functions)
        self._one_logic = one_logic
        self._inverting_logic = inverting_logic
        self.levels = [False] * (inputs + 1)        # index 1..inputs (electrical)
        self.general = [False] * (outputs + 1)      # O/F state, index 1..outputs
        # K26, K33 and K34 as last decoded, and what they say for each input / output
        # (index 1..): a fieldbus reads the words every cycle, the values seldom change
        self._k26, self._inputs_inverted = -1, [False] * (inputs + 1)
        self._k33, self._outputs_inverted = -1, [False] * (outputs + 1)
        self._k34, self._output_functions = -1, [0] * (outputs + 1)
        self._decode(0, 0, 0)

    def _decode(self, k26: int, k33: int, k34: int) -> None:
        """Decode the digits of K26, K33 and K34 where a value changed (ch. 3)."""
        one = self._one_logic
        if k26 != self._k26:
            self._inputs_inverted = [False] + [
                digit(k26, 1 if one else n) % 2 == 1 for n in range(1, self.input_count + 1)]
            self._k26 = k26
        if k33 != self._k33:
            self._outputs_inverted = [False] + [
                digit(k33, 1 if one else n) == self._inverting_logic
                for n in range(1, self.output_count + 1)]
            self._k33 = k33
        if k34 != self._k34:
            self._output_functions = [0] + [self._functions[digit(k34, n)]
                                            for n in range(1, self.output_count + 1)]
            self._k34 = k34

    # -- inputs -------------------------------------------------------------
    def set_level(self, number: int, on: bool) -> bool:
        """Set the electrical level; returns whether the *signal* changed."""
        if not 1 <= number <= self.input_count:
            raise IndexError(f"input {number} (1..{self.input_count})")
        before = self.input_signal(number)
        self.levels[number] = bool(on)
        return before != self.input_signal(number)

    def input_signal(self, number: int, k26: int | None = None) -> bool:
        """Logical input signal after K26 (ch. 3 K26: 0/2 on when port on, 1/3 inverted),
        K26 now or the value ``k26``."""
        if not 1 <= number <= self.input_count:
            return False
        value = self._params.get(26) if k26 is None else k26
        if value != self._k26:
            self._decode(value, self._k33, self._k34)
        return self.levels[number] != self._inputs_inverted[number]

    def input_word(self) -> int:
        """?70: bit 0 = input 1 (K26 read once: a fieldbus reads the word every cycle)."""
        k26 = self._params.get(26)
        if k26 != self._k26:
            self._decode(k26, self._k33, self._k34)
        levels, inverted = self.levels, self._inputs_inverted
        word = 0
        for n in range(1, self.input_count + 1):      # a loop: compiled, no generator
            if levels[n] != inverted[n]:
                word |= 1 << (n - 1)
        return word

    # -- outputs --------------------------------------------------------------
    def output_function(self, number: int, k34: int | None = None) -> int:
        """The function (``OUT_*``) of output ``number`` by K34 now, or by the K34
        value ``k34`` (a trace's past instant)."""
        value = self._params.get(34) if k34 is None else k34
        if not 1 <= number <= self.output_count:
            return self._functions[digit(value, number)]
        if value != self._k34:
            self._decode(self._k26, self._k33, value)
        return self._output_functions[number]

    def command_of(self, number: int, k34: int | None = None) -> int | None:
        """The ``O#``/``F#`` number output ``number`` follows by K34 (now, or the value
        ``k34``), or ``None``."""
        return _follows(self.output_function(number, k34), number)

    def set_general(self, number: int, on: bool) -> bool:
        """``O#``/``F#``: only outputs whose K34 digit follows command ``number`` change
        (CM2: output ``number`` at general use, 3); the command is ignored otherwise.

        Returns whether an output port changed.
        """
        if not 1 <= number <= self.output_count:
            return False
        followers = [n for n in range(1, self.output_count + 1) if self.command_of(n) == number]
        if not followers:
            return False
        before = [self.output_port(n) for n in followers]
        self.general[number] = bool(on)
        return before != [self.output_port(n) for n in followers]

    def output_signal(self, number: int, k34: int | None = None) -> bool:
        """The signal of output ``number`` by K34 (now, or the value ``k34``)."""
        return self._signal_of(self.output_function(number, k34), number)

    def _signal_of(self, fn: int, number: int) -> bool:
        """The signal of output ``number`` whose function is ``fn``."""
        follows = _follows(fn, number)
        if follows is not None:
            return self.general[follows]
        if fn == OUT_NONE or fn == OUT_ANALOG:      # the analog output: no digital signal
            return False
        return self._function_signal(fn, number)

    def output_port(self, number: int) -> bool:
        """The port state of output ``number`` now (K33 applied)."""
        return self.port_of(number, self.output_signal(number))

    def port_of(self, number: int, signal: bool, k33: int | None = None) -> bool:
        """The port for ``signal`` by K33 now, or by the K33 value ``k33``: CM2 digit 1
        high active, 0 low active (ch. 3 K33); CM1 0 normally open, 1 normally closed
        (Appendix A K33)."""
        value = self._params.get(33) if k33 is None else k33
        if not 1 <= number <= self.output_count:
            return signal != (digit(value, 1 if self._one_logic else number)
                              == self._inverting_logic)
        if value != self._k33:
            self._decode(self._k26, value, self._k34)
        return signal != self._outputs_inverted[number]

    def output_word(self) -> int:
        """?50: bit 0 = output 1 (K33 and K34 read and decoded once: a fieldbus reads
        the word every cycle; each port is :meth:`port_of` of its signal)."""
        k33, k34 = self._params.get(33), self._params.get(34)
        if k33 != self._k33 or k34 != self._k34:
            self._decode(self._k26, k33, k34)
        functions, inverted = self._output_functions, self._outputs_inverted
        word = 0
        for n in range(1, self.output_count + 1):
            if self._signal_of(functions[n], n) != inverted[n]:
                word |= 1 << (n - 1)
        return word
