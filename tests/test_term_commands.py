"""``coolmuscle term``'s colon commands, without a screen: ``:motor`` takes a motor ID
of the chain (1..15, cml-users-guide.txt 1.1) and says why it refuses another."""

from __future__ import annotations

import asyncio

import pytest

from coolmuscle import connect_async
from coolmuscle.tools.term import terminal as term


@pytest.mark.parametrize("arg, motor, style", [("2", 2, "info"), ("0", 1, "error"),
                                               ("16", 1, "error")])
def test_motor_command_takes_1_to_15(arg: str, motor: int,
                                     style: str) -> None:
    shown: list[tuple[str, str]] = []

    async def session() -> int:
        async with await connect_async("coolmuscle://?mode=fast") as client:
            terminal = term.Terminal(client, "coolmuscle://",
                                     show=lambda text, kind: shown.append((text, kind)))
            assert await terminal.command(f"motor {arg}") is True
            return terminal.motor
    assert asyncio.run(session()) == motor
    assert shown and shown[-1][1] == style
