"""The output functions a K34 digit names, and each firmware's table of them.

A K34 digit selects what an output shows (cml-users-guide.txt ch. 3 K34;
cm1-ethernetip-interface-manual.txt Appendix A K34).  The same digit is not the same
function on every firmware, so the table is part of the firmware profile
(:attr:`coolmuscle.motor.state.firmware.Firmware.output_functions`); the outputs
themselves (:mod:`coolmuscle.motor.signals.io`) evaluate the function it names.
"""

from __future__ import annotations

from typing import Final

# Final: compiled code that asks which function an output has (every fieldbus cycle,
# ?50) compares with the numbers themselves, not with module attributes.
#: Output functions; CM2's K34 digit of each is its number (ch. 3 K34).
OUT_NONE: Final = 0
OUT_IN_POSITION: Final = 1
OUT_ALARM: Final = 2
OUT_GENERAL: Final = 3
OUT_ORIGIN_DONE: Final = 4
OUT_MERGE_PULSE: Final = 6
OUT_ROTATION_PULSE: Final = 7
OUT_MOTOR_FREE: Final = 8
OUT_PUSH: Final = 9
#: Functions of CM1 only (Appendix A K34): "3:CML O1/F1", "4:CML O2/F2" (whichever
#: output it is), "5:Analog Output", "9: Torque Limit reached - Push Mode Only".
OUT_FOLLOWS_O1: Final = 11
OUT_FOLLOWS_O2: Final = 12
OUT_ANALOG: Final = 15
OUT_PUSH_AT_LEVEL: Final = 19

#: K34 digit -> output function, cml-users-guide.txt ch. 3 K34 (5 is "—").
CML_OUTPUT_FUNCTIONS: tuple[int, ...] = (
    OUT_NONE, OUT_IN_POSITION, OUT_ALARM, OUT_GENERAL, OUT_ORIGIN_DONE, OUT_NONE,
    OUT_MERGE_PULSE, OUT_ROTATION_PULSE, OUT_MOTOR_FREE, OUT_PUSH)
#: K34 digit -> output function, cm1-ethernetip-interface-manual.txt Appendix A K34:
#: "0:Command 1:Inposition 2:Alarm 3:CML O1/F1 4:CML O2/F2 5:Analog Output 6:merge
#: motion 7:Quadrature phase output 8: Motor Free 9: Torque Limit reached - Push Mode
#: Only".  "Command" is read as: the output follows the commands O#/F# of its own
#: number (docs/fidelity.md "CM1 profile").
CM1_OUTPUT_FUNCTIONS: tuple[int, ...] = (
    OUT_GENERAL, OUT_IN_POSITION, OUT_ALARM, OUT_FOLLOWS_O1, OUT_FOLLOWS_O2, OUT_ANALOG,
    OUT_MERGE_PULSE, OUT_ROTATION_PULSE, OUT_MOTOR_FREE, OUT_PUSH_AT_LEVEL)
