"""The arm controller port's lab side (``source: tcp``): a controller over the network — the RV-1A's over MXT
(UDP) or a Modbus TCP controller or gateway, or a controller twin node — on the wall clock. The arm PC's clock
is main's: chrony keeps them together (docs/deploy.md). See :mod:`flexsheet.arm.controller_port`."""

from __future__ import annotations

from typing import Any

from flexsheet.arm.controller_port import ControllerSource
from flexsheet.arm.stream import ControllerLink
from nodes.arm_bridge.modbus_link import ModbusLink
from nodes.arm_bridge.mxt_link import MxtLink

__all__ = ["NetworkController"]


class NetworkController(ControllerSource):
    """A controller over the network (module doc): Modbus TCP or MXT, paced by the stream's own loop."""

    protocols = frozenset({"modbus", "mxt"})

    other_clock = ("source tcp reaches a controller over the network on the wall clock (MXT's UDP session is "
                   "paced by the controller's own 7.1 ms clock); on a simulated clock (clock: sim) use "
                   "source: sim, the controller twin of this process")

    @classmethod
    def link(cls, protocol: str, host: str, port: int, **options: Any) -> ControllerLink:
        """A :class:`~nodes.arm_bridge.modbus_link.ModbusLink` (``protocol`` ``modbus``) or a
        :class:`~nodes.arm_bridge.mxt_link.MxtLink` (``mxt``) to ``host``:``port``, with the link's keyword
        ``options`` (:meth:`ControllerSource.link`)."""
        if protocol not in cls.protocols:
            raise ValueError(f"source tcp carries protocol {' or '.join(sorted(cls.protocols))}, not "
                             f"{protocol}")
        return (MxtLink if protocol == "mxt" else ModbusLink)(host, port, **options)
