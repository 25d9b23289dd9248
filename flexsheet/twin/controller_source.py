"""The arm controller port's simulated side (``source: sim``): the controller twin of this process, reached
in-process through :class:`flexsheet.twin.loopback.LoopbackModbusClient` (the same Modbus requests through the
same core calls the twin's TCP server makes) at simulated instants, and the arm PC's clock off main's by the
hidden truth's draw (:func:`flexsheet.twin.lab_clock.arm_clock_offset`). See
:mod:`flexsheet.arm.controller_port`."""

from __future__ import annotations

from flexsheet.arm.controller_port import ControllerSource
from flexsheet.twin.lab_clock import arm_clock_offset
from flexsheet.twin.loopback import LoopbackModbusClient

__all__ = ["TwinController"]


class TwinController(ControllerSource):
    """The in-process controller twin (module doc); Modbus only, on a simulated clock."""

    protocols = frozenset({"modbus"})
    paced_by_node = True

    simulated_clock = True
    other_clock = ("source sim is the controller twin of this process, reached at simulated instants: it "
                   "needs the launch file's clock: sim; on the wall clock reach a controller twin node over "
                   "the network (source: tcp)")

    @classmethod
    def modbus_client(cls) -> type:
        return LoopbackModbusClient

    @classmethod
    def clock_offset(cls, params) -> float:
        """The truth's draw for ``params.twin`` (``truth_seed``, ``realism``) and ``params.arm``."""
        return arm_clock_offset(params.twin.truth_seed, params.twin.realism, params.arm)
