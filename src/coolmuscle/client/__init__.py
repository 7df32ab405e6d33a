"""The host library: one Python API for real and virtual Cool Muscle motors.

It speaks CML (cml-users-guide.txt) over a byte stream: any pyserial URL or device
(``/dev/ttyUSB0``, ``socket://host:port``, ``coolmuscle://`` for an in-process virtual
chain) and never re-implements motor behaviour.  Layers:

* :mod:`~coolmuscle.client.protocol` and :mod:`~coolmuscle.client.replies`: the
  sans-IO core (line ends, echo, exchanges, events, 6.6 reply formats);
* :mod:`~coolmuscle.client.ops`, :mod:`~coolmuscle.client.commands`,
  :mod:`~coolmuscle.client.banks`: operations as generators, shared by both drivers;
* :mod:`~coolmuscle.client.sync` (:func:`connect`) and :mod:`~coolmuscle.client.aio`
  (:func:`connect_async`): the blocking and the asyncio front.

See docs/user-guide.md.
"""

from __future__ import annotations

from .aio import AsyncCoolMuscle, AsyncMotor, connect_async
from .banks import BankDifference, UploadError, UploadResult
from .program import BankBlock, ProgramFile, load_program, parse_program
from .protocol import MotorEvent
from .replies import Version
from .sync import CoolMuscle, Motor, connect

__all__ = ["connect", "connect_async", "CoolMuscle", "Motor", "AsyncCoolMuscle",
           "AsyncMotor", "MotorEvent", "Version", "UploadResult", "UploadError",
           "BankDifference", "ProgramFile", "BankBlock", "load_program", "parse_program"]
