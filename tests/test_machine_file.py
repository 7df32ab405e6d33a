"""Machine files (docs/machine-file.md): schema checks, the examples,
the shaft's start position and resolution scaling, input and fault schedules, the
reserved analog/encoder tables, and ``coolmuscle run --machine``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.machine import MachineFileError, parse_machine
from coolmuscle.sim.kernel import NS_PER_S, seconds
from coolmuscle.tools.cli import app as cli
from fixtures import ChainFactory

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.toml"))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_load(path: Path, make_chain: ChainFactory) -> None:
    """Each example loads on a chain of the motors it names (its axes, its wire faults)."""
    machine = parse_machine(path.read_text(), source=str(path))
    named = [axis.motor for axis in machine.axes] + [fault.motor for fault in machine.wire
                                                     if fault.motor is not None]
    chain = make_chain(motors=max([1, *named]), machine=path)
    chain.kernel.run(until=seconds(40))
    assert chain.execute("?99.1")


@pytest.mark.parametrize("text, message", [
    ("[[axis]]\nmotro = 1\n", "unknown key 'motro'"),
    ("[[axis]]\nmotor = 16\n", "outside 1..15"),
    ("[[axis]]\n[axis.load]\ninertia = -1\n", "outside"),
    ("[[axis]]\n[axis.load]\ntorque = 1e308\n", "load.torque: 1e.308 is outside -1000..1000"),
    ("[[axis]]\n[axis.load]\ntorque = -inf\n", "outside -1000..1000"),
    ("[[axis]]\n[axis.load]\ninertia = 1e300\n", "outside 0..10"),
    ("[[axis]]\n[axis.drive]\nrated_torque = 0\n", "outside"),
    ("[[axis]]\n[axis.thermal]\nidle = -300\n", "outside -40..200"),
    ("[[axis]]\n[axis.load]\nfriction = nan\n", "expected a number"),
    ("[[axis]]\n[axis.drive]\nkp = 0\n", "kp: 0 is outside 0.001..inf"),
    ("[[axis]]\nstart = inf\n", "start: inf is outside"),
    ("[[axis]]\n[[axis.input]]\nat = inf\ninput = 1\non = true\n", "at: inf is outside 0..1e.09"),
    ("a = " + "[" * 20000 + "]" * 20000 + "\n", "nested too deeply"),   # past any limit
    ("[[axis]]\n[axis.load]\nmass = 1\n", "unknown key 'mass'"),
    ("[[axis]]\n[axis.stoppers]\nccw = 10\ncw = 0\n", "ccw must be below cw"),
    ("[[axis]]\n[axis.cw_limit]\ninput = 2\non = [5]\n", "expected [from, to]"),
    ("[[axis]]\n[axis.cw_limit]\ninput = 9\non = [5, 6]\n", "outside 1..6"),
    ("[[axis]]\n[[axis.input]]\nat = 1\ninput = 1\non = 1\n", "expected true or false"),
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'over_current'\nuntil = 2\n",
     "not a lasting fault"),
    ("[[axis]]\nparams = { X27 = 1 }\n", "not a K parameter"),
    ("[[axis]]\nmotor = 1\n[[axis]]\nmotor = 1\n", "same motor"),
    ("axis = 3\n", "[[axis]] tables"),
    ("[[axis]\n", "not valid TOML"),
])
def test_schema_mistakes_name_the_key(text: str, message: str) -> None:
    with pytest.raises(MachineFileError, match=message.replace("[", r"\[").replace("]", r"\]")
                       .replace("(", r"\(").replace(")", r"\)")):
        parse_machine(text, "m.toml")


@pytest.mark.parametrize("text, message", [
    ("[[axis]]\nmotor = 2\n", "no motor ID2"),
    ("[[axis]]\nparams = { K27 = 7777777 }\n", "motor 1"),
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'gremlins'\n", "unknown fault"),
    ("[[axis]]\n[axis.origin_sensor]\ninput = 6\non = [0, 1]\n", "this firmware has 1..4"),
    # the fault schedule's values are checked when the file is installed (an attack
    # found them failing only when the fault came, as "the motor model raised")
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'overload'\ntorque = nan\n",
     "torque must be a finite number"),
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'over_temperature'\ntemperature = 1e9\n",
     "temperature must be -40..200"),
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'stuck_input'\ninput = 99\non = true\n",
     "input must be 1..6"),
    ("[[axis]]\n[[axis.fault]]\nat = 1\nfault = 'broken_cable'\ncable = 'x'\n",
     "cable must be"),
    ("[[axis]]\n[axis.analog]\nkind = 'sine'\nfrequency = 1e300\n",
     r"frequency must be 0..1e\+06"),
    # a misspelt key of [axis.analog] / [axis.encoder] is an error, as elsewhere
    ("[[axis]]\n[axis.analog]\nkind = 'constant'\nvalu = 2.5\n", "unknown key 'valu'"),
    ("[[axis]]\n[axis.analog]\nkind = 'ramp'\nvalue = 2.5\n", "unknown key 'value'"),
    ("[[axis]]\n[axis.encoder]\nkind = 'load'\nratoi = 0.5\n", "unknown key 'ratoi'"),
    ("[[axis]]\n[axis.encoder]\nkind = 'load'\nrate = 100\n", "unknown key 'rate'"),
])
def test_install_mistakes(text: str, message: str, make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="cm2" if "input = 6" not in text else "rt3")
    with pytest.raises(MachineFileError, match=message):
        chain.load_machine(parse_machine(text))


def test_reserved_tables_go_to_their_modules_or_say_so(make_chain: ChainFactory) -> None:
    text = "[[axis]]\n[axis.encoder]\nratio = 2\n"
    try:
        import coolmuscle.motor.signals.encoder as encoder  # noqa: F401
    except ImportError:
        with pytest.raises(MachineFileError, match="gearing_from_config"):
            make_chain(machine=parse_machine(text))


def test_start_position_and_resolution_scaling(make_chain: ChainFactory) -> None:
    text = ("[[axis]]\nppr = 500\nstart = 1000\n[axis.stoppers]\ncw = 1500\n")
    chain = make_chain(machine=parse_machine(text))   # K37=3: 1000 ppr, twice the file's
    motor = chain.motors[1]
    assert motor.axis.raw_actual() == 2000.0 and chain.execute("?96.1") == ["Px.1=0"]
    chain.execute("S.1=10, P.1=5000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(5))
    assert chain.execute("?96.1") == ["Px.1=1000"]    # the stopper at 3000 raw


def test_scheduled_inputs_and_faults() -> None:
    text = """
