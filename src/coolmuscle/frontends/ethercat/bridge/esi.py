"""The ESI file of the bridge (manual 8.1.4 "Install ESI File"): one Device per variant.

``coolmuscle ethercat esi > CoolMuscleBridge.xml``.  The engine's writer
(:mod:`..engine.esi`) turns the slave descriptions of :mod:`.description` into the
EtherCATInfo file: the vendor, the "Cool Muscle" group, and EB01, EB02 and EB12 with
their identity, the dictionary of Appendix 6, the FMMUs and SyncManagers of 2.3 and
the fixed PDOs of 6.3.3.
"""

from __future__ import annotations

from ..engine import esi
from . import identity as ident
from .description import describe


def esi_text(bridges: tuple[str, ...] = tuple(ident.VARIANTS)) -> str:
    """The ESI file of the bridges ``bridges`` (default: every variant) as text."""
    return esi.esi_text([describe(code) for code in bridges])


__all__ = ["esi_text"]
