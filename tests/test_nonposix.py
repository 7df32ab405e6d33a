"""Everything that needs only sockets and files runs where POSIX is missing, as on Windows.

Every ``coolmuscle`` process here starts with tests/nonposix_site on ``PYTHONPATH``: its
``sitecustomize`` makes ``fcntl``, ``termios``, ``pty``, ``tty``, ``resource``, ``pwd``
and ``grp`` impossible to import and deletes what Windows lacks (``socket.AF_PACKET``,
``os.getuid``, ``os.setsid``, ``os.killpg``, ``os.openpty``, ``os.sched_setscheduler``,
``signal.SIGHUP``, ``signal.pthread_sigmask`` ...); ``multiprocessing`` has only the
``spawn`` start method.  Real peers talk to it: pyserial (``socket://``), pymodbus,
pycomm3, an HTTP GET; the command line runs ``run``, ``batch`` (with a process pool),
``sweep``, ``check``, ``upload``, ``term`` (its input from a pipe), ``capture`` over TCP,
the host library and an RFC 2217 port (``sim --rfc2217``, pyserial's ``rfc2217://``);
one sim per state directory still holds.  What needs POSIX
(``--pty``, ``--stdio``, ``--modbus-rtu``, ``--com1``, ``capture --pty``, ``--ethercat``)
is refused with one line and exit status 2.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from coolmuscle.testing.served import Program, ServedSim, child_env

ROOT = Path(__file__).resolve().parents[1]
SITE = Path(__file__).with_name("nonposix_site")
EXAMPLE = ROOT / "examples" / "2.1-operation.cml"

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("nonposix")]


def env(**extra: str) -> dict[str, str]:
    """This environment with the blocker first on ``PYTHONPATH``."""
    base = dict(os.environ)
    base["PYTHONPATH"] = os.pathsep.join(
        [str(SITE)] + [p for p in base.get("PYTHONPATH", "").split(os.pathsep) if p])
    return child_env(base, **extra)


def coolmuscle(*args: str, stdin: str | None = None, timeout: float = 120,
               cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coolmuscle", *args], env=env(),
                          input=stdin, capture_output=True, text=True, timeout=timeout,
                          cwd=cwd, stdin=None if stdin is not None else subprocess.DEVNULL)


def python(code: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], env=env(), capture_output=True,
                          text=True, timeout=timeout)


def served(tmp_path: Path, name: str, *args: str, **options: object) -> ServedSim:
    return ServedSim(tmp_path / f"{name}.log", *args, env=env(), **options)  # type: ignore[arg-type]


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[ServedSim]:
    """A CM2 on TCP, Modbus TCP and the web page, with a state directory."""
    with served(tmp_path, "sim", modbus_tcp=True, web=True, state=tmp_path / "state") as one:
        yield one


def test_the_blocker_takes_away_what_windows_lacks() -> None:
    """The bootstrap is in place in the children: the modules cannot be imported, the
    attributes are gone, multiprocessing only spawns."""
    code = ("import importlib, os, signal, socket, multiprocessing as mp\n"
            "for name in ('fcntl', 'termios', 'pty', 'tty', 'resource', 'pwd', 'grp'):\n"
            "    try:\n"
            "        importlib.import_module(name)\n"
            "    except ImportError:\n"
            "        pass\n"
            "    else:\n"
            "        print('imported', name)\n"
            "print(hasattr(socket, 'AF_PACKET'), hasattr(os, 'getuid'), hasattr(os, 'setsid'),"
            " hasattr(os, 'killpg'), hasattr(os, 'openpty'), hasattr(signal, 'SIGHUP'),"
            " hasattr(signal, 'pthread_sigmask'), hasattr(os, 'sched_setscheduler'))\n"
            "print(mp.get_all_start_methods(), mp.get_start_method())\n")
    done = python(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["False False False False False False False False",
                                        "['spawn'] spawn"]


def test_sim_on_tcp_modbus_tcp_and_the_web_page_with_real_peers(sim: ServedSim,
                                                                 tmp_path: Path) -> None:
    with serial.serial_for_url(sim.url, timeout=2) as port:     # pyserial, as a host does
        port.write(b"K37.1=7\r")
        port.write(b"?96.1\r")
        assert port.read_until(b"Px.1=0\r\n").endswith(b"?96.1\r\nPx.1=0\r\n")
    from pymodbus.client import ModbusTcpClient

    client = ModbusTcpClient("127.0.0.1", port=sim.modbus_port, timeout=2, retries=0)
    assert client.connect()
    try:
        assert not client.write_registers(200, [0, 777], device_id=1).isError()
        assert client.read_holding_registers(200, count=2, device_id=1).registers == [0, 777]
    finally:
        client.close()
    with urllib.request.urlopen(sim.web_url, timeout=10) as page:
        assert page.status == 200 and b"<html" in page.read().lower()

    second = Program(["sim", "--tcp", "0", "--state", str(tmp_path / "state")],
                     tmp_path / "second.log", env=env())
    try:                                 # one sim per state directory, without flock
        assert second.proc.wait(timeout=60) == 1
    finally:
        second.close()
    lines = second.text.strip().splitlines()
    assert len(lines) == 1 and "is in use: another coolmuscle (pid " \
        f"{sim.pid})" in lines[0], lines

    assert sim.signal() in (130, 0), sim.text       # Ctrl-C: the saved K37 stays
    with served(tmp_path, "again", state=tmp_path / "state") as again:
        with serial.serial_for_url(again.url, timeout=2) as port:
            port.write(b"K37.1\r")
            assert port.read_until(b"K37.1=7\r\n").endswith(b"K37.1=7\r\n")


def test_an_rfc2217_port_is_the_com_port_where_there_is_no_pty(tmp_path: Path) -> None:
    """``sim --rfc2217``: a serial port that pyserial's ``rfc2217://`` client (and a
    virtual COM port tool) opens, its rate told to the paced line as a pty's would be;
    ``term`` reaches it too."""
    with served(tmp_path, "rfc", "--pace", tcp=False, rfc2217=True) as sim:
        with serial.serial_for_url(sim.rfc2217_url, baudrate=38400, timeout=2) as port:
            port.write(b"?96.1\r")
            assert port.read_until(b"Px.1=0\r\n").endswith(b"?96.1\r\nPx.1=0\r\n")
            port.baudrate = 9600                 # another rate than K20: garbage
            port.timeout = 0.5
            port.reset_input_buffer()
            port.write(b"?96.1\r")
            assert b"Px.1" not in port.read(64)
        done = coolmuscle("term", sim.rfc2217_url, "--timeout", "0.5", stdin="?96.1\n:quit\n")
        assert (done.returncode, done.stdout) == (0, "Px.1=0\n"), done


def test_ethernet_ip_with_pycomm3(tmp_path: Path) -> None:
    from pycomm3 import CIPDriver

    with served(tmp_path, "cm1", "--firmware", "cm1", tcp=False, enip=True) as cm1:
        with CIPDriver(f"127.0.0.1:{cm1.enip_port}") as plc:
            identity = plc.generic_message(service=0x0E, class_code=1, instance=1,
                                           attribute=7, connected=False, route_path=False)
            assert not identity.error, identity.error
            assert b"COOL MUSCLE" in bytes(identity.value).upper()
            status = plc.generic_message(service=0x0E, class_code=4, instance=101,
                                         attribute=3, connected=False, route_path=False)
            assert not status.error and len(bytes(status.value)) == 8


def test_run_check_batch_and_sweep(tmp_path: Path) -> None:
    done = coolmuscle("run", str(EXAMPLE), "--trace", str(tmp_path / "t.csv"))
    assert done.returncode == 0 and "< Px.1=0" in done.stdout, done
    assert (tmp_path / "t.csv").stat().st_size > 1000
    done = coolmuscle("check", str(EXAMPLE))
    assert done.returncode == 0 and "0 errors" in done.stdout, done
    data = ROOT / "tests" / "data" / "batch"
    done = coolmuscle("batch", str(data / "2.1-operation.cml"), str(data / "6.3-loop.cml"),
                      "--jobs", "2", "--results", str(tmp_path / "r.csv"))
    assert done.returncode == 0, done               # two spawned workers
    assert len((tmp_path / "r.csv").read_text().splitlines()) == 3
    done = coolmuscle("sweep", str(data / "sweep" / "move.cml"), "--vary", "SPEED=100,250",
                      "--vary", "ACCEL=100", "--jobs", "1", "--results",
                      str(tmp_path / "s.csv"))
    assert done.returncode == 0, done
    assert len((tmp_path / "s.csv").read_text().splitlines()) == 3


def test_upload_term_and_the_client_on_a_served_sim(sim: ServedSim, tmp_path: Path) -> None:
    done = coolmuscle("upload", str(ROOT / "examples" / "2.2-program-bank.cml"), "--port",
                      sim.url)
    assert done.returncode == 0, done
    assert "verified" in done.stdout, done

    done = coolmuscle("term", sim.url, "--timeout", "0.5", stdin="?96.1\n:quit\n")
    assert done.returncode == 0, done        # the bank's program may have moved it
    assert re.fullmatch(r"Px\.1=-?\d+\n", done.stdout), done

    code = ("import coolmuscle\n"
            f"with coolmuscle.connect({sim.url!r}) as m:\n"
            "    m.write_param(37, 3)\n"
            "    print(type(m.get_position()).__name__, m.read_param(37))\n")
    done = python(code)
    assert done.returncode == 0 and done.stdout == "int 3\n", done


def test_capture_relays_over_tcp(sim: ServedSim, tmp_path: Path) -> None:
    out = tmp_path / "session.cml"
    relay = Program(["capture", sim.url, "--out", str(out), "--listen", "0", "--once"],
                    tmp_path / "capture.log", env=env())
    try:
        found = relay.wait_for(r"host program on socket://127\.0\.0\.1:(\d+)", 60)
        with serial.serial_for_url(f"socket://127.0.0.1:{found.group(1)}", timeout=2) as port:
            port.write(b"?96.1\r")
            assert port.read_until(b"Px.1=0\r\n").endswith(b"Px.1=0\r\n")
        assert relay.proc.wait(timeout=30) == 0, relay.text
    finally:
        relay.close()
    text = out.read_text()
    assert "\n?96.1\n" in text and "<< Px.1=0\\r\\n" in text, text


@pytest.mark.parametrize("args, line", [
    (["sim", "--pty"], "coolmuscle: error: --pty needs a POSIX system (Linux, macOS); on "
                       "Windows use --rfc2217 [HOST:]PORT (a COM port to rfc2217:// clients "
                       'and virtual COM port tools) or --tcp (README.md "Windows")'),
    (["sim", "--stdio"], "coolmuscle: error: --stdio needs a POSIX system (Linux, macOS); on "
                         "Windows use --tcp"),
    (["sim", "--modbus-rtu", "pty"], "coolmuscle: error: --modbus-rtu needs a POSIX system "
                                     "(Linux, macOS); on Windows use --modbus-tcp"),
    (["sim", "--ethercat", "eth9"], "coolmuscle: error: --ethercat needs Linux (a raw "
                                    "AF_PACKET socket for the EtherCAT frames)"),
    (["capture", "socket://127.0.0.1:9", "--out", "{tmp}/c.cml", "--pty", "{tmp}/link"],
     "coolmuscle: error: --pty needs a POSIX system (Linux, macOS); on Windows use --listen "
     "[HOST:]PORT and a virtual COM port tool"),
])
def test_what_needs_posix_is_refused_in_one_line(args: list[str], line: str,
                                                 tmp_path: Path) -> None:
    done = coolmuscle(*[a.format(tmp=tmp_path) for a in args])
    assert (done.returncode, done.stdout, done.stderr) == (2, "", line + "\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
