"""Restore (coolmuscle.tools.desk.restorer) on in-process virtual chains: the order of the
parts, only what differs is sent, each part read back; a part the motor refuses stops
the restore and the report says what was and was not written; a backup of another
firmware, or of motors that are not on the line, is refused before anything is sent."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.client.ops import fenced
from coolmuscle.tools.desk import FirmwareMismatchError, parse_backup, plan_restore, render_backup
from coolmuscle.tools.desk.connection import AT_REST
from desk_support import virtual_line

TWO = "coolmuscle://?motors=2&mode=fast"


def test_the_parts_in_order_with_only_what_differs() -> None:
    saved = virtual_line(["K24.1=2000", "K37.2=7", "P3.2=1000000", "B1.2", "S1.2", "END",
                          "K20.1=1", "K23.1=17"], motors=2)    # K20 at once: no K23 16 yet
    backup = saved.read_chain()
    saved.close()
    fresh = virtual_line(["B7.2", "S2.2", "END"], motors=2)
    live = fresh.read_chain()
    fresh.close()
    parts = plan_restore(backup, live, save=True)
    assert [(p.name, p.lines) for p in parts] == [
        ("ID1 K parameters", ("K23.1=17", "K24.1=2000")),
        ("ID1 data", ()),
        ("ID1 banks", ()),
        ("ID2 K parameters", ("K37.2=7",)),
        ("ID2 data", ("P3.2=1000000",)),
        ("ID2 banks", ("B1.2", "S1.2", "END", "B7.2", "END")),   # B7 emptied: no command
        ("line", ("K20.1=1",)),                                 # deletes one bank (2.2.2)
        ("ID1 save", ("$.1",)),
        ("ID2 save", ("$.2",))]


HEAD = "# == ID1 : CM2v3.10R.1 #0802A12345\n"


def test_a_part_the_motor_refuses_stops_the_restore_and_is_named(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    backup = tmp_path / "motor.cml"
    backup.write_text(HEAD + "K23.1=17\nK24.1=2000\nP5.1=7\nB1.1\nS1.1\n^.1\nEND\n"
                      "# == ID2 : CM2v3.10R.1 #0802A12345\nK24.2=3000\n")
    code, out, err = cli(capsys, "restore", str(backup), "--port", TWO, "--save")
    assert code == 1
    assert out.splitlines() == [
        "ID1 K parameters: 2 line(s) written, read back equal",
        "ID1 data: 1 line(s) written, read back equal",
        # ch. 3 K23 16 reports it; "^" is not allowed in a CM2 bank (6.5)
        "ID1 banks: FAILED after 4 of 4 line(s): error03.1: ^ is not allowed in bank.1; "
        "bank B1.1 line 2 reads nothing, the backup has '^.1'",
        "not written: ID2 K parameters, ID1 save, ID2 save; nothing saved ($ not sent)"]
    assert err == f"coolmuscle: restore of {backup} failed at ID1 banks\n"


def test_a_backup_of_another_firmware_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = virtual_line([], firmware="rt3")
    rt3 = tmp_path / "rt3.cml"
    rt3.write_text(render_backup(line.read_chain()))
    line.close()
    code, out, err = cli(capsys, "restore", str(rt3), "--port", "coolmuscle://?mode=fast")
    assert (code, out) == (2, "")
    assert err == (f"coolmuscle: error: {rt3} holds ID1 of rt3 (ID1 : CM1v3.00R.1 "
                   "#0000A00000), coolmuscle://?mode=fast's ID1 is cm2 (ID1 : CM2v3.10R.1 "
                   "#0802A12345): K85, K87 do not apply there; nothing written\n")


def test_motors_that_are_not_on_the_line_are_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    backup = tmp_path / "two.cml"
    backup.write_text(HEAD + "K24.1=2000\n# == ID2 : CM2v3.10R.1 #0802A12345\nK24.2=10\n")
    code, _out, err = cli(capsys, "restore", str(backup), "--port", "coolmuscle://?mode=fast")
    assert code == 2
    assert err == (f"coolmuscle: error: {backup} holds ID1, ID2, coolmuscle://?mode=fast "
                   "answers ID1: ID2 not on the line; nothing written\n")


def test_another_motors_allocation_cannot_be_set() -> None:
    backup = parse_backup(HEAD + "# == ID2 : CM2v3.10R.1 #0802A12345\n"
                          "# ID2 holds P300 N200 R100: \\P and \\N reach ID1 only\n", "b.cml")
    line = virtual_line([], motors=2)
    try:
        with pytest.raises(FirmwareMismatchError, match=r"b.cml holds ID2 with P300 N200 "
                           r"R100, coolmuscle://\?motors=2&firmware=cm2&mode=fast's ID2 has "
                           r"P200 N200 R200: \\P and \\N \(2.1.2\) reach ID1 only"):
            line.restore(backup, name="b.cml")
    finally:
        line.close()


def test_a_moving_motor_is_refused() -> None:
    line = virtual_line(["S.1=10", "P.1=100000", "^.1"])
    try:
        with pytest.raises(ValueError, match=r"ID1 is moving \(Ux.1=0\): stop it before a "
                                             r"restore"):
            line.restore(parse_backup(HEAD + "K24.1=2000\n", "b.cml"))
        assert line.run(fenced(line.session, 1, ("K24.1",)))[0].text == "K24.1=1000"
    finally:
        line.close()
    assert AT_REST & 8 and AT_REST & 16


def test_an_existing_backup_is_not_overwritten(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    kept = tmp_path / "motor.cml"
    kept.write_text("precious\n")
    code, _out, err = cli(capsys, "backup", "coolmuscle://?mode=fast", "-o", str(kept))
    assert (code, err, kept.read_text()) == \
        (2, f"coolmuscle: error: {kept} exists (--force replaces it)\n", "precious\n")
    code, _out, err = cli(capsys, "backup", "coolmuscle://?mode=fast", "-o", str(kept),
                         "--force")
    assert code == 0 and kept.read_text().startswith("# coolmuscle backup of ")
    assert [p.name for p in tmp_path.iterdir()] == ["motor.cml"]      # no temporary left


def test_k65_of_the_other_motors_follows_a_change_of_id1s() -> None:
    saved = virtual_line(["K65.1=5", "K65.2=0"], motors=2)      # ID1's is copied (ch. 3 K65)
    backup = saved.read_chain()
    saved.close()
    assert (backup.motor(1).params[65], backup.motor(2).params[65]) == (5, 0)
    line = virtual_line([], motors=2)
    try:
        report = line.restore(backup)
        assert report.ok, report.lines()
        assert report.lines()[3] == "ID2 K parameters: 1 line(s) written, read back equal"
    finally:
        line.close()
