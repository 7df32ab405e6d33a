"""Interpolation executed by a chain (cml-users-guide.txt 2.1.2 "@", 2.2.2 "N"/"R", 4.4;
cm-banks-rt3.txt 1.1 ";").

The programs of 4.4.1-4.4.3 run as printed on a two-motor chain; the trace recorder
samples the two axes: endpoints exact, every sampled point on the documented arc or line
within 1 pulse (command and actual position), the direction and the major/minor choice
as the text says, and the synthesized path speed never above S.  The expected centres
are worked out here from the manual's numbers, not taken from the model.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest

from bank_support import Rig, enters_window, rig
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record

S_PPS = 100 * 100       # S1 = 100 at the default K37 (100 pps a unit): 10,000 pps
DATA_4_4_1 = ("A1.1=100", "S1.1=100", "P1.1=0", "P2.1=1000", "R1.1=2000",
              "A1.2=100", "S1.2=100", "P1.2=0", "P2.2=1000", "R1.2=2000")
DATA_4_4_2 = ("A1.1=100", "S1.1=100", "P1.1=0", "P2.1=1000", "N1.1=-823",
              "A1.2=100", "S1.2=100", "P1.2=0", "P2.2=1000", "N1.2=1823")
DATA_4_4_3 = ("A1.1=100", "S1.1=100", "P1.1=0", "P2.1=1000", "R1.1=0",
              "A1.2=100", "S1.2=100", "P1.2=0", "P2.2=1000", "R1.2=0")
START_LINE = "A1.1,S1.1,P1.1,A1.2,S1.2,P1.2"


def radius_centres(start: tuple[float, float], end: tuple[float, float],
                   r: float) -> list[tuple[float, float]]:
    """The two centres of circles of radius ``r`` through ``start`` and ``end``."""
    (x0, y0), (x1, y1) = start, end
    d = math.dist(start, end)
    h = math.sqrt(r * r - (d / 2) ** 2)
    mx, my = (x0 + x1) / 2, (y0 + y1) / 2
    ux, uy = (x1 - x0) / d, (y1 - y0) / d
    return [(mx - uy * h, my + ux * h), (mx + uy * h, my - ux * h)]


# 4.4.1: R = 2000 from (0, 0) to (1000, 1000): the centre up-left of the chord is the
# one whose CW way round is the long arc (and whose CCW way is the short one).
CENTRE_4_4_1 = radius_centres((0, 0), (1000, 1000), 2000)[0]


def run_bank(data: tuple[str, ...], *lines: str, motors: int = 2, firmware: str = "cm2",
             until: float = 4.0) -> tuple[Rig, Any]:
    r = rig(*data, motors=motors, firmware=firmware)
    recorder = record(r.chain)
    r.type("B1.1", *lines, "END", "[1.1")
    r.until(until)
    return r, recorder


def path_window(r: Rig, motor_id: int = 1, target: float = 1000.0) -> tuple[int, int]:
    """Start and end (ns) of the motion that took ``motor_id`` to ``target``."""
    for t, profile, *_ in r.motor(motor_id).axis.history:
        if profile.final_position == target and profile.segments:
            return t, profile.end_ns
    raise AssertionError("no such motion in the history")


def samples(recorder: Any, t0: int, t1: int, n: int = 500,
            ids: tuple[int, int] = (1, 2)) -> Iterator[tuple[Any, Any]]:
    for i in range(n + 1):
        t = t0 + (t1 - t0) * i // n
        yield recorder.sample(ids[0], t), recorder.sample(ids[1], t)


def check_on_circle(recorder: Any, t0: int, t1: int, centre: tuple[float, float],
                    radius: float) -> None:
    for a, b in samples(recorder, t0, t1):
        for x, y in ((a.command, b.command), (a.position, b.position)):
            assert abs(math.dist((x, y), centre) - radius) <= 1.0, (a.time, x, y)


def ellipse_distance(x: float, y: float, centre: tuple[float, float], rx: float,
                     ry: float) -> float:
    """Distance (pulses, first order) from (x, y) to the ellipse."""
    dx, dy = x - centre[0], y - centre[1]
    f = (dx / rx) ** 2 + (dy / ry) ** 2 - 1
    grad = math.hypot(2 * dx / rx ** 2, 2 * dy / ry ** 2)
    return abs(f) / grad


def swept_angle(recorder: Any, t0: int, t1: int, centre: tuple[float, float]) -> float:
    """Signed angle the commanded point turns round ``centre`` (CCW positive)."""
    total, last = 0.0, None
    for a, b in samples(recorder, t0, t1, 2000):
        angle = math.atan2(b.command - centre[1], a.command - centre[0])
        if last is not None:
            total += (angle - last + math.pi) % (2 * math.pi) - math.pi
        last = angle
    return total


def check_speed(recorder: Any, t0: int, t1: int, r: Rig, speed: float = S_PPS) -> None:
    """The path speed never above S: the actual speeds in the trace; the commanded
    axis speeds follow the planned path speed within interp.MAX_SPEED_ERROR (1e-4)."""
    ax, ay = r.motor(1).axis, r.motor(2).axis
    for a, b in samples(recorder, t0, t1, 2000):
        assert math.hypot(a.speed, b.speed) <= speed * (1 + 1e-9)
        cmd = math.hypot(_command_velocity(ax, a.time), _command_velocity(ay, a.time))
        assert cmd <= speed * (1 + 1e-4), a.time


def _command_velocity(axis: Any, t: int) -> float:
    profile = [p for start, p, *_ in axis.history if start <= t][-1]
    return profile.velocity_at(t)


def check_end(r: Rig, x: int = 1000, y: int = 1000) -> None:
    r.wait(0.5)
    assert r.chain.execute("?96.1") == [f"Px.1={x}"]
    assert r.chain.execute("?96.2") == [f"Px.2={y}"]
    assert r.motor(1).axis.target() == x and r.motor(2).axis.target() == y


# ------------------------------------------------------------------ 4.4.1

def test_4_4_1_program_1_long_arc_clockwise_with_radius_r1() -> None:
    """B1.1: ``R1.1,R1.2,@2.2+,@2.1+`` "Draw a long arc in the CW direction with Radius R1"."""
    r, recorder = run_bank(DATA_4_4_1, START_LINE, "R1.1,R1.2,@2.2+,@2.1+")
    t0, t1 = path_window(r)
    assert path_window(r, 2) == (t0, t1)               # both axes start and end together
    assert recorder.sample(1, t1).target == 1000.0 and recorder.sample(2, t1).target == 1000.0
    assert all(abs(recorder.sample(m, t1).command - 1000.0) < 1e-6 for m in (1, 2))
    check_on_circle(recorder, t0, t1, CENTRE_4_4_1, 2000)
    angle = swept_angle(recorder, t0, t1, CENTRE_4_4_1)
    chord_angle = 2 * math.asin(math.dist((0, 0), (1000, 1000)) / 2 / 2000)
    assert angle < 0                                    # clockwise
    assert angle == pytest.approx(-(2 * math.pi - chord_angle), abs=1e-3)   # the long arc
    check_speed(recorder, t0, t1, r)
    # ch. 3 K55: each motor is in position when it is within 5 pulses of its own target
    # (the axes approach their ends at different speeds: not at one instant)
    assert all(enters_window(recorder, m, r.times(f"Ux.{m}=8")[-1], 1000) for m in (1, 2))
    check_end(r)


def test_4_4_1_program_2_short_arc_counterclockwise() -> None:
    """B2.1: ``R1.1-,R1.2-,@2.2-,@2.1-`` "Draw a short arc in the CCW direction"."""
    r, recorder = run_bank(DATA_4_4_1, START_LINE, "R1.1-,R1.2-,@2.2-,@2.1-")
    t0, t1 = path_window(r)
    check_on_circle(recorder, t0, t1, CENTRE_4_4_1, 2000)
    angle = swept_angle(recorder, t0, t1, CENTRE_4_4_1)
    assert angle == pytest.approx(2 * math.asin(math.dist((0, 0), (1000, 1000)) / 4000),
                                  abs=1e-3)            # CCW, the short arc
    check_speed(recorder, t0, t1, r)
    check_end(r)


def test_4_4_1_other_two_trajectories_and_negative_radius() -> None:
    """The four trajectories of 4.4.1: long CCW and short CW use the other centre; a
    negative R without modifier is the short arc (2.2.2 "R")."""
    other = radius_centres((0, 0), (1000, 1000), 2000)[1]
    r, recorder = run_bank(DATA_4_4_1, START_LINE, "R1.1,R1.2,@2.2-,@2.1-")
    t0, t1 = path_window(r)
    check_on_circle(recorder, t0, t1, other, 2000)
    assert swept_angle(recorder, t0, t1, other) > math.pi
    data = tuple(d.replace("R1.1=2000", "R1.1=-2000").replace("R1.2=2000", "R1.2=-2000")
                 for d in DATA_4_4_1)
    r, recorder = run_bank(data, START_LINE, "R1.1,R1.2,@2.2+,@2.1+")
    t0, t1 = path_window(r)
    check_on_circle(recorder, t0, t1, other, 2000)
    assert -math.pi < swept_angle(recorder, t0, t1, other) < 0
    check_end(r)


# ------------------------------------------------------------------ 4.4.2

CENTRE_4_4_2 = (-823.0, 1823.0)
RADIUS_4_4_2 = math.hypot(823, 1823)


@pytest.mark.parametrize("modifier, long_way", [("+", True), ("-", False)])
def test_4_4_2_centre_n1_clockwise_and_counterclockwise(modifier: str, long_way: bool) -> None:
    """B1.1 / B2.1 of 4.4.2: ``N1.1,N1.2,@2.2±,@2.1±`` round N = (-823, 1823); ``+`` is
    CW (the table of 4.4.2), which from this start is the long way round."""
    r, recorder = run_bank(DATA_4_4_2, "A1.1, S1.1, P1.1, A1.2, S1.2, P1.2",
                           f"N1.1, N1.2, @2.2{modifier}, @2.1{modifier}")
    t0, t1 = path_window(r)
    check_on_circle(recorder, t0, t1, CENTRE_4_4_2, RADIUS_4_4_2)
    angle = swept_angle(recorder, t0, t1, CENTRE_4_4_2)
    assert (angle < 0) == (modifier == "+")
    assert (abs(angle) > math.pi) == long_way
    check_speed(recorder, t0, t1, r)
    check_end(r)


# ------------------------------------------------------------------ 4.4.3

def test_4_4_3_radius_zero_draws_the_line() -> None:
    r, recorder = run_bank(DATA_4_4_3, START_LINE, "R1.1,R1.2,@2.2,@2.1")
    t0, t1 = path_window(r)
    last = -1.0
    for a, b in samples(recorder, t0, t1):
        assert abs(a.command - b.command) <= 1.0 and abs(a.position - b.position) <= 1.0
        assert a.command >= last
        last = a.command
    check_speed(recorder, t0, t1, r)
    # 1414.2 pulses at 10,000 pps with 100 kpps² up and down: L / S + S / A
    assert (t1 - t0) / 1e9 == pytest.approx(math.hypot(1000, 1000) / S_PPS + 0.1, abs=1e-6)
    check_end(r)


def test_4_4_3_modifiers_do_not_change_the_line() -> None:
    r, recorder = run_bank(DATA_4_4_3, START_LINE, "R1.1-,R1.2-,@2.2-,@2.1-")
    t0, t1 = path_window(r)
    assert all(abs(a.command - b.command) <= 1.0 for a, b in samples(recorder, t0, t1))


# ------------------------------------------------------------------ lines and merges

def test_4_4_the_next_line_waits_for_both_motors() -> None:
    r, recorder = run_bank(DATA_4_4_1 + ("P3.1=3000",), START_LINE, "R1.1,R1.2,@2.2+,@2.1+",
                           "P3.1")
    _, t1 = path_window(r)
    start3, _ = path_window(r, 1, 3000.0)
    # the next line waits for both motors in position (ch. 3 K55: within K55 of the
    # target, which may come a little before the path's command ends)
    assert start3 >= max(r.times("Ux.1=8")[1], r.times("Ux.2=8")[1]) >= t1 - seconds(0.02)


def test_p_after_at_on_the_same_line_waits_for_the_path() -> None:
    r, recorder = run_bank(DATA_4_4_3 + ("P3.1=3000",), START_LINE, "R1.1,R1.2,@2.1,@2.2,P3.1")
    _, t1 = path_window(r)
    start3, _ = path_window(r, 1, 3000.0)
    assert start3 >= r.times("Ux.2=8")[-1] >= t1 - seconds(0.02)
    check_end(r, 3000, 1000)


def test_rt3_1_1_semicolon_merges_two_interpolations() -> None:
    """RT3 1.1 "r2.1,r2.2,@1.2,@1.1; r1.1,r1.2,@2.2,@1.1": a line to (P1.1, P1.2), then an
    arc to (P1.1, P2.2), without stopping at the junction."""
    data = ("S1.1=100", "A1.1=100", "S1.2=100", "A1.2=100", "P1.1=2000", "P1.2=0",
            "P2.2=2000", "R1.1=1000", "R1.2=1000", "R2.1=0", "R2.2=0")
    r, recorder = run_bank(data, "S1.1,A1.1,S1.2,A1.2",
                           "r2.1,r2.2,@1.2,@1.1; r1.1,r1.2,@2.2,@1.1", firmware="rt3")
    t0, t1 = path_window(r, 2, 2000.0)
    assert recorder.sample(1, t1).target == 2000.0 and recorder.sample(2, t1).target == 2000.0
    assert all(abs(recorder.sample(m, t1).command - 2000.0) < 1e-6 for m in (1, 2))
    # the junction (2000, 0) is passed at speed: no stop between the two @ pairs
    hist = r.motor(1).axis.history
    profile = [p for start, p, *_ in hist if start == t0][0]
    junction = profile.first_crossing(1999.5, t0)
    assert junction is not None
    a = recorder.sample(1, junction)
    b = recorder.sample(2, junction)
    assert math.hypot(a.speed, b.speed) > 0.5 * S_PPS
    # the arc part: R = 1000 from (2000, 0) to (2000, 2000) is a half circle round (2000, 1000)
    for a, b in samples(recorder, junction + seconds(0.01), t1):
        assert abs(math.dist((a.command, b.command), (2000, 1000)) - 1000) <= 1.0
    assert all(enters_window(recorder, m, r.times(f"Ux.{m}=8")[-1], 2000) for m in (1, 2))


def test_several_pairs_on_one_line_run_together() -> None:
    data = DATA_4_4_1 + tuple(d.replace(".1=", ".3=").replace(".2=", ".4=") for d in DATA_4_4_1)
    r, recorder = run_bank(data, START_LINE + ",A1.3,S1.3,P1.3,A1.4,S1.4,P1.4",
                           "R1.1,R1.2,R1.3-,R1.4-,@2.1+,@2.2+,@2.3-,@2.4-", motors=4)
    t0, t1 = path_window(r, 1)
    u0, u1 = path_window(r, 3)
    assert t0 == u0
    check_on_circle(recorder, t0, t1, CENTRE_4_4_1, 2000)
    for a, b in samples(recorder, u0, u1, 200, ids=(3, 4)):
        assert abs(math.dist((a.command, b.command), CENTRE_4_4_1) - 2000) <= 1.0
    assert abs(swept_angle(recorder, t0, t1, CENTRE_4_4_1)) > math.pi


def test_pause_stops_along_the_arc_and_resume_finishes_it() -> None:
    r = rig(*DATA_4_4_1, motors=2)
    recorder = record(r.chain)
    r.type("B1.1", START_LINE, "R1.1,R1.2,@2.2+,@2.1+", "END", "[1.1")
    r.until(0.4)
    r.type("]")
    r.wait(0.5)
    assert r.motor(1).status == 8 and r.motor(2).status == 8
    stopped = (r.motor(1).position(), r.motor(2).position())
    assert abs(math.dist(stopped, CENTRE_4_4_1) - 2000) <= 1.0
    r.type("[")
    r.wait(2)
    check_on_circle(recorder, recorder.start, r.kernel.now, CENTRE_4_4_1, 2000)
    check_end(r)


# ------------------------------------------------------------------ direct mode

def test_2_1_2_direct_mode_at_with_r0_and_n0() -> None:
    """``@.1+, @.2+`` toward P0 with R0 (2.1.2 example), then with N0 (written last)."""
    r = rig("S.1=100", "A.1=100", "P.1=1000", "P.2=1000", "R.1=2000", "R.2=2000", motors=2)
    recorder = record(r.chain)
    r.type("@.1+, @.2+")
    r.wait(2)
    check_on_circle(recorder, 0, r.kernel.now, CENTRE_4_4_1, 2000)
    check_end(r)
    r.type("P.1=0", "P.2=0", "N.1=-823", "N.2=1823")
    t0 = r.kernel.now
    r.type("@.1-, @.2-")
    r.wait(2)
    check_on_circle(recorder, t0, r.kernel.now, CENTRE_4_4_2, RADIUS_4_4_2)
    # CCW from (1000, 1000) back to (0, 0) round this centre is the long way round
    assert swept_angle(recorder, t0, r.kernel.now, CENTRE_4_4_2) > math.pi
    check_end(r, 0, 0)


def test_at_without_an_adjacent_partner_is_error00_and_moves_nothing() -> None:
    r = rig("K23.2=25", "K23.3=25", "S.1=100", "A.1=100", "P.1=1000", "P.3=1000",
            "P.2=1000", motors=3)
    r.type("@.1+, @.3+")
    r.type("@.2+")
    r.wait(1)
    assert r.texts() == ["error00.1: Out Of Range!!", "error00.3: Out Of Range!!",
                         "error00.2: Out Of Range!!"]
    assert [r.motor(i).position() for i in (1, 2, 3)] == [0, 0, 0]


def test_non_adjacent_pair_in_a_bank_is_error00() -> None:
    r, _ = run_bank(("K23.3=25",) + DATA_4_4_1
                    + tuple(d.replace(".2=", ".3=") for d in DATA_4_4_1[5:]),
                    "R1.1,R1.3,@2.1+,@2.3+", motors=3, until=1)
    assert "error00.1: Out Of Range!!" in r.texts() and "error00.3: Out Of Range!!" in r.texts()
    assert r.motor(1).position() == 0 and r.motor(3).position() == 0
    assert r.motor(1).program.state == "idle"     # the line did not hang


def test_at_needs_the_r_type() -> None:
    r = rig("K23.2=25", "S.1=100", "A.1=100", "P.1=1000", "P.2=1000", motors=2,
            firmware="cm1")
    r.type("@.1+, @.2+")
    r.wait(1)
    assert r.texts() == ["error00.1: Out Of Range!!", "error00.2: Out Of Range!!"]


# ------------------------------------------------------------------ shapes

def test_different_radii_draw_an_oval() -> None:
    data = ("S1.1=100", "A1.1=100", "P1.1=3000", "P1.2=1000", "R1.1=3000", "R1.2=1000")
    r, recorder = run_bank(data, "S1.1,A1.1,R1.1-,R1.2-,@1.1-,@1.2-")
    t0, t1 = path_window(r, 1, 3000.0)
    # the ovals with semi-axes 3000 x 1000 through (0,0) and (3000,1000) are centred on
    # (3000, 0) and (0, 1000); CCW the short way is a quarter round (0, 1000)
    for a, b in samples(recorder, t0, t1):
        for x, y in ((a.command, b.command), (a.position, b.position)):
            assert ellipse_distance(x, y, (0, 1000), 3000, 1000) <= 1.0, (x, y)
    assert all(a.command > -0.05 and b.command > -0.05 for a, b in samples(recorder, t0, t1))
    check_speed(recorder, t0, t1, r)
    check_end(r, 3000, 1000)


def test_centre_not_equidistant_ends_exactly_at_p() -> None:
    data = ("S1.1=100", "A1.1=100", "P1.1=1000", "P1.2=0", "N1.1=500", "N1.2=0")
    r, recorder = run_bank(data + ("P1.1=1100",), "S1.1,A1.1,N1.1,N1.2,@1.1-,@1.2-")
    t0, t1 = path_window(r, 1, 1100.0)
    radii = [math.dist((a.command, b.command), (500, 0)) for a, b in samples(recorder, t0, t1)]
    assert radii[0] == pytest.approx(500) and radii[-1] == pytest.approx(600)
    assert all(x <= y + 1e-6 for x, y in zip(radii, radii[1:]))   # grows evenly, no jump
    check_end(r, 1100, 0)


def test_chord_longer_than_twice_the_radius_is_a_half_circle() -> None:
    data = ("S1.1=100", "A1.1=100", "P1.1=2000", "P1.2=0", "R1.1=100", "R1.2=100")
    r, recorder = run_bank(data, "S1.1,A1.1,R1.1,R1.2,@1.1+,@1.2+")
    t0, t1 = path_window(r, 1, 2000.0)
    for a, b in samples(recorder, t0, t1):
        assert abs(math.dist((a.command, b.command), (1000, 0)) - 1000) <= 1.0
    check_end(r, 2000, 0)


def test_6_5_at_in_a_ladder_bank_pairs_within_the_scan() -> None:
    """6.5 marks ``@`` usable in ladder banks: the pair of one scan starts a path from
    the direct data (R0 = 0: a line); later scans leave the running path alone."""
    r = rig("K63.1=10", "S.1=100", "A.1=100", "P.1=1000", "P.2=500", "R.1=0", "R.2=0",
            motors=2)
    recorder = record(r.chain)
    r.type("L1.1", "@.1+, @.2+", "END", "[L1.1")
    r.wait(1)
    r.type("]L.1", "]L.1")
    t0, t1 = path_window(r, 1, 1000.0)
    assert path_window(r, 2, 500.0) == (t0, t1)
    # once in position (K55) a scan may issue the pair again: it only re-plans the last
    # pulses to the same end, never a second path
    again = [(t, p) for t, p, *_ in r.motor(1).axis.history if p.segments][1:]
    assert all(t >= r.times("Ux.1=8")[0] and p.final_position == 1000.0 and
               p.duration < 0.01 for t, p in again)
    for a, b in samples(recorder, t0, t1):
        assert abs(a.command - 2 * b.command) <= 1.0
    check_end(r, 1000, 500)


def test_two_pairs_each_merge_their_legs_across_semicolon() -> None:
    """Two pairs on one line joined by ``;`` to a second line: each pair's two legs are
    one path (4.4 merge "during even at the interpolation"), the pairs run side by side."""
    data = ("S1.1=100", "A1.1=100", "S1.3=100", "A1.3=100",
        "P1.1=1000", "P1.2=0", "P2.1=1000", "P2.2=1000", "R1.1=0", "R1.2=0",
        "P1.3=1000", "P1.4=0", "P2.3=1000", "P2.4=1000", "R1.3=0", "R1.4=0")
    r, recorder = run_bank(data, "S1.1,A1.1,S1.3,A1.3",
                           "R1.1,R1.2,R1.3,R1.4,@1.1,@1.2,@1.3,@1.4;",
                           "@2.1,@2.2,@2.3,@2.4", motors=4)
    for x_id, y_id in ((1, 2), (3, 4)):
        hist = [(t, p) for t, p, *_ in r.motor(y_id).axis.history if p.segments]
        assert len({t for t, _ in hist}) == 1    # one path (the second leg re-planned
        t0, profile = hist[-1]                   # it at once): no stop at (1000, 0)
        corner = profile.first_crossing(500.0, t0)
        assert corner is not None and recorder.sample(x_id, corner).command == pytest.approx(
            1000, abs=1.0)
        assert math.hypot(recorder.sample(x_id, corner).speed,
                          recorder.sample(y_id, corner).speed) > 1000
    assert r.motor(1).axis.history[-1][0] == r.motor(3).axis.history[-1][0]
    check_end(r, 1000, 1000)
    assert r.chain.execute("?96.3") == ["Px.3=1000"] and r.chain.execute("?96.4") == ["Px.4=1000"]


def test_a_path_ending_beyond_a_software_limit_moves_neither_motor() -> None:
    """ch. 3 K58/K59 software limits: a move is clamped to them; a path cannot be, so a
    path whose end lies beyond them on either motor is not started at all."""
    r = rig("K58.2=5", "S.1=100", "A.1=100", "P.1=1000", "P.2=1000", "R.1=0", "R.2=0",
            motors=2)
    r.type("@.1, @.2")
    r.wait(1)
    assert [r.motor(m).position() for m in (1, 2)] == [0, 0]
    r.type("P.2=400", "@.1, @.2")
    r.wait(1)
    check_end(r, 1000, 400)
