"""The CM1 EtherNet/IP interface module itself (cm1-ethernetip-interface-manual.txt).

Its facts: identity values, assemblies 0x65/0x66/0x80, the exclusive-owner
connection, vendor class 0x64 and the description the CIP machinery serves
(:mod:`.objects`), the module over the device API (:mod:`.adapter`) and the EDS
file (:mod:`.eds`).
"""
