"""The daisy chain of motors; implements the device API (coolmuscle.device.Device).

PLACEHOLDER: the constructor signature and ``host_line``/``kernel`` attributes are
final; the behaviour is being written (motor model).  Until then every received line
is answered by nothing.
"""

from __future__ import annotations

from pathlib import Path

from .hostline import HostLine, LineSettings
from .sim.kernel import Kernel


class Chain:
    """Motors 1..N behind one host line."""

    def __init__(self, kernel: Kernel | None = None, motors: int = 1, *,
                 firmware: str = "cm2", state_dir: Path | str | None = None,
                 pacing: bool = False) -> None:
        self.kernel = kernel or Kernel()
        self.host_line = HostLine(self.kernel, self._on_host_line, LineSettings,
                                  pacing=pacing)
        self.state_dir = Path(state_dir) if state_dir else None
        self._motor_count = motors

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(range(1, self._motor_count + 1))

    def _on_host_line(self, text: str) -> None:
        del text

    def close(self) -> None:
        """Flush and close the store."""
