"""A host program to capture (docs/user-guide.md "coolmuscle capture"): two moves, each
waited for until the motor reports it in position (``Ux.1=8``, K23 function 1), then
the position read once the motor is at rest.

Run: ``python examples/capture-host.py [URL]`` (default ``socket://127.0.0.1:5150``),
with the virtual environment active (README.md).

A session of events and queries at rest replays byte for byte with ``coolmuscle run
--check``; a query while the motor moves would answer what the motor was doing at that
very instant, which the wall clock moves a little from one session to the next.
"""

from __future__ import annotations

import sys
import time

from coolmuscle import connect


def main(url: str) -> None:
    with connect(url) as motor:
        for target in (3000, 0):
            motor.move_to(target, speed=100, accel=50)     # S.1, A.1, P.1, ^.1
            motor.wait_in_position(timeout=10)             # the motor says Ux.1=8
            time.sleep(0.3)                                # at rest, then ask
            print(f"moved to {target}: Px.1={motor.position}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "socket://127.0.0.1:5150")
