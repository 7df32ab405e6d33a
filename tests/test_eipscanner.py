"""EIPScanner (the C++ EtherNet/IP scanner library) as a second Class 1 originator.

tests/eipscanner_originator.cpp is our own small program on EIPScanner's public API;
this test builds it with cmake in a temporary folder against an installed EIPScanner
and runs it against ``coolmuscle sim --firmware cm1 --enip``: Forward_Open to the
assemblies 0x80/0x66/0x65 at RPI 10 ms, a move through O->T, the status through T->O,
Forward_Close, then the input assembly by explicit messaging
(cm1-ethernetip-interface-manual.txt 3.1, 3.2, ch. 4).

EIPScanner is neither on PyPI nor in Debian: where it is not installed the test is
skipped and says how to provide it (docs/wireshark.md "A second Class 1 originator").
EIPScanner binds UDP 2222 on every address to receive T->O, so the module's own I/O
port is a free one (its Forward_Open reply names it); as root everything runs in a
network namespace of its own.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from wireshark_support import in_net, private_net, sim_process

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "eipscanner_originator.cpp"
TARGET = 4000
BUILD_TIMEOUT = 300
RUN_TIMEOUT = 60
PREFIXES = [os.environ.get("EIPSCANNER_PREFIX", ""), "/usr/local", "/usr"]
HOW = ("EIPScanner is not installed: install the library (nimbuscontrols/EIPScanner, a CMake "
       "project; neither on PyPI nor in Debian) and point EIPSCANNER_PREFIX at its prefix "
       "(PREFIX/include/EIPScanner, PREFIX/lib)")

CMAKELISTS = """\
cmake_minimum_required(VERSION 3.13)
project(cm1_originator CXX)
set(CMAKE_CXX_STANDARD 20)
set(CMAKE_CXX_STANDARD_REQUIRED ON)
find_path(EIPSCANNER_INCLUDE ConnectionManager.h
          PATHS "${EIPSCANNER_PREFIX}/include/EIPScanner" NO_DEFAULT_PATH REQUIRED)
find_library(EIPSCANNER_LIBRARY NAMES EIPScanner
             PATHS "${EIPSCANNER_PREFIX}/lib" "${EIPSCANNER_PREFIX}/lib64" NO_DEFAULT_PATH REQUIRED)
find_package(Threads REQUIRED)
add_executable(eipscanner_originator "${ORIGINATOR_SOURCE}")
target_include_directories(eipscanner_originator PRIVATE "${EIPSCANNER_INCLUDE}")
target_link_libraries(eipscanner_originator PRIVATE "${EIPSCANNER_LIBRARY}" Threads::Threads)
get_filename_component(EIPSCANNER_LIBDIR "${EIPSCANNER_LIBRARY}" DIRECTORY)
set_target_properties(eipscanner_originator PROPERTIES BUILD_RPATH "${EIPSCANNER_LIBDIR}")
"""


def eipscanner_prefix() -> Path | None:
    """The installation prefix of EIPScanner (headers and library), or ``None``."""
    for prefix in filter(None, PREFIXES):
        root = Path(prefix)
        if (root / "include" / "EIPScanner" / "ConnectionManager.h").is_file() and any(
                (root / lib).glob("libEIPScanner*") for lib in ("lib", "lib64")):
            return root
    return None


def missing() -> str | None:
    for tool in ("cmake", "c++"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (apt-get install cmake g++)"
    if eipscanner_prefix() is None:
        return HOW
    return None


WHY = missing()
pytestmark = [pytest.mark.peer, pytest.mark.realtime]


def build(prefix: Path, where: Path) -> Path:
    """Configure and build the originator in ``where``; returns the program."""
    (where / "CMakeLists.txt").write_text(CMAKELISTS)
    steps = [["cmake", "-S", str(where), "-B", str(where / "build"), "-DCMAKE_BUILD_TYPE=Release",
              f"-DEIPSCANNER_PREFIX={prefix}", f"-DORIGINATOR_SOURCE={SOURCE}"],
             ["cmake", "--build", str(where / "build")]]
    for step in steps:
        done = subprocess.run(step, capture_output=True, text=True, timeout=BUILD_TIMEOUT,
                              check=False)
        assert done.returncode == 0, \
            f"{' '.join(step)}:\n{done.stdout[-3000:]}{done.stderr[-3000:]}"
    return where / "build" / "eipscanner_originator"


@contextmanager
def where_to_run() -> Iterator[str | None]:
    """A namespace of its own as root (UDP 2222 and 44818 free); else this one."""
    if os.geteuid() == 0 and shutil.which("ip"):
        with private_net() as ns:
            yield ns
    else:
        yield None


@pytest.mark.skipif(WHY is not None, reason=f"EIPScanner originator: {WHY}")
def test_eipscanner_class1_originator_moves_the_motor_and_reads_its_status_ch4(
        tmp_path: Path) -> None:
    prefix = eipscanner_prefix()
    assert prefix is not None
    program = build(prefix, tmp_path)
    with where_to_run() as ns:
        endpoint = "127.0.0.1" if ns else "127.0.0.1:0"
        rt = ("--enip-rt-priority", "10") if os.geteuid() == 0 else ()
        with sim_process(ns, "--firmware", "cm1", "--enip", endpoint, "--enip-io-port", "0", *rt,
                         banner=r"enip: ([\d.]+):(\d+) \(I/O udp (\d+)\)") as banner:
            port, io_port = int(banner.group(2)), int(banner.group(3))
            assert io_port != 2222                   # EIPScanner's own T->O port
            done = subprocess.run(in_net(ns, [str(program), "127.0.0.1", str(port), str(TARGET)]),
                                  capture_output=True, text=True, timeout=RUN_TIMEOUT,
                                  check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    print(json.dumps(result), file=sys.stderr)
    assert result["opened"] and result["open_until_close"] and not result["timed_out"]
    assert result["saw_running"]                              # 3.1: 0 while it moves
    assert result["last"] == [0, 8, TARGET]                   # in position at P0, via T->O
    assert result["explicit_ok"] and result["explicit"] == [0, 8, TARGET]
    assert result["counts_step_by_one"]                       # CIP sequence count +1
    assert result["received"] > 30
    assert abs(result["median_interval_ms"] - 10.0) < 2.0     # RPI 10 ms

