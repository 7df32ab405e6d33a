"""Signals: digital inputs and outputs and their functions (K26-K36), analog input and output
(K35, K38), the external encoder (5.4), rotation pulses (5.2) and manual jog/feed (5.1)."""
