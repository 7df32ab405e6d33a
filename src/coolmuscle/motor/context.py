"""Who executes a line (:class:`Context`) and what a motor needs from its chain (:class:`MotorBus`).

Shared by the façade (:mod:`.motor`), the program, ladder and direct executors and the
chain; it sits below all of them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Iterable, Protocol

from ..cml import ast

if TYPE_CHECKING:
    from .motor import Motor


class MotorBus(Protocol):
    """What a motor needs from its chain."""

    def emit(self, motor: int, kind: str, text: str, *, value: int | None = None,
             origin: str = "motor") -> None:
        """Report a line (host line + event stream)."""

    def motor(self, motor_id: int) -> "Motor | None":
        """Another motor of the chain (None when absent)."""

    def watch(self, callback: Callable[[], None],
              motors: Iterable[int] | None = None) -> Callable[[], None]:
        """Call ``callback`` at every poke (about ``motors``) until the remover is called."""

    def poke(self, motor: int | None = None) -> None:
        """Something changed (input, data, motion of ``motor``): re-check the bank waits."""

    def chain_command(self, motor: "Motor", stmt: ast.Exec, ctx: "Context") -> None:
        """Chain-wide execution commands (``]``, ``*``, ``*1`` ...)."""


@dataclass
class Context:
    """Who is executing: the origin of the line and where its replies go."""

    origin: str = "host"
    replies: list[str] | None = None
    default_motor: int = 1
    program: bool = False   # inside a program bank
    ladder: bool = False    # inside a ladder bank
    quiet: bool = False     # ladder line ending with ';'
    session: object = None  # which sender of ``origin`` (a TCP client ...): owns bank uploads
    extra: dict[str, object] = field(default_factory=dict)
