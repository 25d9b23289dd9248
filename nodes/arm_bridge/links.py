"""The arm controller port's lab side (``source: tcp``): a controller over the network — the RV-1A's over MXT
(UDP) or a Modbus TCP controller or gateway, or a controller twin node — on the wall clock. The arm PC's clock
is main's: chrony keeps them together (docs/deploy.md). See :mod:`flexsheet.arm.controller_port`."""

from __future__ import annotations

from flexsheet.arm.controller_port import ControllerSource

__all__ = ["NetworkController"]


class NetworkController(ControllerSource):
    """A controller over the network (module doc): Modbus TCP or MXT, paced by the stream's own loop."""

    protocols = frozenset({"modbus", "mxt"})

    other_clock = ("source tcp reaches a controller over the network on the wall clock (MXT's UDP session is "
                   "paced by the controller's own 7.1 ms clock); on a simulated clock (clock: sim) use "
                   "source: sim, the controller twin of this process")
