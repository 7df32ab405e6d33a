"""Who the bridge says it is: vendor ID, product codes, names, SM/FMMU layout.

The manual (ethercat-bridge-users-guide.txt 1.3) names the variants EB01, EB02 and
EB12 but gives no EtherCAT vendor ID, product code, revision or mailbox sizes; the
values chosen here are kept in this one place and recorded in docs/fidelity.md
("EtherCAT bridge").  Everything else (object 1018h, and through the slave description
of :mod:`.description` the SII image and the ESI file) reads them from here.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass

#: Not an ETG-assigned vendor ID (the manual gives none): "CMB" in ASCII, chosen so
#: that it is plainly an emulation and clashes with no vendor a master knows.
VENDOR_ID = 0x00434D42
VENDOR_NAME = "coolmuscle (emulated Muscle Corporation bridge)"
REVISION = 0x00010000
SERIAL = 0x00000001

#: Manual 2.3 / 6.3: SM0/SM1 mailbox, SM2/SM3 process data (24 bytes each way, 6.3.1).
MBX_OUT_START, MBX_OUT_SIZE = 0x1000, 128
MBX_IN_START, MBX_IN_SIZE = 0x1080, 128
PD_OUT_START, PD_IN_START = 0x1100, 0x1180
PD_SIZE = 24
AXES = 4
CYCLE_NS = 1_000_000        # 6.3: the cycle between master and bridge is 1 ms

#: SM control bytes: mailbox write/read with ECAT interrupt, buffered write with the
#: SM watchdog, buffered read (ESC datasheet 0x0804).
SM_CONTROL = (0x26, 0x22, 0x64, 0x20)
#: SII word 0 / ESC register 0x0140: the PDI is SPI (the bridge's microcontroller).
PDI_CONTROL = 0x0005
#: The device group of the SII general category and the ESI file.
GROUP_TYPE, GROUP_NAME = "CoolMuscle", "Cool Muscle"
#: CiA402 (the drive profile of chapter 6), AddInfo 2, one channel per axis.
PROFILE, PROFILE_INFO = 402, 2


@dataclass(frozen=True)
class Variant:
    """One bridge model of manual 1.3 / 1.4."""

    code: str
    product_code: int
    firmware: tuple[str, str, str, str]    # the motor behind ID1..ID4
    name: str

    @property
    def device_name(self) -> str:
        """SII / 1008h name (at most 40 characters: SOEM's EC_MAXNAME)."""
        return f"{self.code} {self.name}"


VARIANTS: dict[str, Variant] = {
    "EB01": Variant("EB01", 0x00EB0001, ("cm1",) * 4, "CM1 EtherCAT Cool MUSCLE Bridge"),
    "EB02": Variant("EB02", 0x00EB0002, ("cm2",) * 4, "CM2 EtherCAT Cool MUSCLE Bridge"),
    "EB12": Variant("EB12", 0x00EB0012, ("cm1", "cm1", "cm2", "cm2"),
                    "CM1-2 EtherCAT Cool MUSCLE Bridge"),
}
DEFAULT_VARIANT = "EB02"

HARDWARE_VERSION = "1.00"


def _version() -> str:
    try:
        return importlib.metadata.version("coolmuscle")
    except importlib.metadata.PackageNotFoundError:
        return "0.1.0"


SOFTWARE_VERSION = f"coolmuscle {_version()}"


def variant(code: str) -> Variant:
    """The variant named ``code`` (EB01, EB02, EB12; case-insensitive)."""
    try:
        return VARIANTS[code.upper()]
    except KeyError:
        raise ValueError(f"unknown bridge {code!r}; known: {', '.join(VARIANTS)}") from None
