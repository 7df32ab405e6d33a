"""Motion: closed-form command profiles and their planner (PTP, merge, stop, S-curve), the
servo and load model of the shaft, the axis that joins them, and interpolation geometry (4.4)."""
