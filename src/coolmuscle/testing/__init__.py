"""Testing a project with coolmuscle: the pytest plug-in and what it is made of.

docs/testing-your-project.md.  The plug-in (:mod:`.plugin`, entry point ``pytest11``)
gives the fixtures ``cm_chain``, ``cm_sim`` and ``cm_lab``; the parts serve a test
without it too:

* :mod:`.rig` - :class:`~.rig.ChainRig`, a chain in virtual time with its recording;
* :mod:`.expect` - the assertions and :class:`~.expect.MotionAssertionError`;
* :mod:`.banks` - a ``.cml`` file loaded on a chain, and where each bank line came from;
* :mod:`.coverage` - bank coverage, its table and its Cobertura XML;
* :mod:`.served` - ``coolmuscle sim`` as a process on free ports, waits and ports;
* :mod:`.lab` - the EtherCAT lab; :mod:`.ledger` - nothing left behind.

Importing this package loads nothing else; the names below load their module on first
use.
"""

from __future__ import annotations

__all__ = ["ChainRig", "MotionAssertionError", "ServedSim", "build_chain", "wait_until"]


def __getattr__(name: str) -> object:
    if name in ("ChainRig", "build_chain"):
        from . import rig
        return getattr(rig, name)
    if name == "MotionAssertionError":
        from .expect import MotionAssertionError
        return MotionAssertionError
    if name in ("ServedSim", "wait_until"):
        from . import served
        return getattr(served, name)
    raise AttributeError(f"module 'coolmuscle.testing' has no attribute {name!r}")
