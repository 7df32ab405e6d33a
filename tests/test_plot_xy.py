"""The XY path beside the trace plot (cml-users-guide.txt 4.4 figures; ``run --plot --xy``)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.cli import app as cli
from coolmuscle.tools.trace.plot import interpolated_pairs
from coolmuscle.tools.trace.plot import plot as plot_chain
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory

TRANSCRIPTS = Path(__file__).parent / "transcripts"


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def arc_chain() -> Chain:
    chain = Chain(motors=3)
    record(chain)
    for line in ("S.1=100", "A.1=100", "P.1=1000", "P.2=1000", "R.1=2000", "R.2=2000",
                 "P.3=500", "S.3=100", "A.3=100", "^.3", "@.1+, @.2+"):
        chain.execute(line)
    chain.kernel.run(until=seconds(2))
    return chain


def test_pairs_that_interpolated_get_an_xy_panel(tmp_path: Path) -> None:
    chain = arc_chain()
    assert interpolated_pairs(record(chain)) == [(1, 2)]
    with_xy = png_size(plot_chain(chain, tmp_path / "xy.png"))
    without = png_size(plot_chain(chain, tmp_path / "plain.png", xy=[]))
    assert with_xy[0] > without[0] * 1.4 and with_xy[1] == without[1]


def test_a_chain_without_interpolation_has_no_xy_panel(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(motors=2)
    record(chain)
    chain.execute("S.1=100, A.1=100, P.1=1000, ^.1")
    chain.kernel.run(until=seconds(1))
    assert interpolated_pairs(record(chain)) == []
    assert png_size(plot_chain(chain, tmp_path / "p.png")) == png_size(
        plot_chain(chain, tmp_path / "q.png", xy=[]))
    assert png_size(plot_chain(chain, tmp_path / "r.png", xy=[(1, 2)]))[0] > png_size(
        tmp_path / "p.png")[0]


def test_run_plot_draws_the_4_4_1_path_and_xy_is_checked(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "arc.png"
    script = str(TRANSCRIPTS / "4.4.1-radius-long-arc-cw.cml")
    with pytest.raises(SystemExit) as info:
        cli.main(["run", script, "--motors", "2", "--check", "--plot", str(out)])
    assert info.value.code in (0, None)
    assert png_size(out)[0] > 1500                 # the XY panel is beside the time panels
    with pytest.raises(SystemExit) as info:
        cli.main(["run", script, "--motors", "2", "--plot", str(out), "--xy", "1,3"])
    assert info.value.code == 2
    assert "--xy 1,3: two different IDs of the chain (1..2)" in capsys.readouterr().err
