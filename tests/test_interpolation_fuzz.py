"""Fuzz: any mix of ``@``, ``R``, ``N``, ``P``, ``Y`` and data on a chain never crashes
(docs/architecture.md rule 5), in direct mode, in program banks and in a ladder bank,
paced or not, stopped and resumed or not; a pair that ran to its end is exactly on its
P data."""

from __future__ import annotations

import math

from hypothesis import event, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record

index = st.integers(0, 3)
modifier = st.sampled_from(["", "+", "-"])


def statements(motors: int) -> st.SearchStrategy[str]:
    ids = st.integers(1, motors + 1)           # one ID past the chain too
    return st.one_of(
        st.builds(lambda i, m, d: f"@{i or ''}.{m}{d}", index, ids, modifier),
        st.builds(lambda i, m, d: f"R{i}.{m}{d}", index, ids, modifier),
        st.builds(lambda i, m: f"N{i}.{m}", index, ids),
        st.builds(lambda i, m: f"S{i}.{m}", index, ids),
        st.builds(lambda i, m: f"P{i}.{m}", index, ids),
        st.builds(lambda i, m: f"Y{i}.{m}", index, ids),
    )


def pairs(motors: int) -> st.SearchStrategy[list[str]]:
    """The @ of two adjacent motors, either order, with an R or N selection before."""
    return st.builds(
        lambda sel, i, j, m, d, e, swap: [f"{sel}{i}.{m}", f"{sel}{j}.{m + 1}"]
        + [f"@{i or ''}.{m}{d}", f"@{j or ''}.{m + 1}{e}"][::swap],
        st.sampled_from(["R", "N"]), index, index, st.integers(1, motors - 1), modifier,
        modifier, st.sampled_from([1, -1]))


def assignments(motors: int) -> st.SearchStrategy[str]:
    ids = st.integers(1, motors)
    return st.one_of(
        st.builds(lambda k, i, m, v: f"{k}{i}.{m}={v}", st.sampled_from("PPRN"), index, ids,
                  st.integers(-5000, 5000)),
        st.builds(lambda i, m, v: f"S{i}.{m}={v}", index, ids, st.integers(0, 300)),
        st.builds(lambda i, m, v: f"A{i}.{m}={v}", index, ids, st.integers(1, 500)),
    )


@settings(max_examples=50, deadline=None)
@given(data=st.data(), motors=st.integers(2, 4),
       where=st.sampled_from(["direct", "bank", "ladder"]), pacing=st.booleans(),
       stop=st.booleans())
def test_interpolation_lines_never_crash(data: st.DataObject, motors: int, where: str,
                                         pacing: bool, stop: bool) -> None:
    values = data.draw(st.lists(assignments(motors), max_size=25))
    lines = data.draw(st.lists(
        st.builds(lambda ps, rest: sum(ps, []) + rest, st.lists(pairs(motors), max_size=2),
                  st.lists(statements(motors), max_size=3)).filter(bool),
        min_size=1, max_size=3))
    base = data.draw(st.lists(st.integers(-5000, 5000), min_size=12, max_size=12))
    chain = Chain(motors=motors, pacing=pacing)
    record(chain)
    for motor in range(1, motors + 1):
        chain.execute(", ".join(f"S{i}.{motor}=100" for i in range(4)) + f", K63.{motor}=20")
        chain.execute(", ".join(f"{kind}{i}.{motor}={base[(k * 4 + i + motor) % 12]}"
                                for k, kind in enumerate("PRN") for i in range(4)))
    for line in values:
        chain.execute(line)
    texts = [", ".join(line) for line in lines]
    if where == "direct":
        for text in texts:
            chain.host_line.feed(text.encode() + b"\r")
            chain.kernel.advance(seconds(0.05))
    else:
        kind = "B" if where == "bank" else "L"
        chain.execute(f"{kind}1.1")
        for text in texts:
            chain.execute(text)
        chain.execute("END")
        chain.execute("[1.1" if kind == "B" else "[L1.1")
    chain.kernel.advance(seconds(0.3))
    if stop:
        chain.host_line.feed(b"]\r")
        chain.kernel.advance(seconds(0.2))
        chain.host_line.feed(b"[\r")
    chain.kernel.advance(seconds(4))
    chain.host_line.feed(b"]L.1\r]L.1\r")
    for motor in chain.motors.values():
        assert math.isfinite(motor.axis.position())
        assert chain.execute(f"?96.{motor.id}")[0].startswith(f"Px.{motor.id}=")
        path = motor.path
        if path is None:
            continue
        event(f"a path ran ({where})")
        if path.owns(motor) and not motor.axis.moving and not stop:
            end = path.end_point()
            assert motor.axis.target() == (end[0] if motor is path.x else end[1])
