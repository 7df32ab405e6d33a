"""Chain timing with wire-time pacing (cml-users-guide.txt ch. 3 K20, K65; 1.1).

With pacing on, bytes take 10 bits at the K20 rate on the host line and at the K65 rate
on each link of the chain: a command for ID n reaches it after n-1 hops, its reply
comes back the same way, and the motors a bank line starts start the later the farther
they are, so "when setting a high baud rate, the synchronization will be better" (K65).
K65 written on ID1 is written on every motor; on another ID it changes nothing else.
"""

from __future__ import annotations

import math
from pathlib import Path

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.hostline import byte_time_ns
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory

BT_38400 = byte_time_ns(38400)     # 260,416 ns a byte at the default K20 and K65


def host(chain: Chain) -> list[tuple[int, bytes]]:
    """Everything the host receives, with the instant its last byte arrived."""
    received: list[tuple[int, bytes]] = []
    chain.host_line.add_listener(lambda data: received.append((chain.kernel.now, data)))
    return received


def type_line(chain: Chain, text: str) -> int:
    """Send ``text`` + CR at once; returns when its last byte reached ID1."""
    chain.host_line.feed(text.encode() + b"\r")
    return chain.kernel.now + (len(text) + 1) * BT_38400


def test_ch3_k65_on_id1_is_written_on_every_motor_and_persists(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(motors=3, state_dir=tmp_path)
    chain.execute("K65.1=5")
    assert [chain.get_param(m, 65) for m in (1, 2, 3)] == [5, 5, 5]
    assert chain.links.baud() == 230400
    chain.execute("K65.3=1")            # another ID: only its own value
    assert [chain.get_param(m, 65) for m in (1, 2, 3)] == [5, 5, 1]
    assert chain.links.baud() == 230400  # "the baud rate between slave motors will not be changed"
    chain.close()
    again = make_chain(motors=3, state_dir=tmp_path)
    assert [again.get_param(m, 65) for m in (1, 2, 3)] == [5, 5, 1]
    again.close()


def test_1_1_a_query_for_id_n_takes_n_minus_1_hops_each_way(make_chain: ChainFactory) -> None:
    chain = make_chain(motors=3, pacing=True)
    received = host(chain)
    arrived = type_line(chain, "?96.3")
    chain.kernel.run(until=seconds(1))
    reply = [t for t, data in received if data == b"Px.3=0\r\n"]
    # 2 hops down with the 6 bytes of the line, 2 hops up with the 8 of the reply,
    # then the 8 bytes on the host line at K20
    assert reply == [arrived + 2 * 6 * BT_38400 + 2 * 8 * BT_38400 + 8 * BT_38400]
    chain.execute("K65.1=5")
    received.clear()
    arrived = type_line(chain, "?96.3")
    chain.kernel.run(until=seconds(2))
    fast = byte_time_ns(230400)
    reply = [t for t, data in received if data == b"Px.3=0\r\n"]
    # now the reply reaches ID1 while the echo (7 bytes at K20) still holds the host line
    assert arrived + 2 * 6 * fast + 2 * 8 * fast < arrived + 7 * BT_38400
    assert reply == [arrived + 7 * BT_38400 + 8 * BT_38400]


def test_replies_of_one_line_reach_the_host_in_arrival_order(make_chain: ChainFactory) -> None:
    """``?96.3, ?96.1``: ID1 answers first, though its query comes second on the line."""
    chain = make_chain(motors=3, pacing=True)
    events = []
    chain.subscribe(events.append)
    received = host(chain)
    type_line(chain, "?96.3, ?96.1")
    chain.kernel.run(until=seconds(1))
    lines = [data for _, data in received if data.startswith(b"Px")]
    assert lines == [b"Px.1=0\r\n", b"Px.3=0\r\n"]
    times = [e.time for e in events]
    assert times == sorted(times)


def _bank_start_lags(k65: int) -> tuple[int, int]:
    chain = Chain(motors=3, pacing=True)
    chain.execute(f"K65.1={k65}")
    for motor in (1, 2, 3):
        chain.execute(f"S1.{motor}=100, A1.{motor}=100, P1.{motor}=1000")
    chain.execute("B1.1")
    chain.execute("S1.1, A1.1, P1.1, S1.2, A1.2, P1.2, S1.3, A1.3, P1.3")
    chain.execute("END")
    record(chain)
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(1))
    starts = [next(t for t, p, *_ in chain.motors[m].axis.history
                   if p.final_position == 1000 and p.segments) for m in (1, 2, 3)]
    origins = [next(p.origin_ns for t, p, *_ in chain.motors[m].axis.history
                    if p.final_position == 1000 and p.segments) for m in (1, 2, 3)]
    assert starts[0] == starts[1] == starts[2]     # the line runs at one instant on ID1 ...
    return origins[1] - origins[0], origins[2] - origins[0]   # ... the commands travel


def test_ch3_k65_bank_line_starts_farther_motors_later_and_faster_links_sync_better() -> None:
    """The statements for ID2 ("S1.2, A1.2, P1.2" and separators: 15 bytes) take one hop,
    those for ID3 two; at 230.4 kbps the lags are 6 times shorter than at 38.4 kbps."""
    slow = _bank_start_lags(0)
    fast = _bank_start_lags(5)
    # ID3's message waits on the first link behind ID2's, then takes the second link
    assert slow == (15 * BT_38400, 3 * 15 * BT_38400)
    assert fast == (15 * byte_time_ns(230400), 3 * 15 * byte_time_ns(230400))


