"""``python -m coolmuscle.tools.accel build|status|clean`` (see :mod:`.build`)."""

from __future__ import annotations

import sys

from .build import main

sys.exit(main())
