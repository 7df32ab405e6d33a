"""coolmuscle: a byte-faithful virtual Cool Muscle servo motor and host tools.

See README.md and docs/.  The public API grows issue by issue; names exported here
are stable.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
