"""Several motors in one program bank (cml-users-guide.txt 4.3.1, 4.3.2), read off the trace.

The programs of the golden transcripts tests/transcripts/4.3*.cml run on a two-motor
chain with the trace recorder on: each motion ends exactly on its P data, a line starts
only when every motor the line before moved is in position (4.3.1), ``Y`` lets the next
line start at once, and a series of ``Y`` completes each motion but the last (4.3.2).
"""

from __future__ import annotations

from typing import Any

from bank_support import Rig, rig
from coolmuscle.tools.trace.recorder import record

DATA = ("P1.1=2500", "S1.1=200", "A1.1=100", "P1.2=1000", "S1.2=100", "A1.2=50",
        "P2.1=1000", "P2.2=2000", "P3.1=3000")


def motions(r: Rig, motor_id: int) -> list[tuple[int, int, float]]:
    """(start ns, end ns, target) of every planned motion of ``motor_id``."""
    return [(t, p.end_ns, p.final_position)
            for t, p, *_ in r.motor(motor_id).axis.history if p.segments]


def in_position(r: Rig, motor_id: int) -> list[int]:
    return r.times(f"Ux.{motor_id}=8")


def check_exact_and_within_s(r: Rig, recorder: Any, motor_id: int, s_pps: float) -> None:
    for _, profile, motion, zero, sign in r.motor(motor_id).axis.history:
        if profile.segments:                          # each motion's command ends on P
            assert abs(sign * (motion.command_at(profile.end_ns) - zero)
                       - profile.final_position) < 1e-6
    for start, end, _target in motions(r, motor_id):
        for i in range(201):
            t = start + (end - start) * i // 200
            assert abs(recorder.sample(motor_id, t).speed) <= s_pps * (1 + 1e-9)


def test_4_3_1_each_line_starts_when_both_motors_are_in_position() -> None:
    r = rig(*DATA, motors=2)
    recorder = record(r.chain)
    r.type("B1.1", "A1.1, S1.1, P1.1, A1.2, S1.2, P1.2", "P2.1, P2.2", "P3.1", "END", "[1.1")
    r.until(3)
    m1, m2 = motions(r, 1), motions(r, 2)
    assert [target for *_, target in m1] == [2500, 1000, 3000]
    assert [target for *_, target in m2] == [1000, 2000]
    assert m1[0][0] == m2[0][0]                        # line 2: together
    line2_done = max(in_position(r, 1)[0], in_position(r, 2)[0])
    assert in_position(r, 1)[0] != in_position(r, 2)[0]  # one motor waited for the other
    assert m1[1][0] == m2[1][0] == line2_done          # line 3: when both are in position
    line3_done = max(in_position(r, 1)[1], in_position(r, 2)[1])
    assert m1[2][0] == line3_done                      # line 4 waits for both as well
    check_exact_and_within_s(r, recorder, 1, 200 * 100)
    check_exact_and_within_s(r, recorder, 2, 100 * 100)
    r.wait(0.5)
    assert r.chain.execute("?96.1") == ["Px.1=3000"] and r.chain.execute("?96.2") == ["Px.2=2000"]


def test_4_3_2_y_lets_the_next_line_start_at_once() -> None:
    r = rig(*DATA[:-2], "P2.2=20000", "P3.1=3000", motors=2)
    recorder = record(r.chain)
    r.type("B2.1", "A1.1, S1.1, P1.1, A1.2, S1.2, P1.2", "P2.1, Y2.2", "P3.1", "END", "[2.1")
    r.until(4)
    m1, m2 = motions(r, 1), motions(r, 2)
    line4 = m1[2][0]
    assert line4 == in_position(r, 1)[1]               # only motor 1 is waited for
    assert line4 < m2[1][1]                            # motor 2 still on its way to P2
    assert recorder.sample(2, line4).speed > 0
    check_exact_and_within_s(r, recorder, 1, 200 * 100)
    check_exact_and_within_s(r, recorder, 2, 100 * 100)


def test_4_3_2_a_series_of_y_completes_each_motion_but_the_last() -> None:
    r = rig("S1.2=100", "A1.2=100", "P1.2=5000", "P2.2=0", "S1.1=100", "A1.1=100",
            "P1.1=1000", motors=2)
    recorder = record(r.chain)
    r.type("B1.1", "S1.2, A1.2, Y1.2", "Y2.2", "S1.1, A1.1, P1.1", "END", "[1.1")
    r.until(3)
    m1, m2 = motions(r, 1), motions(r, 2)
    assert [target for *_, target in m2] == [5000, 0]
    assert m2[1][0] >= in_position(r, 2)[0]           # the first Y completed first
    assert m1[0][0] == m2[1][0]                        # the last Y: line 3 at once
    assert m1[0][1] < m2[1][1]
    check_exact_and_within_s(r, recorder, 2, 100 * 100)
