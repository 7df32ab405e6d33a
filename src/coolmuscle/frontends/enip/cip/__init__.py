"""EtherNet/IP encapsulation and CIP for an adapter (target), configured by a description.

Nothing here names a product: the identity, the connection offered and the number
of connections come from an :class:`~.description.AdapterDescription`, the objects
from an object table the product builds with :mod:`.objects`, the I/O images from
its module (:class:`~.io.Module`).  Sans-IO except the producer thread.

Modules: :mod:`.encapsulation` (framing, sessions, common packet format),
:mod:`.messages` (paths, requests, replies, general status), :mod:`.description`,
:mod:`.objects` (the object service and the standard objects), :mod:`.connmgr`
(Forward_Open/Close), :mod:`.io` (the connection table: Class 1 and 3),
:mod:`.router` (the Message Router), :mod:`.producer` (the T->O thread).
"""
