"""Plots of the cml-users-guide.txt 4.1 motion examples (the images of docs/plots.md).

Run: ``python examples/plot_4_1.py [OUT_DIR]`` (default docs/images), with the
virtual environment active (README.md).

Each example is the manual's program bank, uploaded and run on a virtual motor in
virtual time with the script runner (docs/scripts.md), then plotted from its trace.
The data tables of 4.1 were lost with the manual's figures, so the values below are
chosen to show each motion clearly.  Output 1 is the in-position signal in merge
motion (K34=6, K73=30 ms), output 2 the in-position signal (K34=1).  4.1.4 pushes an
object the machine file ``push-object.toml`` puts at 11000 pulses (drawn dotted); the
plot runs on half a second past the push's completion (Ux=40) so that state shows.
"""

from __future__ import annotations

import sys
from pathlib import Path

from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.script import run_script
from coolmuscle.tools.trace import record
from coolmuscle.tools.trace.plot import plot as plot_chain

HERE = Path(__file__).parent
OUTPUTS = "K34.1=16\nK73.1=30\n"

EXAMPLES: dict[str, tuple[str, str, str | None]] = {
    "4.1.1-basic-ptp": (
        "4.1.1 basic PTP: S1 A1 P1 / P2 / S2 P3 (one motion a line)",
        """S1.1=50
S2.1=100
A1.1=100
P1.1=4000
P2.1=8000
P3.1=0
B1.1
S1.1, A1.1, P1.1
P2.1
S2.1, P3.1
END
[1.1
@wait 3.2
""", None),
    "4.1.2-merge": (
        "4.1.2 merge motion: S1 A1 P1, S2 P2, P3 (pulses at the passing points)",
        """S1.1=50
S2.1=100
A1.1=100
P1.1=3000
P2.1=8000
P3.1=12000
B2.1
S1.1, A1.1, P1.1, S2.1, P2.1, P3.1
END
[2.1
@wait 2.0
""", None),
    "4.1.2-merge-reversal": (
        "4.1.2 merge motion removed where the direction turns over",
        """S1.1=80
A1.1=100
P1.1=3000
P2.1=6000
P3.1=1000
B2.1
S1.1, A1.1, P1.1, P2.1, P3.1
END
[2.1
@wait 2.2
""", None),
    "4.1.3-accel-decel": (
        "4.1.3 different acceleration and deceleration: S1 A1 P1, A2 P2",
        """S1.1=100
A1.1=30
A2.1=300
P1.1=6000
P2.1=15000
B3.1
S1.1, A1.1, P1.1, A2.1, P2.1
END
[3.1
@wait 2.2
""", None),
    "4.1.4-push": (
        "4.1.4 push motion: S3 A1 P1, S1 Q2 (an object at 11000; K60 30 %, K61 200 ms)",
        """K34.1=96
S1.1=20
S3.1=100
A1.1=100
P1.1=10000
P2.1=12000
B4.1
S3.1, A1.1, P1.1, S1.1, Q2.1
END
[4.1
@wait 2.3
""", "push-object.toml"),
}


def plot(name: str, out: Path) -> Path:
    """Run one example bank and draw its trace."""
    title, script, machine = EXAMPLES[name]
    chain = Chain(machine=HERE / machine if machine else None)
    record(chain)
    try:
        result = run_script(OUTPUTS + script, chain)
        if not result.ok:
            raise RuntimeError(f"{name}: {result.summary()}")
        return plot_chain(chain, out / f"{name}.png", title=title)
    finally:
        chain.close()


def main(argv: list[str]) -> int:
    out = Path(argv[1]) if len(argv) > 1 else HERE.parent / "docs" / "images"
    out.mkdir(parents=True, exist_ok=True)
    for name in EXAMPLES:
        print(plot(name, out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
