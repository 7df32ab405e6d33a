"""The state of a motor: K parameters (ch. 3, table 6.1), firmware profiles (CM2, RT3, CM1),
data memory and V values (6.2), K37 units, and the SQLite store behind ``$``."""
