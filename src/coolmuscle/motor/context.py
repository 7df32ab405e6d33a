"""Who executes a line: :class:`Context` (origin, where replies go, bank or ladder).

Shared by the façade (:mod:`.motor`), the program, ladder and direct executors and the
chain; it sits below all of them.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Context:
    """Who is executing: the origin of the line and where its replies go."""

    origin: str = "host"
    replies: list[str] | None = None
    default_motor: int = 1
    program: bool = False   # inside a program bank
    ladder: bool = False    # inside a ladder bank
    quiet: bool = False     # ladder line ending with ';'
    extra: dict[str, object] = field(default_factory=dict)