def _path_error(k65: int) -> float:
    """Largest distance of the commanded point from the 4.4.1 arc with pacing on."""
    chain = Chain(motors=2, pacing=True)
    chain.execute(f"K65.1={k65}")
    for line in ("A1.1=100", "S1.1=100", "P1.1=0", "P2.1=1000", "R1.1=2000", "A1.2=100",
                 "S1.2=100", "P1.2=0", "P2.2=1000", "R1.2=2000", "B1.1",
                 "S1.1,A1.1,R1.1,R1.2,@2.2+,@2.1+", "END"):
        chain.execute(line)
    recorder = record(chain)
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(2))
    x_origin = [p.origin_ns for _, p, *_ in chain.motors[1].axis.history if p.segments][0]
    y_origin = [p.origin_ns for _, p, *_ in chain.motors[2].axis.history if p.segments][0]
    # "R1.2" and "@2.2+" (with their separators: 11 bytes) travel one hop to ID2
    assert y_origin - x_origin == 11 * byte_time_ns({0: 38400, 1: 9600, 5: 230400}[k65])
    centre = (500 - 1322.8757, 500 + 1322.8757)
    worst = 0.0
    for i in range(1001):
        t = x_origin + seconds(1.3) * i // 1000
        x, y = recorder.sample(1, t).command, recorder.sample(2, t).command
        worst = max(worst, abs(math.dist((x, y), centre) - 2000))
    assert math.dist((recorder.sample(1, t).command, recorder.sample(2, t).command),
                     (1000, 1000)) < 1e-6
    return worst


def test_4_4_adjacent_ids_interpolate_and_a_faster_chain_keeps_the_path() -> None:
    """The Y axis starts one hop after the X axis; the path error is that lag times the
    speed, so it shrinks with a higher K65 (ch. 3 K65; 4.4 "adjacent Motor IDs")."""
    at_9600, at_230400 = _path_error(1), _path_error(5)
    assert at_9600 > 10 * at_230400
    assert at_230400 < 30


def test_direct_mode_pair_starts_the_y_axis_when_the_line_reaches_it(
        make_chain: ChainFactory) -> None:
    chain = make_chain(motors=2, pacing=True)
    for line in ("S.1=100", "A.1=100", "P.1=1000", "P.2=1000", "R.1=0", "R.2=0"):
        chain.execute(line)
    record(chain)
    type_line(chain, "@.1+, @.2+")
    chain.kernel.run(until=seconds(2))
    x = [p.origin_ns for _, p, *_ in chain.motors[1].axis.history if p.segments][0]
    y = [p.origin_ns for _, p, *_ in chain.motors[2].axis.history if p.segments][0]
    assert y - x == 11 * BT_38400          # the 11 bytes of the line, one hop
    assert chain.execute("?96.1") == ["Px.1=1000"] and chain.execute("?96.2") == ["Px.2=1000"]


def test_without_pacing_everything_happens_at_once(make_chain: ChainFactory) -> None:
    chain = make_chain(motors=3)
    received = host(chain)
    chain.host_line.feed(b"?96.3\r")
    assert received[-1] == (0, b"Px.3=0\r\n")


def test_pause_of_a_paced_path_keeps_each_axis_on_its_own_time_line(
        make_chain: ChainFactory) -> None:
    """``]`` while the Y axis runs a hop behind: each axis decelerates from where it is
    (no jump in the command), the pair stops near the arc, ``[`` finishes it exactly."""
    chain = make_chain(motors=2, pacing=True)
    chain.execute("K65.1=1")
    for line in ("A1.1=100", "S1.1=100", "P2.1=1000", "R1.1=2000", "P2.2=1000", "R1.2=2000",
                 "B1.1", "S1.1,A1.1,R1.1,R1.2,@2.2+,@2.1+", "END"):
        chain.execute(line)
    recorder = record(chain)
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(0.6))
    now = chain.kernel.now
    before = [recorder.sample(m, now).command for m in (1, 2)]
    chain.execute("]")
    after = [recorder.sample(m, now).command for m in (1, 2)]
    # the new pieces start on the exact path: within interp.MAX_ERROR of the old ones
    assert all(abs(b - a) <= 0.05 for b, a in zip(before, after))
    chain.kernel.advance(seconds(0.5))
    centre = (500 - 1322.8757, 500 + 1322.8757)
    here = (chain.motors[1].position(), chain.motors[2].position())
    assert abs(math.dist(here, centre) - 2000) < 60        # the lag of 9.6 kbps
    chain.execute("[")
    chain.kernel.advance(seconds(3))
    assert chain.execute("?96.1") == ["Px.1=1000"] and chain.execute("?96.2") == ["Px.2=1000"]


def test_the_chain_model_reads_no_clock_and_opens_no_threads_or_sockets() -> None:
    """docs/architecture.md rule 1 for the chain, its links and the motor model."""
    import ast as pyast

    import coolmuscle
    root = Path(coolmuscle.__file__).parent
    files = [*sorted((root / "chain").rglob("*.py")), *sorted((root / "device").rglob("*.py")),
             *sorted((root / "motor").rglob("*.py"))]
    assert len(files) > 45
    for path in files:
        for node in pyast.walk(pyast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, pyast.Import)
                     else [node.module or ""] if isinstance(node, pyast.ImportFrom) else [])
            for name in names:
                assert name.split(".")[0] not in {"time", "asyncio", "socket", "threading"}, (
                    path, name)
