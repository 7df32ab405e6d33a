"""Part 2 of the EtherCAT bridge: the CiA402 drive and the Cool Muscle modes behind it
(ethercat-bridge-users-guide.txt chapters 6, 7, Appendices 1-5).  See docs/ethercat.md."""
