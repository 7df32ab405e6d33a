"""The bridge as the slave engine sees it: one slave description per variant.

:func:`describe` gathers what :mod:`.identity` chose (vendor ID, product code,
revision, serial, names, the SM/FMMU layout of ethercat-bridge-users-guide.txt 2.3,
the 1 ms cycle of 6.3) and the object table of Appendix 6 (:mod:`.table`) into the
:class:`~..engine.description.SlaveDescription` the engine is configured by: the
slave stack checks a master's SyncManagers against it, the SII image and the ESI file
are written from it.
"""

from __future__ import annotations

from ..engine.description import Identity, Names, SlaveDescription, SyncManagerLayout
from . import identity as ident
from .table import build_table


def describe(code: str = ident.DEFAULT_VARIANT) -> SlaveDescription:
    """The slave description of bridge ``code`` (EB01, EB02, EB12; case-insensitive)."""
    v = ident.variant(code)
    return SlaveDescription(
        identity=Identity(ident.VENDOR_ID, v.product_code, ident.REVISION, ident.SERIAL),
        names=Names(device=v.device_name, order=v.code, group_type=ident.GROUP_TYPE,
                    group=ident.GROUP_NAME, vendor=ident.VENDOR_NAME),
        mailbox_out=SyncManagerLayout(ident.MBX_OUT_START, ident.SM_CONTROL[0],
                                      ident.MBX_OUT_SIZE),
        mailbox_in=SyncManagerLayout(ident.MBX_IN_START, ident.SM_CONTROL[1],
                                     ident.MBX_IN_SIZE),
        outputs=SyncManagerLayout(ident.PD_OUT_START, ident.SM_CONTROL[2]),
        inputs=SyncManagerLayout(ident.PD_IN_START, ident.SM_CONTROL[3]),
        table=build_table(v.code),
        cycle_ns=ident.CYCLE_NS,
        pdi_control=ident.PDI_CONTROL,
        profile=ident.PROFILE, profile_info=ident.PROFILE_INFO, channels=ident.AXES)
