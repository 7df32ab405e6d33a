"""The station's banks on a virtual motor, in virtual time (the ``cm_chain`` fixture).

``CONVEYOR_BANKS=banks/pick_broken.cml pytest`` runs them on the broken variant: the
placement test fails and its message names the CML line that was running.
"""

from __future__ import annotations

import os

import pytest

BANKS = os.environ.get("CONVEYOR_BANKS", "banks/pick.cml")


@pytest.fixture
def station(cm_chain):
    """The banks loaded, the ladder scanning, a cycle started and run to its end."""
    cm_chain.load(BANKS)
    cm_chain.send("[L1.1")
    cm_chain.send("[1.1")
    cm_chain.run(3.5)
    return cm_chain


def test_the_part_is_picked_at_2000_and_placed_at_6000(station):
    motor = station.expect(1)
    motor.position(2000, within=2, by=0.5)
    motor.position(6000, within=2, by=1.6)
    motor.in_position(by=3.2)
    motor.position(0, within=2, by=3.2)


def test_the_gripper_closes_at_the_pick_station(station):
    motor = station.expect(1)
    motor.output(2, on=False, between=(0.0, 0.4))
    motor.output(2, on=True, between=(0.5, 0.6))


def test_a_cycle_raises_no_alarm_and_stays_within_the_ratings(station):
    motor = station.expect(1)
    motor.no_alarm()
    motor.peak_speed_below(6000)
    motor.peak_torque_below(100)
    motor.peak_temperature_below(60)


def test_the_busy_lamp_follows_the_part_sensor(cm_chain):
    cm_chain.load(BANKS)
    cm_chain.send("[L1.1")
    cm_chain.run(0.05)
    cm_chain.set_input(1, 1, True)
    cm_chain.run(0.05)
    cm_chain.set_input(1, 1, False)
    cm_chain.run(0.05)
    lamp = cm_chain.expect(1)
    lamp.output(1, on=False, between=(0.0, 0.05))
    lamp.output(1, on=True, between=(0.07, 0.1))
    lamp.output(1, on=False, between=(0.12, 0.15))


@pytest.mark.cm_chain(setup=["P1.1=2000"])
def test_the_motor_answers_as_the_manual_shows(cm_chain):
    cm_chain.expect_reply("P1.1", b"P1.1\r\nP1.1=2000\r\n")
    cm_chain.expect_reply("?96.1", b"?96.1\r\nPx.1=0\r\n")
