"""What the CIP machinery is told about the adapter it serves: a typed description.

The encapsulation, the Message Router, the Connection Manager and the connection
table name no product: the identity a Forward_Open's electronic key is checked
against (CIP Vol 1 5A-2, C-1.4.2), the assemblies, the one Class 1 connection the
adapter offers (its connection points, sizes and RPI range, CIP Vol 1 3-5.5) and how
many connections of each kind it takes come from one :class:`AdapterDescription` the
product module builds.  The same facts write the product's EDS file.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class IdentityInfo:
    """Identity object instance 1 (CIP Vol 1 5A-2)."""

    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    serial: int
    product_name: str
    vendor_name: str


@dataclass(frozen=True, slots=True)
class AssemblyInfo:
    """One assembly instance (CIP Vol 2 5-5; its data, attribute 3, is the product's)."""

    instance: int
    size: int
    name: str
    writable: bool


@dataclass(frozen=True, slots=True)
class ConnectionInfo:
    """The I/O connection the adapter offers (CIP Vol 1 3-5.5): the output (O->T),
    input (T->O) and configuration assembly instances, their data sizes, the RPI range."""

    name: str
    output: int
    input: int
    config: int
    output_size: int
    input_size: int
    rpi_min_us: int
    rpi_max_us: int
    rpi_default_us: int
    run_idle_header: bool     # O->T real-time format: 32-bit run/idle header


@dataclass(frozen=True, slots=True)
class AdapterDescription:
    """One adapter (target) as the CIP machinery serves it.  The connections it takes
    are counted per kind, as its EDS declares them ([Capacity] MaxIOConnections and
    MaxMsgConnections, CIP Vol 1 7-3.6.12): class 1 I/O connections and class 3
    explicit connections to the Message Router never take each other's places."""

    identity: IdentityInfo
    connection: ConnectionInfo
    max_io_connections: int
    max_msg_connections: int
