"""A sans-IO EtherCAT slave engine, configured by a slave description.

The simulator core never names a profile: every fact about the slave it runs comes
from a :class:`~.description.SlaveDescription` (identity, names, SyncManager layout,
mailbox sizes and addresses, process-data sizes, the object table) that the
application builds, and the application plugs in through
:class:`~.slave.Application`.  Nothing here opens a socket or reads a clock.

Modules: :mod:`.esc` (the slave controller: frames in, frames out), :mod:`.esm` (the
state machine as a table), :mod:`.slave` (the slave stack: ESM checks, mailbox,
process images, watchdog), :mod:`.coe` (SDO server and SDO information),
:mod:`.od` (data types, entries, objects, the table), :mod:`.dictionary` (the live
dictionary, SDO abort codes), :mod:`.description`, :mod:`.sii` (the EEPROM image),
:mod:`.esi` (the ESI file).
"""
