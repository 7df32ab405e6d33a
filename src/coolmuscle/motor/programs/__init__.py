"""CML execution: direct mode, expressions and queries (6.3-6.9), program banks (2.2.2),
ladder and logic banks (2.2.3), the bank checker, and two-motor interpolation (4.4)."""
