"""MD5 digests of what a tree's ``coolmuscle run`` prints and traces: motion bit for bit.

Run: ``python bench/motion_digest.py [--src TREE/src] [--pure] [--quick]``

For every golden transcript of tests/transcripts/ (this checkout's) it runs ``coolmuscle
run SCRIPT --trace OUT.csv`` (the 1 ms grid) in a fresh interpreter of the tree whose
``src`` is given (default: this checkout's), then one 15-motor chain looping the PTP
banks of bench_speed.py for 600 simulated seconds with a 1 ms trace (``--quick``: 60 s).
One line per run: the MD5 of what it printed and of its trace; the last line is the MD5
of all of them.  Two trees (or one tree compiled and as sources, ``--pure`` setting
``COOLMUSCLE_PURE=1``) move their motors the same way, to the bit, when their lines are
the same.  The first line is the tree's ``coolmuscle --version``: whether the compiled
hot modules ran (coolmuscle/_accel.py).  The 600 s trace is about 600 MB, written to a
temporary directory and removed.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from bench_speed import chain_script  # noqa: E402  (the bench's own 15-motor script)


def md5_of(path: Path) -> str:
    h = hashlib.md5()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def environment(src: Path, pure: bool) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(src)
    env.pop("COOLMUSCLE_PURE", None)
    if pure:
        env["COOLMUSCLE_PURE"] = "1"
    return env


def run(env: dict[str, str], script: Path, work: Path, *extra: str) -> str:
    """``coolmuscle run SCRIPT --trace`` in a fresh interpreter: the two MD5s."""
    trace = work / "trace.csv"
    out = subprocess.run([sys.executable, "-m", "coolmuscle", "run", str(script),
                          "--trace", str(trace), *extra], env=env, cwd=script.parent,
                         capture_output=True)
    if out.returncode not in (0, 1):         # 1: an expectation not met, still a result
        raise SystemExit(f"{script.name}: exit {out.returncode}\n{out.stderr.decode()}")
    digest = f"{hashlib.md5(out.stdout).hexdigest()} {md5_of(trace)}"
    trace.unlink()
    return digest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--src", type=Path, default=ROOT / "src",
                        help="the src directory of the tree to run (default: this one's)")
    parser.add_argument("--pure", action="store_true", help="run the sources (COOLMUSCLE_PURE=1)")
    parser.add_argument("--quick", action="store_true", help="the chain for 60 s, not 600 s")
    args = parser.parse_args()
    env = environment(args.src.resolve(), args.pure)
    version = subprocess.run([sys.executable, "-m", "coolmuscle", "--version"], env=env,
                             capture_output=True, text=True, check=True).stdout
    print(" | ".join(version.split("\n")).strip(" |"))
    total = hashlib.md5()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        items = [(path.name, path, ()) for path in sorted(ROOT.glob("tests/transcripts/*.cml"))]
        chain = work / "chain15.cml"
        chain.write_text(chain_script(15))
        seconds = "60" if args.quick else "600"
        items.append((f"15 motors {seconds} s", chain, ("--motors", "15", "--until", seconds)))
        for name, path, extra in items:
            line = f"{name}: {run(env, path, work, *extra)}"
            total.update(line.encode() + b"\n")
            print(line, flush=True)
    print(f"all: {total.hexdigest()}")


if __name__ == "__main__":
    main()
