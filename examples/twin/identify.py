"""The identification session of docs/twin.md: moves and polls that let `coolmuscle fit`
tell the load's inertia, its friction, the position-loop gain and a stopper apart.

    python examples/twin/identify.py socket://127.0.0.1:5151            # through the relay
    python examples/twin/identify.py /dev/ttyUSB0 --push-to 25000       # a serial port

It plays :func:`plan` on the port in real time (pyserial; any URL pyserial opens) and
prints what the motor says.  Run it through `coolmuscle capture` so that the session is
recorded; the tests play the same plan on a virtual motor (tests/twin_support.py).

What each part gives the fit (docs/twin.md "A session the fit can use"):

* accelerations at three rates while polling the torque (?98): the torque during an
  acceleration is inertia x acceleration + friction, while cruising friction alone, so
  the two are told apart;
* cruising at three speeds while polling the position error (?95): Pe = speed / kp;
* the same moves both ways: friction turns round with the motion, a load torque does not;
* with --push-to, a slow move past the stopper with the torque limited (M, 2.1.1), held
  there while polling the position (?96): the stopper's position (keep the target
  within K56 x 100 pulses of the stopper, or the position error overflows, Ux=1).

The motor's origin is set where it stands (`|2`), so run it with the shaft where the
virtual motor is to start.  Nothing is saved on the motor: S, A, P and M are direct-mode
data, no K parameter or bank is written.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

#: (speed S in 100 pps, acceleration A in kpps², target) of each move (K37=3: 1000 ppr).
MOVES = ((100, 100, 20000), (300, 300, 0), (200, 600, 20000), (100, 100, 0),
         (300, 300, 20000), (200, 600, 0))
POLLS = ("?96.1", "?95.1", "?98.1")


def _move_time(speed: int, accel: int, distance: int) -> float:
    """Seconds a trapezoidal move takes (S x 100 pps, A kpps²), plus time to settle."""
    v, a = speed * 100.0, accel * 1000.0
    ramp = v / a
    if distance <= v * ramp:            # a triangle: never reaches S
        return 2.0 * (distance / a) ** 0.5 + 0.3
    return distance / v + ramp + 0.3


def plan(period: float = 0.01, rounds: int = 1,
         push_to: int | None = None) -> list[tuple[float, str]]:
    """The session as (seconds from its start, line to send), in time order.

    ``rounds`` repeats the moves (a longer session: more samples); ``period`` is the
    time between two polls (each poll is about 4 ms of the line at 38.4 kbps)."""
    out: list[tuple[float, str]] = [(0.0, "|2.1")]
    t = 0.05
    position = 0
    n = 0

    def poll_until(end: float) -> None:
        nonlocal t, n
        while t < end - 1e-9:
            out.append((round(t, 6), POLLS[n % len(POLLS)]))
            n += 1
            t += period

    def move(speed: int, accel: int, target: int) -> None:
        nonlocal t, position
        for line in (f"S.1={speed}", f"A.1={accel}", f"P.1={target}", "^.1"):
            out.append((round(t, 6), line))
            t += period
        end = t + _move_time(speed, accel, abs(target - position))
        position = target
        poll_until(end)

    for _ in range(rounds):
        for speed, accel, target in MOVES:
            move(speed, accel, target)
    if push_to is not None:
        move(300, 300, 20000)
        out.append((round(t, 6), "M.1=30"))        # 30 % of the maximum torque (2.1.1)
        t += period
        move(20, 100, push_to)                      # 2000 pps into the stopper
        poll_until(t + 0.5)                         # held against it
        out.append((round(t, 6), "M.1=100"))
        t += period
        move(300, 300, 0)
    return out


def play(port: str, lines: list[tuple[float, str]]) -> None:
    """Send each line at its time (wall clock) and print everything the motor says."""
    import serial  # pyserial: a dependency of coolmuscle

    link = serial.serial_for_url(port, baudrate=38400, timeout=0.05)
    done = threading.Event()

    def reader() -> None:
        while not done.is_set():
            data = link.read(256)
            if data:
                sys.stdout.write(data.decode("latin-1").replace("\r\n", "\n"))
                sys.stdout.flush()

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    start = time.monotonic()
    try:
        for at, line in lines:
            delay = start + at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            link.write(line.encode("ascii") + b"\r")
        time.sleep(0.5)                              # the last replies
    finally:
        done.set()
        thread.join(timeout=1.0)
        link.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("port", help="serial port or pyserial URL (socket://HOST:PORT)")
    parser.add_argument("--period", type=float, default=0.01,
                        help="seconds between polls (default 0.01)")
    parser.add_argument("--rounds", type=int, default=1, help="repeat the moves")
    parser.add_argument("--push-to", type=int, default=None, metavar="PULSES",
                        help="push past the stopper to this position (K56 x 100 beyond "
                             "it at most)")
    args = parser.parse_args()
    lines = plan(args.period, args.rounds, args.push_to)
    print(f"identification session: {len(lines)} lines, {lines[-1][0]:.1f} s",
          file=sys.stderr)
    play(args.port, lines)


if __name__ == "__main__":
    main()
