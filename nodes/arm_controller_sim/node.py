"""The RV-1A controller twin: a real Modbus TCP server (pymodbus) with the map of docs/register_map.md, or a
MELFA real-time external control (MXT) UDP server (``protocol: mxt``, :mod:`.mxt_twin`).

:class:`ControllerTwin` wraps :class:`.controller.ControllerCore` (register logic, servo, watchdog, e-stop) in a
pymodbus ``ModbusTcpServer``: every read first brings the servo up to the current time and refreshes the
register image; every write goes through the core's checks, and a refused write is answered with Modbus
exception 03 (ILLEGAL DATA VALUE; 02 for a bad address) and changes nothing. A background task advances the
servo every period even with no client, so the watchdog trips when the client goes quiet.

``flexsheet run arm_controller_sim --param port=15021`` runs one; two run side by side on different ports.
``flexsheet run arm_controller_sim --param protocol=mxt --param host=127.0.0.1 --param port=10000`` serves MXT.
"""

from __future__ import annotations

import asyncio
import time
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from flexsheet.model.kinematics import Q_HOME
from flexsheet.runtime.node import Node, ticks
from messages import mxt
from messages import registers as reg
from nodes.arm_controller_sim.controller import ControllerCore, WriteRejected
from nodes.arm_controller_sim.mxt_twin import MxtCore, MxtTwin
from nodes.arm_controller_sim.servo import ServoParams

__all__ = ["ControllerTwin", "ArmControllerSimParams", "ArmControllerSimNode"]


class ControllerTwin:
    """Modbus TCP server around a :class:`ControllerCore`.

    ``core``: the controller logic (its clock is ``time.monotonic()``). ``host``/``port``: where to listen
    (port 0 picks a free port; :attr:`port` holds the bound one after :meth:`start`).
    """

    def __init__(self, core: ControllerCore, host: str = "127.0.0.1", port: int = 0) -> None:
        self.core = core
        self.host = host
        self.port = port
        self.server: ModbusTcpServer | None = None
        self._task: asyncio.Task | None = None

    async def _action(self, function_code, start_address, address, count, registers, set_values):
        now = time.monotonic()
        core = self.core
        core.advance(now)
        if function_code == 4:
            registers[0:reg.IR_COUNT] = core.input_registers(now)
        elif function_code == 3:
            registers[0:reg.HR_COUNT] = core.holding
        elif set_values is not None:
            try:
                core.write_holding(address, list(set_values), now)
            except WriteRejected as exc:
                return ExcCodes.ILLEGAL_ADDRESS if exc.code == reg.REJ_ADDRESS else ExcCodes.ILLEGAL_VALUE
        return None

    async def start(self) -> int:
        """Listen and start the servo task; returns the bound TCP port."""
        device = SimDevice(
            id=0,
            simdata=(
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=reg.HR_COUNT, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=reg.IR_COUNT, values=0, datatype=DataType.REGISTERS)],
            ),
            action=self._action,
        )
        self.server = ModbusTcpServer(device, address=(self.host, self.port))
        await self.server.serve_forever(background=True)
        self.port = self.server.transport.sockets[0].getsockname()[1]
        self._task = asyncio.get_running_loop().create_task(self._run())
        return self.port

    async def _run(self) -> None:
        async for _ in ticks(self.core.period):
            self.core.advance(time.monotonic())

    async def stop(self) -> None:
        """Stop the servo task and close the server and its connections."""
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None
        if self.server is not None:
            await self.server.shutdown()
            self.server = None


class ArmControllerSimParams(BaseModel):
    """Parameters of the controller twin node (SI units). ``port`` and ``period`` default by protocol."""

    model_config = ConfigDict(extra="forbid")
    protocol: Literal["modbus", "mxt"] = Field(default="modbus", description="modbus (TCP register map) or "
                                               "mxt (MELFA real-time external control, UDP)")
    host: str = Field(default="127.0.0.1", description="listen address")
    port: int | None = Field(default=None, ge=0, le=65535, description="TCP (modbus) or UDP (mxt) port; "
                             "0 = any free port; default 15020 (modbus) / 10000 (mxt)")
    period: float | None = Field(default=None, gt=0.0, description="control cycle, s; default 0.0071 "
                                 "(modbus) / 0.00711 (mxt, CR750-Q/CR800-Q; 0.0035 for CR800-R/D)")
    initial_joints: list[float] = Field(default_factory=lambda: Q_HOME.tolist(), min_length=6, max_length=6,
                                        description="joints at start, rad")
    tau: float = Field(default=0.015, gt=0.0, description="servo first-order lag time constant, s")
    speed_scale: float = Field(default=1.0, gt=0.0, le=1.0, description="joint speed limits × URDF limits")
    accel_factor: float = Field(default=4.0, gt=0.0, description="acceleration limits = factor × speed limits, 1/s")
    step_tolerance: float = Field(default=1.5, ge=1.0, description="largest accepted command step per cycle, "
                                  "× speed limit × period")
    watchdog_periods: int = Field(default=3, ge=1, description="modbus: periods the watchdog counter may stall")
    timeout_s: float = Field(default=0.5, description="mxt: no-packet timeout, s (<= 0: never, MXTTOUT = -1)")
    on_timeout: Literal["hold", "fault"] = Field(default="hold", description="mxt: after the timeout keep "
                                                 "servoing to the last command (hold) or stop and end the session")

    @model_validator(mode="after")
    def _protocol_defaults(self) -> ArmControllerSimParams:
        if self.port is None:
            self.port = mxt.DEFAULT_PORT if self.protocol == "mxt" else 15020
        if self.period is None:
            self.period = 0.00711 if self.protocol == "mxt" else 0.0071
        return self


class ArmControllerSimNode(Node):
    """Node ``arm_controller_sim``: serves one controller twin over Modbus TCP or MXT/UDP (no topics besides
    diagnostics; the heartbeat message carries the MXT session counters)."""

    Params = ArmControllerSimParams
    node_type = "arm_controller_sim"

    async def setup(self) -> None:
        p = self.params
        sp = ServoParams()
        servo = ServoParams(tau=p.tau, qd_max=sp.qd_max * p.speed_scale, qdd_max=sp.qd_max * p.speed_scale * p.accel_factor)
        if p.protocol == "mxt":
            self.core = MxtCore(np.array(p.initial_joints), period=p.period, servo=servo, timeout=p.timeout_s,
                                on_timeout=p.on_timeout, step_tolerance=p.step_tolerance, now=time.monotonic())
            self.twin = MxtTwin(self.core, p.host, p.port)
            port = await self.twin.start()
            self.state_message = f"mxt listening on udp {p.host}:{port}"
            self.timer(1.0, self._diagnose)
        else:
            self.core = ControllerCore(np.array(p.initial_joints), period=p.period, servo=servo,
                                       watchdog_periods=p.watchdog_periods, step_tolerance=p.step_tolerance,
                                       now=time.monotonic())
            self.twin = ControllerTwin(self.core, p.host, p.port)
            port = await self.twin.start()
            self.state_message = f"listening on {p.host}:{port}"
        self.log.info("arm controller twin (%s) listening on %s:%d (period %.5f s)", p.protocol, p.host, port,
                      p.period)

    def _diagnose(self) -> None:
        self.state_message = f"udp {self.params.host}:{self.twin.port}; {self.core.summary()}"

    async def teardown(self) -> None:
        await self.twin.stop()
