"""The EtherCAT Cool Muscle Bridge as an EtherCAT slave (docs/ethercat.md).

* :mod:`.engine`: a sans-IO EtherCAT slave engine (ESC, state machine, slave stack,
  CoE, object dictionary, SII, ESI) configured by a slave description; it names no
  device.
* :mod:`.bridge`: the bridge application: its identity, the Appendix 6 object table,
  the slave description it hands to the engine, CiA402 and the Cool Muscle modes
  over the device API.
* :mod:`.transport`: the raw-socket transport (AF_PACKET, the frame thread) that
  ``coolmuscle sim --ethercat`` starts; :mod:`.lab`: the veth lab.  The
  ``coolmuscle ethercat`` command is :mod:`coolmuscle.tools.cli.ethercat`.
"""
