"""The backup file (coolmuscle.tools.desk.backupfile): written in the order a restore
writes, read back to the same motors, and every line checked as the motor would check
it, a refusal naming the line."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from coolmuscle.client.aio_driver import AsyncDriver
from coolmuscle.client.banks import send_line
from coolmuscle.client.ops import Session
from coolmuscle.client.sync import open_port
from coolmuscle.tools.desk import (
    BackupFileError,
    MotorImage,
    load_backup,
    parse_backup,
    render_backup,
)
from coolmuscle.tools.desk.reading import read_motor
from desk_support import virtual_line

SETUP = ["K23.1=17", "K24.1=2000", "P15.1=100", 'V1.1="a,b"', 'V2.1="Px"', "H0.1=12",
         "S.1=50", "B1.1", "S1.1,A1.1,P1.1", "END", "L2.1", "I1.1&&I2.1,O1.1", "END",
         "B4.1", "END", "K37.2=7", "P3.2=1000000"]


def test_a_backup_reads_back_to_the_motors_it_was_made_of() -> None:
    line = virtual_line(SETUP, motors=2)
    try:
        image = line.read_chain()
    finally:
        line.close()
    text = render_backup(image)
    again = parse_backup(text, "motor.cml")
    assert again.motors == image.motors
    assert (again.source, again.taken) == (image.source, image.taken)
    lines = text.splitlines()
    assert lines[2:7] == ["# coolmuscle: motors=2 firmware=cm2",
                          "# == ID1 : CM2v3.10R.1 #0802A12345",
                          "# ID1 K parameters (ch. 3, table 6.1); K82, K20, K81 at the end",
                          "K23.1=17", "K24.1=2000"]
    assert "K20.1=0" not in lines[:lines.index("# == ID2 : CM2v3.10R.1 #0802A12345")]
    data = lines.index("# ID1 data (6.2): allocation (2.1.2), memories, H0, direct mode (?.n)")
    assert lines[data + 1:data + 3] == ["\\P200", "\\N200"]
    assert ['V1.1="a,b"', 'V2.1="Px"', "H0.1=12", "P.1=0", "S.1=50"] == \
        [x for x in lines if x.startswith(("V1.1", "V2.1", "H0.1", "P.1", "S.1="))]
    banks = lines.index("# ID1 banks (?1000)")
    assert lines[banks + 1:banks + 9] == ["B1.1", "S1.1, A1.1, P1.1", "END", "B4.1", "END",
                                          "L2.1", "I1.1&&I2.1, O1.1", "END"]
    assert "# ID2 holds P200 N200 R200: \\P and \\N (2.1.2) name no motor ID and reach ID1 " \
           "only" in lines
    assert lines[-8:] == ["# The line, last: K82 parity, K20 baud rate, K81 COM0 station "
                          "(Modbus RTU)", "K82.2=0", "K20.2=0", "K81.2=0", "K82.1=0",
                          "K20.1=0", "Y", "K81.1=0"]


HEAD = "# == ID1 : CM2v3.10R.1 #0802A12345\n"


@pytest.mark.parametrize("body, message", [
    ("K24.1=5\n", "line 2: K24=5 is out of range (10..50000) on cm2 (ID1)"),
    ("K25.1=333303\n", "line 2: K25=333303 is out of range (111111..999999 digit by digit) "
                       "on cm2 (ID1)"),
    ("K52.1=1\n", "line 2: K52 is not defined on cm2 (it reads 0) on cm2 (ID1)"),
    ("K90.1=1\n", "line 2: K90 does not exist (K20..K89) on cm2 (ID1)"),
    ("K24.2=1000\n", "line 2: ID2 has no '# == ID2 : ...' title line before it (the "
                     "firmware of each motor comes from it)"),
    ("A3.1=0\n", "line 2: A3.1=0: A=0 is out of range 1..32767"),
    ("P201.1=0\n", "line 2: P201.1=0: P201 does not exist on cm2 (P0..P200)"),
    ('V1.1="abcde"\n', "line 2: V1.1=\"abcde\": V string 'abcde' must be 1-4 one-byte "
                       "characters"),
    ("K37.1=0\nP1.1=9000000\n", "line 3: P1.1=9000000: P=9000000 is beyond ±8589934 "
                                 "(K37=0)"),
    ("S2.1=fast\n", "line 2: S2.1=fast: not a number"),
    ("\\P700\n", "line 2: \\P700: \\P700: 0..600"),
    ("B31.1\nEND\n", "line 2: bank B31.1 does not exist on cm2 (1..30)"),
    ("B1.1\nS1.1,,\nEND\n", "line 3: bank B1.1: "),
    ("B1.1\nS1.1\n", "line 2: bank B1 has no END"),
    ("^.1\n", "line 2: not a line of a coolmuscle backup: '^.1'"),
    ("Y\n", "line 2: not a line of a coolmuscle backup: 'Y'"),
])
def test_a_line_the_motor_would_refuse_is_named(body: str, message: str) -> None:
    with pytest.raises(BackupFileError) as caught:
        parse_backup(HEAD + body, "motor.cml")
    assert str(caught.value).startswith(f"motor.cml {message}")


def test_a_c_type_motor_has_no_n_and_r() -> None:
    with pytest.raises(BackupFileError, match=r"line 2: N1.1=0: no N data on a C type motor"):
        parse_backup("# == ID1 : CM2v3.10C.1 #0802A12345\nN1.1=0\n", "motor.cml")


def test_a_partial_backup_holds_what_it_gives() -> None:
    image = parse_backup(HEAD + "K24.1=2000\nK20.1=0\nN\nP3.1=+0012\n", "motor.cml")
    motor = image.motor(1)
    assert (dict(motor.params), dict(motor.data), dict(motor.banks)) == \
        ({20: 0, 24: 2000}, {"P3": "12"}, {})


def test_files_that_are_no_backup(tmp_path: Path) -> None:
    cases = {tmp_path / "missing.cml": "cannot read {p}: No such file or directory",
             tmp_path: "{p} is a directory, not a backup file"}
    binary = tmp_path / "binary.cml"
    binary.write_bytes(b"# == ID1\xff\xfe")
    cases[binary] = "{p}: not a text file (byte 8 is not UTF-8)"
    empty = tmp_path / "empty.cml"
    empty.write_text("# nothing here\nK24.1=10\n")
    cases[empty] = ("{p} line 2: ID1 has no '# == ID1 : ...' title line before it (the "
                    "firmware of each motor comes from it)")
    script = tmp_path / "script.cml"
    script.write_text("# a script\n")
    cases[script] = "{p}: not a coolmuscle backup (no '# == ID1 : ...' title line)"
    for path, message in cases.items():
        with pytest.raises(BackupFileError) as caught:
            load_backup(path)
        assert str(caught.value) == message.format(p=path)


def test_the_reading_operations_run_on_the_asyncio_driver_too() -> None:
    async def read() -> MotorImage:
        port = open_port("coolmuscle://?mode=fast")
        driver = AsyncDriver(port, Session(timeout=5))
        driver.start()
        try:
            await driver.run(send_line(driver.session, 1, "K24.1=2000"))
            return await driver.run(read_motor(driver.session, 1))
        finally:
            driver.close()
            port.close()

    line = virtual_line(["K24.1=2000"])
    try:
        assert asyncio.run(read()) == line.run(read_motor(line.session, 1))
    finally:
        line.close()
