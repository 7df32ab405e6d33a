"""The live object dictionary: values of the table's entries, access rules, hooks.

One :class:`Dictionary` per slave, built from its object table (:mod:`.od`).  Errors
are wire codes: every refusal raises :class:`SdoAbort` with an SDO abort code
(ETG.1000.6 5.6.2.7, the codes of CiA 301), encoded once by the CoE server.

The application attaches behaviour with :meth:`Dictionary.on_read` /
:meth:`Dictionary.on_write` (a hook may raise :class:`SdoAbort`), and moves the
process images with :meth:`pack_inputs` / :meth:`unpack_outputs` (the PDO mapping
of the assigned PDOs, 1C12h/1C13h, read from the table).  Reads and writes come from
the ESC thread; values are single dict items, so a value the application sets from
its own thread is seen whole.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable

from .od import ARRAY, RECORD, STRING, Entry, Obj, Table

log = logging.getLogger(__name__)

# SDO abort codes (ETG.1000.6 5.6.2.7; the codes of CiA 301).
TOGGLE = 0x05030000
TIMEOUT = 0x05040000
BAD_COMMAND = 0x05040001
OUT_OF_MEMORY = 0x05040005
UNSUPPORTED_ACCESS = 0x06010000
WRITE_ONLY = 0x06010001
READ_ONLY = 0x06010002
SUB0_NOT_ZERO = 0x06010003
NO_OBJECT = 0x06020000
NOT_MAPPABLE = 0x06040041
PDO_TOO_LONG = 0x06040042
PARAMETER_INCOMPATIBLE = 0x06040043
INTERNAL_INCOMPATIBLE = 0x06040047
HARDWARE = 0x06060000
LENGTH_MISMATCH = 0x06070010
LENGTH_HIGH = 0x06070012
LENGTH_LOW = 0x06070013
NO_SUBINDEX = 0x06090011
VALUE_RANGE = 0x06090030
VALUE_HIGH = 0x06090031
VALUE_LOW = 0x06090032
MAX_BELOW_MIN = 0x06090036
GENERAL = 0x08000000
CANNOT_STORE = 0x08000020
LOCAL_CONTROL = 0x08000021
DEVICE_STATE = 0x08000022
NO_DICTIONARY = 0x08000023

#: PDO assignment objects (6.3.3): their entries change only while subindex 0 is 0.
_ASSIGNMENTS = frozenset({0x1C12, 0x1C13})

#: An entry's name, (index, subindex), as one object: compiled, a tuple typed by its
#: size would be unboxed and made again at every use.
Key = tuple[object, ...]

ReadHook = Callable[[int], "int | str"]
WriteHook = Callable[[int, "int | str"], "int | str | None"]


class SdoAbort(Exception):
    """An SDO request refused with an abort code (ETG.1000.6 5.6.2.7)."""

    def __init__(self, code: int, why: str = "") -> None:
        super().__init__(f"SDO abort 0x{code:08X}{': ' + why if why else ''}")
        self.code = code


class Dictionary:
    """Values and access rules of one slave's objects."""

    def __init__(self, table: Table) -> None:
        self.table = table
        self._objects: dict[int, Obj] = {o.index: o for o in table.objects if o.available}
        # Every entry's value in a list, at its place (slot); the place by (index, sub).
        # An application reading an entry every cycle keeps its place (:meth:`key`): a
        # list read, where a tuple key is hashed and compared at every lookup.
        self._place: dict[Key, int] = {}
        self._slots: list[int | str] = []
        for o in self._objects.values():
            for e in o.entries:
                if e.available:
                    self._place[(o.index, e.sub)] = len(self._slots)
                    self._slots.append(e.default)
        self._read_hooks: dict[int, ReadHook] = {}
        self._write_hooks: dict[int, WriteHook] = {}
        self._rx = [(o.index, e) for p in table.rx_pdos() for o, e in table.pdo_entries(p)]
        self._tx = [(o.index, e) for p in table.tx_pdos() for o, e in table.pdo_entries(p)]
        self._rx_fmt = "<" + "".join(e.dtype.fmt for _i, e in self._rx)
        self._tx_fmt = "<" + "".join(e.dtype.fmt for _i, e in self._tx)
        # the images' layouts made once: every cycle packs and unpacks them
        self._rx_struct = struct.Struct(self._rx_fmt)
        self._tx_struct = struct.Struct(self._tx_fmt)
        self._rx_places: list[int] = [self._place[(i, e.sub)] for i, e in self._rx]
        self._tx_places: list[int] = [self._place[(i, e.sub)] for i, e in self._tx]

    # -- application side -------------------------------------------------------
    def on_read(self, index: int, hook: ReadHook) -> None:
        """Compute the value of ``index`` (any subindex) when a master reads it."""
        self._read_hooks[index] = hook

    def on_write(self, index: int, hook: WriteHook) -> None:
        """Called with (sub, value) after the access checks, before the value is kept;
        it may raise :class:`SdoAbort`, or return the value to keep instead."""
        self._write_hooks[index] = hook

    def get(self, index: int, sub: int = 0) -> int | str:
        """The stored value (no access check, no hook); ``KeyError`` for an entry the
        slave does not have."""
        return self._slots[self._place[(index, sub)]]

    def set(self, index: int, sub: int, value: int | str) -> None:
        """Store a value from the application (no access check); an entry the table
        does not have is kept as well (an application's own)."""
        place = self._place.get((index, sub))
        if place is None:
            self._place[(index, sub)] = len(self._slots)
            self._slots.append(value)
        else:
            self._slots[place] = value

    def key(self, index: int, sub: int = 0) -> int:
        """The place of entry ``index``.``sub``, for :meth:`value_at` and :meth:`set_at`:
        taken once by an application that reads or writes the entry every cycle
        (``KeyError`` for an entry the slave does not have)."""
        return self._place[(index, sub)]

    def value_at(self, place: int) -> int:
        """:meth:`get` of a numeric entry by a :meth:`key` (what a cycle reads: typed
        as an int, compiled code uses it as one without converting it generically)."""
        value = self._slots[place]
        return value if isinstance(value, int) else int(value)

    def set_at(self, place: int, value: int | str) -> None:
        """:meth:`set` by a :meth:`key`."""
        self._slots[place] = value

    def objects(self) -> list[Obj]:
        """The available objects in index order (SDO information's object list)."""
        return [self._objects[i] for i in sorted(self._objects)]

    # -- process images (6.3.1) ----------------------------------------------------
    @property
    def output_size(self) -> int:
        return self._rx_struct.size

    @property
    def input_size(self) -> int:
        return self._tx_struct.size

    def unpack_outputs(self, image: bytes) -> None:
        """Store a received RxPDO image (SM2) into its mapped objects."""
        layout = self._rx_struct
        if len(image) < layout.size:
            return
        slots = self._slots
        for place, value in zip(self._rx_places, layout.unpack_from(image)):
            slots[place] = value

    def pack_inputs(self) -> bytes:
        """The TxPDO image (SM3) from the mapped objects' values."""
        slots = self._slots
        return self._tx_struct.pack(*[slots[place] for place in self._tx_places])

    # -- master side (SDO) -----------------------------------------------------------
    def lookup(self, index: int, sub: int) -> tuple[Obj, Entry]:
        obj = self._objects.get(index)
        if obj is None:
            raise SdoAbort(NO_OBJECT, f"{index:04X}h")
        entry = obj.entry(sub)
        if entry is None or not entry.available:
            raise SdoAbort(NO_SUBINDEX, f"{index:04X}h.{sub}")
        return obj, entry

    def read(self, index: int, sub: int) -> bytes:
        """SDO upload of one entry: its encoded value."""
        obj, entry = self.lookup(index, sub)
        if entry.access == "wo":
            raise SdoAbort(WRITE_ONLY)
        return entry.dtype.encode(self._current(obj, entry))

    def _current(self, obj: Obj, entry: Entry) -> int | str:
        hook = self._read_hooks.get(obj.index)
        if hook is not None:
            return hook(entry.sub)
        return self.get(obj.index, entry.sub)

    def write(self, index: int, sub: int, data: bytes, *, sized: bool = True) -> None:
        """SDO download of one entry.  ``sized``: the length is exact (else truncate)."""
        obj, entry = self.lookup(index, sub)
        if entry.access == "ro":
            raise SdoAbort(READ_ONLY, f"{index:04X}h.{sub}")
        value = self._decode(entry, data, sized)
        if obj.code in (ARRAY, RECORD) and sub > 0 and obj.entries[0].access == "ro" \
                and entry.pdo == "" and index in _ASSIGNMENTS and self.get(index, 0):
            raise SdoAbort(SUB0_NOT_ZERO)   # CiA 301: entries change only while sub 0 is 0
        if isinstance(value, int):
            if entry.low is not None and value < entry.low:
                raise SdoAbort(VALUE_LOW)
            if entry.high is not None and value > entry.high:
                raise SdoAbort(VALUE_HIGH)
        hook = self._write_hooks.get(index)
        if hook is not None:
            stored = hook(sub, value)
            if stored is not None:
                value = stored
        self.set(index, sub, value)

    @staticmethod
    def _decode(entry: Entry, data: bytes, sized: bool) -> int | str:
        if entry.dtype is STRING:
            if entry.max_len and len(data) > entry.max_len:
                raise SdoAbort(LENGTH_HIGH)
            return data.decode("latin-1")
        size = entry.dtype.size
        if len(data) < size:
            raise SdoAbort(LENGTH_LOW)
        if len(data) > size:
            if sized:
                raise SdoAbort(LENGTH_HIGH)
            data = data[:size]
        return entry.dtype.decode(data)

    # -- complete access (ETG.1000.6 5.6.2.1.1) ----------------------------------------
    def read_complete(self, index: int, start: int) -> bytes:
        """Upload of all entries from ``start`` (0 or 1); subindex 0 is padded to 16 bits."""
        obj = self._objects.get(index)
        if obj is None:
            raise SdoAbort(NO_OBJECT)
        if obj.code == 7 or start > 1:
            raise SdoAbort(UNSUPPORTED_ACCESS)
        out = bytearray()
        for entry in obj.entries:
            if entry.sub < start:
                continue
            if not entry.available:
                out += bytes(entry.dtype.size)
                continue
            out += entry.dtype.encode(self._current(obj, entry))
            if entry.sub == 0:
                out += b"\x00"
        return bytes(out)

    def write_complete(self, index: int, start: int, data: bytes) -> None:
        """Download of all entries from ``start``; every entry must be writable."""
        obj = self._objects.get(index)
        if obj is None:
            raise SdoAbort(NO_OBJECT)
        if obj.code == 7 or start > 1:
            raise SdoAbort(UNSUPPORTED_ACCESS)
        pos = 0
        for entry in obj.entries:
            if entry.sub < start:
                continue
            size = entry.dtype.size + (1 if entry.sub == 0 else 0)
            if pos + size > len(data):
                break
            if entry.available:
                self.write(index, entry.sub, data[pos:pos + entry.dtype.size])
            pos += size
        if pos < len(data):
            raise SdoAbort(LENGTH_HIGH)
