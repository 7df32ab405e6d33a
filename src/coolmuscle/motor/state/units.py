"""Resolution, speed unit and maximum position from K37 (cml-users-guide.txt ch. 3 K37).

Values 0-10 and 40-50 use a 100 pps speed unit, 20-30 and 60-70 use 10 pps, 80-90
use 1 pps.  9, 29 and 89 are "N/A" in the table and are refused.  Resolutions of
40-70 cannot run incremental (relative) motion.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Continuous rotation target (2.1.1 "P": "If the value is set to 1000000000 ...").
CONTINUOUS = 1_000_000_000

_BASE_RESOLUTION = {0: 200, 1: 400, 2: 500, 3: 1000, 4: 2000, 5: 2500, 6: 5000,
                    7: 10000, 8: 25000, 10: 50000}
_ODD_RESOLUTION = {0: 300, 1: 400, 2: 600, 3: 800, 4: 1200, 5: 1500, 6: 3000,
                   7: 4000, 8: 6000, 9: 8000, 10: 12000}
_MAX_POSITION = {200: 8_589_934, 400: 17_179_869, 500: 21_474_836, 1000: 42_949_672,
                 2000: 85_899_345, 2500: 107_374_182, 5000: 214_748_364,
                 10000: 429_496_729, 25000: 999_999_999, 50000: 999_999_999,
                 300: 12_884_901, 600: 25_769_803, 800: 34_359_738, 1200: 51_539_607,
                 1500: 64_424_509, 3000: 128_849_018, 4000: 171_798_691,
                 6000: 257_698_037, 8000: 343_597_383, 12000: 515_396_075}


@dataclass(frozen=True, slots=True)
class Resolution:
    """What one K37 value means."""

    k37: int
    pulses_per_rev: int
    speed_unit_pps: int
    max_position: int
    incremental_allowed: bool


def _decode(k37: int) -> Resolution | None:
    if 0 <= k37 <= 10 or 20 <= k37 <= 30 or 80 <= k37 <= 90:
        base = k37 % 20 if k37 < 80 else k37 - 80
        ppr = _BASE_RESOLUTION.get(base)
        unit = 100 if k37 <= 10 else 10 if k37 <= 30 else 1
        odd = False
    elif 40 <= k37 <= 50 or 60 <= k37 <= 70:
        ppr = _ODD_RESOLUTION.get(k37 - 40 if k37 <= 50 else k37 - 60)
        unit = 100 if k37 <= 50 else 10
        odd = True
    else:
        return None
    if ppr is None:
        return None
    return Resolution(k37, ppr, unit, _MAX_POSITION[ppr], not odd)


RESOLUTIONS: dict[int, Resolution] = {
    k: r for k in range(0, 91) if (r := _decode(k)) is not None
}
#: CM1 only (cm1-ethernetip-interface-manual.txt Appendix A K37 "100: 50000"); the CM2
#: table stops at 90, so its K37 range refuses it.
RESOLUTIONS[100] = Resolution(100, 50000, 1, 999_999_999, True)


#: The position counter counts 1/50000 turn in a signed 32-bit number: the K37 table's
#: maximum positions are 2**31 of those counts at every resolution (42,949,672 pulses at
#: 1000 ppr, 8,589,934 at 200; capped at 999,999,999 by the data range), so past them
#: the count wraps (docs/fidelity.md "Servo, load and alarms").
COUNTS_PER_REV = 50_000


def counter_half_range(pulses_per_rev: int) -> float:
    """Half the span of the position counter, in pulses at ``pulses_per_rev``: Px stays
    within [-half, half) and wraps round past it."""
    return 2.0 ** 31 * pulses_per_rev / COUNTS_PER_REV


def resolution(k37: int) -> Resolution:
    """The :class:`Resolution` for ``k37``; ``KeyError`` for an N/A value."""
    return RESOLUTIONS[k37]


def valid_k37(k37: int) -> bool:
    """Whether ``k37`` names a resolution in the table."""
    return k37 in RESOLUTIONS


def accel_to_pps2(a_value: int) -> float:
    """A value (kpps²) to pulses per second squared."""
    return float(a_value) * 1000.0


def rpm_to_pps(rpm: float, k37: int) -> float:
    """min⁻¹ to pulses per second (K40 conversion, ch. 3 K40)."""
    return rpm * resolution(k37).pulses_per_rev / 60.0
