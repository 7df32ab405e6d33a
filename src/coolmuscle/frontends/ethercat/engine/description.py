"""The slave description: everything the engine is told about the slave it runs.

The engine (ESC, state machine, slave stack, CoE server, SII image, ESI file) never
names a device.  Identity, names, the SyncManager layout (ETG.1000.4 / ESC datasheet
0x0800; ETG.2010 category 41), the mailbox sizes and addresses, the object table
(:mod:`.od`) and with it the process-data sizes (from the PDO assignment
1C12h/1C13h), the shortest cycle and the profile come from one
:class:`SlaveDescription` the application builds.  The slave stack checks a master's
SyncManager configuration against it, the SII image and the ESI file are written
from it.

The layout is the standard one of a slave with a mailbox and process data: SM0
mailbox out (master to slave), SM1 mailbox in, SM2 outputs, SM3 inputs, and three
FMMUs (outputs, inputs, mailbox status).  The bootstrap mailbox is the standard one.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from .od import Table


@dataclass(frozen=True)
class Identity:
    """Object 1018h, SII words 8-15, the ESI ``Type`` attributes (ETG.1000.6 5.4)."""

    vendor_id: int
    product_code: int
    revision: int
    serial: int


@dataclass(frozen=True)
class Names:
    """What a master shows: SII strings (ETG.2010 categories 10, 30) and ESI names."""

    device: str           # SII general name, ESI Device/Name (at most 40 characters)
    order: str            # SII order code, ESI Device/Type
    group_type: str       # ESI Device/GroupType and Group/Type
    group: str            # SII group string, ESI Group/Name
    vendor: str           # ESI Vendor/Name


@dataclass(frozen=True)
class SyncManagerLayout:
    """Where one SyncManager sits and its control byte (ESC datasheet 0x0800-0x0807).

    ``size`` is the mailbox size for SM0/SM1; for the process data SyncManagers it is 0
    here and comes from the PDO mapping (:attr:`SlaveDescription.output_size`)."""

    start: int
    control: int
    size: int = 0


@dataclass(frozen=True)
class SlaveDescription:
    """One slave, as the engine runs it and writes its SII image and ESI entry."""

    identity: Identity
    names: Names
    mailbox_out: SyncManagerLayout       # SM0: master -> slave
    mailbox_in: SyncManagerLayout        # SM1: slave -> master
    outputs: SyncManagerLayout           # SM2: RxPDO image
    inputs: SyncManagerLayout            # SM3: TxPDO image
    table: Table
    #: The shortest cycle the slave runs (ns): an SM watchdog below it is refused (001Fh).
    cycle_ns: int
    #: SII word 0, loaded into the ESC's PDI control register 0x0140 at power-up.
    pdi_control: int
    #: Device profile (ESI Profile/ProfileNo, e.g. 402), its AddInfo and channel count
    #: (SII general "DS402 channels" when the profile is 402).
    profile: int = 0
    profile_info: int = 0
    channels: int = 0

    @cached_property
    def output_size(self) -> int:
        """Bytes of the RxPDO image (SM2), from the PDOs assigned in 1C12h."""
        return self.table.image_bytes(self.table.rx_pdos())

    @cached_property
    def input_size(self) -> int:
        """Bytes of the TxPDO image (SM3), from the PDOs assigned in 1C13h."""
        return self.table.image_bytes(self.table.tx_pdos())

    def sync_managers(self) -> tuple[tuple[int, int, int], ...]:
        """(start, size, control) of SM0-SM3, in order."""
        return ((self.mailbox_out.start, self.mailbox_out.size, self.mailbox_out.control),
                (self.mailbox_in.start, self.mailbox_in.size, self.mailbox_in.control),
                (self.outputs.start, self.output_size, self.outputs.control),
                (self.inputs.start, self.input_size, self.inputs.control))
