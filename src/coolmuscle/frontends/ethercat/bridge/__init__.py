"""Part 2 of the EtherCAT bridge: the Cool Muscle modes behind the CiA402 drive
(ethercat-bridge-users-guide.txt chapters 6, 7, Appendices 1-5).  See docs/ethercat.md."""
