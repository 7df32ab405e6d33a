"""The EtherCAT Cool Muscle Bridge: the application the slave engine runs
(ethercat-bridge-users-guide.txt; docs/ethercat.md).

Who the bridge is (:mod:`.identity`), its object table of Appendix 6 (:mod:`.table`)
and the slave description it hands to the engine (:mod:`.description`), its ESI
content (:mod:`.esi`), the application behind the slave (:mod:`.app`), the CiA402
state machine (:mod:`.cia402`) and the Cool Muscle modes behind the CiA402 drive
(chapters 6, 7, Appendices 1-5: :mod:`.drive`, :mod:`.axis`, :mod:`.modes`,
:mod:`.csp`, :mod:`.homing`, :mod:`.cpio`, :mod:`.cml_mailbox`, :mod:`.link`,
:mod:`.bridge_objects`).  A client of the motor model through the device API only.
"""