[[axis]]
params = { K23 = 3 }
[[axis.input]]
at = 0.5
input = 2
on = true
[[axis.input]]
at = 0.75
input = 2
on = false
[[axis.fault]]
at = 1.0
fault = "supply_voltage"
volts = 20.0
until = 1.5
[[axis.fault]]
at = 2.0
fault = "over_current"
"""
    chain = Chain(machine=parse_machine(text))
    events: list[tuple[float, str]] = []
    chain.subscribe(lambda ev: events.append((ev.time / NS_PER_S, ev.text))
                    if ev.kind != "reply" else None)
    chain.kernel.run(until=seconds(1.2))
    assert chain.execute("?72.1") == ["VSEN.1=200"]
    chain.kernel.run(until=seconds(1.6))
    assert chain.execute("?72.1") == ["VSEN.1=240"]
    chain.kernel.run(until=seconds(3))
    assert events == [(0.5, "IN.1=02"), (0.75, "IN.1=00"), (2.0, "Ux.1=64")]


def test_sensors_follow_the_actual_position_not_the_command(make_chain: ChainFactory) -> None:
    text = "[[axis]]\nparams = { K23 = 2 }\n[[axis.sensor]]\nname = 'flag'\ninput = 4\n" \
           "on = [1000, 2000]\n"
    chain = make_chain(machine=load_machine_text(text))
    events: list[tuple[float, str]] = []
    chain.subscribe(lambda ev: events.append((ev.time / NS_PER_S, ev.text)))
    chain.execute("S.1=100, A.1=100, P.1=3000")
    chain.execute("^.1")
    motor = chain.motors[1]
    chain.kernel.run(until=seconds(1))
    (on_at, on), (off_at, off) = events
    assert (on, off) == ("IN.1=08", "IN.1=00")
    # the shaft lags the command by Pe = 10000/300 pulses at cruise
    assert abs(on_at - (1000 + 500 + 10000 / 300) / 10000) < 1e-6
    assert abs(off_at - (2000 + 500 + 10000 / 300) / 10000) < 1e-6
    assert motor.axis.motion.position_at(round(on_at * NS_PER_S)) >= 1000.0


def load_machine_text(text: str):  # type: ignore[no-untyped-def]
    return parse_machine(text, "test.toml")


def test_cli_run_with_a_machine_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / "origin.cml"
    script.write_text("|.1\n@until Ux\\.1=8 30\n?96.1\n", encoding="utf-8")
    machine = Path(__file__).resolve().parents[1] / "examples" / "linear-axis.toml"
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["run", str(script), "--machine", str(machine)])
    out, err = capsys.readouterr()
    assert exit_info.value.code in (0, None), err
    assert "< Origin.1=" in out and "< Ux.1=8" in out
    bad = tmp_path / "bad.toml"
    bad.write_text("[[axis]]\nbogus = 1\n", encoding="utf-8")
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["run", str(script), "--machine", str(bad)])
    _, err = capsys.readouterr()
    assert exit_info.value.code == 2
    assert err.strip().startswith("coolmuscle: error:") and "bogus" in err
    assert len(err.strip().splitlines()) == 1


def test_a_machine_file_that_is_not_utf8_is_refused_in_one_line(tmp_path: Path) -> None:
    from coolmuscle.chain.machine import load_machine
    path = tmp_path / "m.toml"
    path.write_bytes(b'name = "\xff"\n')
    with pytest.raises(MachineFileError, match="not UTF-8 text"):
        load_machine(path)
