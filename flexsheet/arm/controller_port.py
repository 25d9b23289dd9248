"""The arm controller port: how an arm bridge reaches its controller, and its arm PC's clock.

An arm bridge (``nodes/arm_bridge``) streams one command per controller cycle over its ``protocol`` (Modbus
TCP or MELFA MXT). Where that controller is, and what its arm PC's clock is, comes from a
:class:`ControllerSource`: an entry point of the group :data:`SOURCES_GROUP` (``pyproject.toml``), named by
the bridge's ``source`` param:

* ``tcp``: a controller (or a controller twin node) over the network, on the wall clock; the arm PC's clock is
  main's (chrony keeps them together, docs/deploy.md) (``nodes/arm_bridge/links.py``);
* ``sim``: the controller twin of this process, reached in-process at simulated instants (Modbus only), the
  arm PC's clock off main's by the hidden truth's draw
  (:class:`flexsheet.twin.controller_source.TwinController`).
"""

from __future__ import annotations

from typing import Any, ClassVar

from flexsheet.runtime.plugins import plugin

__all__ = ["SOURCES_GROUP", "ControllerSource", "controller_source"]

#: the entry-point group of the controller sources (name: an arm bridge's ``source`` param)
SOURCES_GROUP = "flexsheet.controller_sources"


class ControllerSource:
    """Where a bridge's controller is (module doc). Class-level: a source has no state of its own."""

    #: the bridge protocols it carries
    protocols: ClassVar[frozenset[str]] = frozenset()
    #: True: the bridge's timer paces the cycles and a new target is written at once (the controller is
    #: reached at the node clock's instants); False: the stream's own loop paces them on the wall clock
    paced_by_node: ClassVar[bool] = False

    #: the clock it is reached on: a simulated one (True) or the wall clock (False)
    simulated_clock: ClassVar[bool] = False
    #: what to do instead, said when the node runs on the other clock
    other_clock: ClassVar[str] = ""

    @classmethod
    def check_clock(cls, clock: Any) -> None:
        """Raises ``ValueError`` naming the fix when the node's ``clock`` (its ``simulated``: a simulated
        clock or the wall clock) cannot reach this controller."""
        if bool(clock.simulated) != cls.simulated_clock:
            raise ValueError(cls.other_clock)

    @classmethod
    def modbus_client(cls) -> type | None:
        """The Modbus client class (pymodbus's ``AsyncModbusTcpClient`` interface); None: pymodbus's own TCP
        client."""
        return None

    @classmethod
    def clock_offset(cls, params: Any) -> float:
        """The arm PC's clock minus main's, s, for the bridge's ``params``; 0 by default."""
        return 0.0

    @classmethod
    def link(cls, protocol: str, host: str, port: int, **options: Any) -> Any:
        """A new :class:`~flexsheet.arm.stream.ControllerLink` to the controller at ``host``:``port`` (TCP for
        Modbus, UDP for MXT) over ``protocol``, ``options`` being the link's keyword arguments (Modbus:
        ``request_timeout`` s, ``device_id``, ``auto_reset``; MXT: ``period`` s, ``open_timeout`` s,
        ``lost_cycles``, ``record``). Raises ``LookupError`` for a source that reaches no controller by its
        address (the default), ``ValueError`` for a protocol it does not carry."""
        raise LookupError(f"controller source {cls.__name__} opens no link to a controller by its address")


def controller_source(name: str) -> type[ControllerSource]:
    """The :class:`ControllerSource` installed as ``name`` in :data:`SOURCES_GROUP`. Raises ``LookupError``
    naming the installed ones."""
    return plugin(SOURCES_GROUP, name, what="controller source", base=ControllerSource)  # type: ignore[return-value]
