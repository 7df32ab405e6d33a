"""Direct mode through the device API: listings, saving as a power cycle, routing.

cml-users-guide.txt 2.1.2 "$" (save), ch. 3 (K changes persist by themselves; K37
40-70 without incremental motion; K20 asked about under K23 16), 6.6 (?P ?N ?R ?999),
1.1 (motor IDs on a chain); docs/fidelity.md ("K37 = 40..70", "K20 with K23 including
16").
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import NoSuchMotorError
from coolmuscle.sim.kernel import seconds
from fixtures import ChainFactory, collect_events


def test_6_6_position_listing_has_200_values_four_to_a_line(make_chain: ChainFactory) -> None:
    chain = make_chain()
    chain.execute("P200.1=-42")
    lines = chain.execute("?P.1")
    assert len(lines) == 50
    assert lines[0] == "P1.1=0, P2.1=0, P3.1=0, P4.1=0"
    assert lines[-1] == "P197.1=0, P198.1=0, P199.1=0, P200.1=-42"


def test_6_6_all_data_list_is_p_s_a_t_m_n_r_v_in_order(make_chain: ChainFactory) -> None:
    chain = make_chain()
    lines = chain.execute("?999.1")
    firsts = [line.split("=")[0] for line in lines]
    starts = [i for i, name in enumerate(firsts) if name.startswith(("P1.", "S1.", "A1.",
              "T1.", "M1.", "N1.", "R1.", "V1."))]
    assert [firsts[i][0] for i in starts] == list("PSATMNRV")
    assert len(lines) == 50 + 4 + 2 + 2 + 2 + 50 + 50 + 4


def test_2_1_2_save_then_power_cycle_restores_saved_data_only(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("P1.1=1234, V2.1=\"abcd\", S3.1=-77")
    assert chain.execute("$.1") == ["saved.1"]
    chain.execute("P1.1=999, P2.1=555")          # not saved: lost at power off
    chain.close()
    again = make_chain(state_dir=tmp_path)
    try:
        assert again.execute("P1.1") == ["P1.1=1234"]
        assert again.execute("P2.1") == ["P2.1=0"]
        assert again.execute("V2.1") == ['V2.1="abcd"']
        assert again.execute("S3.1") == ["S3.1=-77"]
    finally:
        again.close()


def test_device_api_save_takes_the_motor_id_as_dollar_does(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    """``Device.save(motor)`` is ``$.n`` (docs/device-api.md); an ID not on the chain is
    ``NoSuchMotorError``, as for every other device call."""
    chain = make_chain(motors=2, state_dir=tmp_path)
    chain.execute("P1.2=4321")
    chain.save(2)
    with pytest.raises(NoSuchMotorError):
        chain.save(3)
    chain.close()
    again = make_chain(motors=2, state_dir=tmp_path)
    try:
        assert again.execute("P1.2") == ["P1.2=4321"]
    finally:
        again.close()


def test_ch3_k_changes_persist_without_save(tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("K23.1=17")
    chain.execute("K70.1=0")
    chain.execute("K37.1=9")                      # out of range: not applied, not saved
    chain.close()
    again = make_chain(state_dir=tmp_path)
    try:
        assert again.execute("K23.1") == ["K23.1=17"]
        assert again.execute("K70.1") == ["K70.1=0"]
        assert again.execute("K37.1") == ["K37.1=3"]
    finally:
        again.close()


def test_power_cycle_starts_at_position_zero_in_position(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("P.1=3000, ^.1")
    chain.kernel.run(until=seconds(2))
    chain.execute("$.1")
    chain.close()
    again = make_chain(state_dir=tmp_path)
    try:
        assert again.execute("?96.1") == ["Px.1=0"]
        assert again.execute("?99.1") == ["Ux.1=8"]
        assert again.execute("P.1") == ["P.1=3000"]
    finally:
        again.close()


def test_k68_zero_powers_up_motor_free(tmp_path: Path, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=tmp_path)
    chain.execute("K68.1=0")
    chain.close()
    again = make_chain(state_dir=tmp_path)
    try:
        assert again.execute("?99.1") == ["Ux.1=16"]
    finally:
        again.close()


def test_1_1_statements_go_to_the_motor_their_id_names(make_chain: ChainFactory) -> None:
    chain = make_chain(motors=3)
    assert chain.execute("P1.2=22, P1.3=33, P1.1=11") == []
    assert chain.execute("P1.1, P1.2, P1.3") == ["P1.1=11", "P1.2=22", "P1.3=33"]
    assert chain.execute("?96.4") == []           # no ID4 on the chain: nobody answers
    assert chain.execute("P1") == ["P1.1=11"]     # no ID: the motor the host is on (ID1)


def test_api_replies_do_not_appear_on_the_host_line(make_chain: ChainFactory) -> None:
    chain = make_chain()
    seen: list[bytes] = []
    chain.host_line.add_listener(seen.append)
    assert chain.execute("?96.1") == ["Px.1=0"]
    assert seen == []
    chain.host_line.feed(b"?96.1\r")
    assert b"".join(seen) == b"?96.1\r\nPx.1=0\r\n"


def test_device_api_reads_a_numeric_v_as_an_int(make_chain: ChainFactory) -> None:
    chain = make_chain()
    chain.execute("V1.1=-5, V2.1=\"ab\", V3.1=\"Px\"")
    assert chain.get_register(1, "V", 1) == -5
    assert chain.get_register(1, "V", 2) == '"ab"'
    assert chain.get_register(1, "V", 3) == '"Px"'


def test_a_branch_statement_for_an_absent_id_does_not_run_on_this_motor(
        make_chain: ChainFactory) -> None:
    chain = make_chain(motors=2)
    chain.execute("V1.1=1")
    chain.execute("V1.1, P5.3=77, P5.3=66")
    assert chain.execute("P5.1") == ["P5.1=0"]
    chain.execute("V1.1, P5.2=77, P5.2=66")
    assert chain.execute("P5.2") == ["P5.2=77"]


# -- K37 --------------------------------------------------------------------------------
def test_ch3_k37_40_to_70_incremental_motion_cannot_be_executed(
        make_chain: ChainFactory) -> None:
    # K37: "When it is set to 40-70, the incremental motion cannot be executed."
    # "Continuous motion (P=1000000000) is still available in any resolution."
    chain = make_chain(setup="K23.1=17, K37.1=43, S.1=10, A.1=100")
    assert chain.execute("P.1+=100") == ["error00.1: Out Of Range!!"]
    assert chain.execute("P.1-=100") == ["error00.1: Out Of Range!!"]
    assert chain.execute("P.1") == ["P.1=0"]
    for line in ("P1.1=500", "S1.1=10", "A1.1=100", "B1.1", "S1.1, A1.1, P1.1+", "?96.1",
                 "END"):
        chain.execute(line)
    said = collect_events(chain, ["status", "alarm", "message", "reply"])
    chain.execute("[1.1")
    chain.kernel.run(until=seconds(2))
    assert "error00.1: Out Of Range!!" in [e.text for e in said]       # from the bank
    assert chain.execute("?96.1") == ["Px.1=0"]          # it did not move
    chain.execute("P.1=1000000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?97.1") == ["Sx.1=10"]          # continuous rotation runs
    # at K37 = 3 the same lines move
    chain2 = make_chain(setup="S.1=10, A.1=100")
    chain2.execute("P.1+=100")
    assert chain2.execute("P.1") == ["P.1=100"]


# -- K20 / K23 16 ----------------------------------------------------------------------
def test_ch3_k23_16_k20_change_asks_change_baud_rate_y_n(chain: Chain) -> None:
    # K23 16 confirmation messages: "Change Baud Rate ?? XXX kbps (Y/N)  Confirmation
    # message when the baud rate is changed by K20"; K20 table 1 = 9.6 kbps
    chain.execute("K23.1=17, S.1=10, A.1=100, P.1=1000")
    assert chain.execute("K20.1=1") == ["Change Baud Rate ?? 9.6 kbps (Y/N)"]
    assert chain.motors[1].k(20) == 0                     # not changed before the answer
    assert chain.execute("Y") == []                        # the answer, not the Y command
    assert chain.execute("K20.1") == ["K20.1=1"]
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=0"]           # no Y motion was started
    assert chain.execute("K20.1=4") == ["Change Baud Rate ?? 115.2 kbps (Y/N)"]
    assert chain.execute("n") == []
    assert chain.execute("K20.1") == ["K20.1=1"]
    # another line instead of an answer cancels the change and runs
    assert chain.execute("K20.1=0") == ["Change Baud Rate ?? 38.4 kbps (Y/N)"]
    assert chain.execute("?99.1") == ["Ux.1=8"]
    assert chain.execute("K20.1") == ["K20.1=1"]
    assert chain.execute("K20.1=6") == ["error00.1: Out Of Range!!"]


def test_ch3_k20_without_k23_16_changes_at_once(chain: Chain) -> None:
    assert chain.execute("K20.1=2") == []
    assert chain.execute("K20.1") == ["K20.1=2"]
