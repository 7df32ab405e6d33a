"""Bad data never crashes the model: random valid statements with extreme values.

Every statement form of ch. 6 is generated with values at and beyond the edges of
their ranges (0, negative, maximum, out of range), in direct mode and inside program
and ladder banks, with time advancing between lines.  The motor must answer as it
answers (replies, errorNN, silence) and never raise.
"""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from fixtures import ChainFactory

EDGE = st.sampled_from([0, 1, -1, 2, 100, -100, 32767, -32768, 1000000000, -1000000000,
                        2147483647, 999999999, 5])
REG = st.sampled_from(["P", "S", "A", "M", "T", "V", "N", "R"])
K = st.integers(20, 89)
MOTOR = st.sampled_from(["", ".1", ".2", ".3"])


@st.composite
def statement(draw: st.DrawFn) -> str:
    reg, index, motor = draw(REG), draw(st.integers(0, 9)), draw(MOTOR)
    value = draw(EDGE)
    return draw(st.sampled_from([
        f"{reg}{index}{motor}={value}",
        f"K{draw(K)}{motor}={value}",
        f"{reg}{index}{motor}",
        f"^{motor}", f"|1{motor}", f"|2{motor}", f"({motor}", f"){motor}", f"]{motor}",
        "*", "*1", f"P{index}{motor}+", f"Y{index}{motor}", f"Q{index}{motor}",
        f"O{draw(st.integers(0, 5))}{motor}", f"F{draw(st.integers(0, 5))}{motor}",
        f"?{draw(st.sampled_from([50, 70, 90, 95, 96, 97, 98, 99, 999, 1000]))}{motor}",
        f"V{index}{motor}=V{draw(st.integers(0, 15))}/V{draw(st.integers(0, 15))}",
        f"#{index}{motor}", f"[{draw(st.integers(1, 3))}{motor}", f"[L{draw(st.integers(1, 3))}",
        f"]L{motor}", f"S{index}{motor}, A{index}{motor}, P{index}{motor}",
        f"V{index}{motor}=\"Px\"", f"V{index}{motor}=U{draw(st.integers(1, 6))}(V1)",
    ]))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(setup=st.lists(statement(), max_size=12), bank=st.lists(statement(), max_size=6),
       ladder=st.lists(statement(), max_size=4), after=st.lists(statement(), max_size=12))
def test_random_statements_with_edge_values_never_raise(setup, bank, ladder, after) -> None:
    chain = Chain(motors=2)
    feed = chain.host_line.feed
    for line in setup:
        feed(line.encode() + b"\r")
        chain.kernel.advance(20_000_000)
    for header, body in (("B1.1", bank), ("L1.1", ladder)):
        feed(header.encode() + b"\r")
        for line in body:
            feed(line.encode() + b"\r")
        feed(b"END\r")
    feed(b"[1.1\r[L1.1\r")
    for line in after:
        feed(line.encode() + b"\r")
        chain.kernel.advance(50_000_000)
    chain.kernel.advance(2_000_000_000)
    assert chain.execute("?99.1")[0].startswith("Ux.1=")


def test_zero_speed_data_means_no_motion_and_the_bank_goes_on(make_chain: ChainFactory) -> None:
    chain = make_chain()
    for line in ("S1.1=0", "A1.1=100", "P1.1=5000", "S2.1=100", "P2.1=-200",
                 "B1.1", "S1.1, A1.1, P1.1", "S2.1, P2.1", "END", "[1.1"):
        chain.execute(line)
    chain.kernel.advance(2_000_000_000)
    assert chain.execute("?96.1") == ["Px.1=-200"]
    chain.execute("S.1=0, A.1=100, P.1=3000")
    chain.execute("^.1")                           # S0 = 0: no motion, no report
    chain.kernel.advance(1_000_000_000)
    assert chain.execute("?96.1") == ["Px.1=-200"]
    assert chain.execute("?99.1") == ["Ux.1=8"]
