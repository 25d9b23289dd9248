"""The RV-1A controller twin: a real Modbus TCP server (pymodbus) with the map of docs/register_map.md, or a
MELFA real-time external control (MXT) UDP server (``protocol: mxt``, :mod:`flexsheet.twin.mxt_server`).

:class:`flexsheet.twin.modbus_server.ControllerTwin` wraps :class:`flexsheet.twin.controller.ControllerCore` (register logic, servo, watchdog, e-stop) in a
pymodbus ``ModbusTcpServer``: every read first brings the servo up to the current time and refreshes the
register image; every write goes through the core's checks, and a refused write is answered with Modbus
exception 03 (ILLEGAL DATA VALUE; 02 for a bad address) and changes nothing. A background task advances the
servo every period even with no client, so the watchdog trips when the client goes quiet.

``flexsheet run arm_controller_sim --param port=15021`` runs one; two run side by side on different ports.
``flexsheet run arm_controller_sim --param protocol=mxt --param host=127.0.0.1 --param port=10000`` serves MXT.
"""

from __future__ import annotations

import time
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from flexsheet.arm.kinematics import Q_HOME
from flexsheet.runtime.node import Node
from flexsheet.twin.controller import ControllerCore
from flexsheet.twin.modbus_server import ControllerTwin
from flexsheet.twin.mxt_server import MxtCore, MxtTwin
from flexsheet.twin.servo import ServoParams
from messages import mxt

__all__ = ["ArmControllerSimParams", "ArmControllerSimNode"]


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
