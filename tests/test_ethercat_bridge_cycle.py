"""The bridge's own 1 ms cycle as kernel events (ethercat-bridge-users-guide.txt 6.3,
7.3 F511h.3 "Cycle Time 1. 1 msec"): ``BridgeApp.start_cycles``, what ``sim --ethercat``
runs.

The CM port gives every motor a command each millisecond of its own time, whenever the
master's frames come: the cycles are on an exact grid of virtual time, a cycle that
fails does not stop the next, and an output image that arrives between two cycles is
taken by the next one.  Under ``--time-scale`` a cycle stays 1 ms of wall time (the
master's frames come in wall time).
"""

from __future__ import annotations

import struct
import time

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.ethercat.bridge.app import CYCLE_NS, BridgeApp
from coolmuscle.frontends.ethercat.lab import veth_pair
from coolmuscle.frontends.ethercat.transport import CycleLateness, EthercatTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import Kernel
from coolmuscle.sim.realtime import RealtimeClock
from ethercat_support import needs_net_admin

MS = 1_000_000


@pytest.fixture()
def bridge() -> tuple[Kernel, Chain, BridgeApp]:
    kernel = Kernel()
    chain = Chain(kernel, 4, firmware="cm2")
    return kernel, chain, BridgeApp(chain, "EB02")


def image(cw: int, target: int) -> bytes:
    return struct.pack("<" + "Hi" * 4, *([cw, target] * 4))


def test_cycles_run_every_1_ms_of_virtual_time_6_3_f511h(bridge) -> None:
    kernel, _chain, app = bridge
    assert CYCLE_NS == MS
    seen: list[int] = []
    app.start_cycles(on_start=lambda: seen.append(kernel.now))
    kernel.run(until=10 * MS + MS // 2)
    assert seen == [n * MS for n in range(1, 11)]
    assert app.drive.cycles == 10 and app.drive.max_gap_ns == MS
    app.stop_cycles()
    kernel.run(until=20 * MS)
    assert len(seen) == 10 and app.drive.cycles == 10
    app.stop_cycles()                                    # twice: harmless


@pytest.mark.parametrize("period", [0, -MS])
def test_a_cycle_that_is_not_a_positive_time_is_refused(bridge, period: int) -> None:
    kernel, _chain, app = bridge
    with pytest.raises(ValueError):
        app.start_cycles(period)
    kernel.run(until=3 * MS)
    assert app.drive.cycles == 0


def test_start_again_replaces_the_schedule(bridge) -> None:
    kernel, _chain, app = bridge
    seen: list[int] = []
    app.start_cycles(on_start=lambda: seen.append(kernel.now))
    kernel.run(until=MS // 2)
    app.start_cycles(2 * MS, on_start=lambda: seen.append(-kernel.now))
    kernel.run(until=5 * MS)
    assert seen == [-(MS // 2 + 2 * MS), -(MS // 2 + 4 * MS)]


def test_a_failing_cycle_is_logged_and_the_next_one_comes(bridge, caplog) -> None:
    kernel, _chain, app = bridge
    real = app.cycle
    calls: list[int] = []

    def flaky() -> None:
        calls.append(kernel.now)
        if len(calls) == 2:
            raise RuntimeError("boom")
        real()

    starts: list[int] = []
    app.cycle = flaky                                    # type: ignore[method-assign]
    app.start_cycles(on_start=lambda: starts.append(kernel.now))
    kernel.run(until=4 * MS)
    assert calls == [MS, 2 * MS, 3 * MS, 4 * MS] == starts
    assert "bridge cycle failed" in caplog.text


def test_an_image_between_two_cycles_is_taken_by_the_next_6_3(bridge) -> None:
    """The motor's command changes on the CM port's cycle, not when the frame came."""
    kernel, chain, app = bridge
    od = app.dictionary
    app.start_cycles()

    def frame(cw: int, target: int) -> None:
        data = image(cw, target)
        od.unpack_outputs(data)
        app.outputs(data)

    for cw in (0x06, 0x07, 0x0F):                        # 6.1.2: to Operation enabled
        frame(cw, 0)
        kernel.run(until=kernel.now + 5 * MS)
    assert od.get(0x6041) & 0x6F == 0x27
    pushed = app.drive.axes[1].follower.pushed
    kernel.run(until=kernel.now + MS // 3)               # between two cycles
    frame(0x0F, 100)
    kernel.run(until=kernel.now + MS // 2)               # still before the next cycle
    assert app.drive.axes[1].follower.pushed == pushed
    assert chain.snapshot(1).target == 0
    kernel.run(until=kernel.now + MS // 2)               # the next cycle came
    assert app.drive.axes[1].follower.pushed == pushed + 1
    assert chain.snapshot(1).target == 100


def test_lateness_is_wall_seconds_since_an_instant_was_due() -> None:
    wall = [100.0]
    kernel = Kernel()
    clock = RealtimeClock(kernel, clock=lambda: wall[0])
    assert clock.lateness(0) == 0.0
    wall[0] += 0.003
    assert clock.lateness(MS) == pytest.approx(0.002)
    assert clock.lateness(5 * MS) == pytest.approx(-0.002)


@pytest.mark.parametrize("scale", [1.0, 4.0])
def test_a_cycle_is_late_when_it_starts_more_than_a_wall_cycle_after_its_instant(
        scale: float) -> None:
    """Under a time scale one cycle is still 1 ms of wall time (scale ms of virtual)."""
    wall = [0.0]
    clock = RealtimeClock(Kernel(), scale=scale, clock=lambda: wall[0])
    late = CycleLateness(clock, 0.001)
    period = round(MS * scale)
    for n, start_wall in enumerate([0.0013, 0.0035, 0.0040, 0.0041], 1):
        wall[0] = start_wall                    # cycle n is due at n ms of wall time
        late.note(n * period)
    assert late.cycles == 4
    assert late.late == 1                       # cycle 2 started 1.5 ms after its instant
    assert late.worst == pytest.approx(0.0015)


@needs_net_admin
@pytest.mark.realtime
@pytest.mark.parametrize("scale", [1.0, 5.0])
def test_the_transport_runs_one_cycle_a_wall_ms_on_the_virtual_grid(scale: float) -> None:
    """``sim --ethercat`` (and ``--time-scale``): the cycles come every 1 ms of wall
    time, each ``scale`` ms of virtual time after the last, and stop on close."""
    with veth_pair("cmecyc", inside="master") as lab:
        with ServiceThread(lambda: Chain(None, 4, firmware="cm2"),
                           lambda: [EthercatTransport(lab.slave_if, "EB02")],
                           scale=scale) as st:
            transport = st.transports[0]
            start = time.monotonic()
            time.sleep(0.3)
            cycles, elapsed = st.call(lambda: transport.cycles), time.monotonic() - start
            gap = st.call(lambda: transport.app.drive.max_gap_ns)
            now = st.call(lambda: st.chain.kernel.now)
        assert 0.5 * elapsed * 1000 < cycles < 1.5 * elapsed * 1000 + 5, (cycles, elapsed)
        assert gap == round(MS * scale)
        assert now >= cycles * round(MS * scale)
        after = transport.cycles
        time.sleep(0.05)
        assert transport.cycles == after               # closed: no more cycles
