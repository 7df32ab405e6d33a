"""Bad input never crashes the CML parser (docs/architecture.md, rule 5).

For any string, :func:`coolmuscle.cml.parse` either returns or raises
:class:`CmlSyntaxError` (with a column inside the text).  When it returns, the
canonical text of what it read parses back to the same statements.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cml_support import corpus_lines
from coolmuscle.cml import format_line, parse
from coolmuscle.errors import CmlSyntaxError

CML_ALPHABET = ("PSAMTVNRKHIUYQZOFCJXWBLEDpsvi0123456789.,:;=+-*/<>!&|()[]{}^$?#@\\\""
                " \t\u00a5")
FUZZ = settings(max_examples=600, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])


def check(text: str) -> None:
    """parse() returns or raises CmlSyntaxError; what it returns prints and reparses."""
    try:
        result = parse(text)
    except CmlSyntaxError as err:
        assert 0 <= err.position <= len(text), (text, err.position)
        assert err.number == 1
        return
    for line in result:
        assert line.statements
        again = parse(format_line(line))
        assert [x.statements for x in again] == [line.statements], text


@FUZZ
@given(st.text(max_size=80))
def test_random_unicode_text(text: str) -> None:
    check(text)


@FUZZ
@given(st.binary(max_size=80))
def test_random_bytes_as_latin1(data: bytes) -> None:
    check(data.decode("latin-1"))


@FUZZ
@given(st.text(alphabet=CML_ALPHABET, max_size=60))
def test_random_cml_characters(text: str) -> None:
    check(text)


@st.composite
def mutated(draw: st.DrawFn) -> str:
    """A manual example line with a few characters inserted, deleted or replaced."""
    text = draw(st.sampled_from(corpus_lines("ok", "cond", "fail")))
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(text)))
        char = draw(st.sampled_from(CML_ALPHABET) | st.characters())
        action = draw(st.sampled_from(["insert", "delete", "replace"]))
        if action == "insert":
            text = text[:pos] + char + text[pos:]
        elif action == "delete":
            text = text[:pos] + text[pos + 1:]
        else:
            text = text[:pos] + char + text[pos + 1:]
    return text


@FUZZ
@given(mutated())
def test_mutated_manual_lines(text: str) -> None:
    check(text)


@pytest.mark.parametrize("text", [
    "P1=" + "9" * 10_000,
    "P" + "1" * 5000 + "=1",
    "P1." + "1" * 5000 + "=1",
    "V1=" + "U1(" * 5000 + "V1" + ")" * 5000,
    "!!(" * 5000,
    "(" * 10_000,
    ")" * 10_000,
    "V1=" + "+1" * 50_000,
    "V1=1" + "*2" * 63,
    "," * 10_000,
    ";" * 10_000,
    '"' * 10_001,
    "a" * 100_000,
    "/" * 100_000,
    "\u00a5" * 1000,
    "\x00\x01\x02\r\n\x7f\x80\xff",
    "P1.1=1; " * 5000,
    ", ".join(["P1.1"] * 10_000),
    "I1" + "&&I1" * 100 + ", ?99",
])
def test_over_long_and_deep_lines(text: str) -> None:
    check(text)
