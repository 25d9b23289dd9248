"""The RV-1A controller twin: a real Modbus TCP server (pymodbus) with the map of docs/register_map.md, or a
MELFA real-time external control (MXT) UDP server (``protocol: mxt``, :mod:`flexsheet.twin.mxt_server`).

:class:`flexsheet.twin.modbus_server.ControllerTwin` wraps :class:`flexsheet.twin.controller.ControllerCore`
(register logic, servo, watchdog, e-stop) in a pymodbus ``ModbusTcpServer``: every read first brings the servo
up to the current time and refreshes the register image; every write goes through the core's checks, and a
refused write is answered with Modbus exception 03 (ILLEGAL DATA VALUE; 02 for a bad address) and changes
nothing. A background task advances the servo every period even with no client, so the watchdog trips when the
client goes quiet.

``flexsheet run arm_controller_sim --param port=15021`` runs one; two run side by side on different ports.
``flexsheet run arm_controller_sim --param protocol=mxt --param host=127.0.0.1 --param
port=10000`` serves MXT.
"""

from __future__ import annotations

import os
import time
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from flexsheet.arm.bridge_config import protocol_defaults
from flexsheet.runtime.node import Node
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.twin import loopback
from flexsheet.twin.controller import ControllerCore
from flexsheet.twin.controller_config import ControllerTwinConfig
from flexsheet.twin.modbus_server import ControllerTwin
from flexsheet.twin.mxt_server import MxtCore, MxtTwin
from flexsheet.twin.servo import ServoParams

__all__ = ["ArmControllerSimParams", "ArmControllerSimNode"]




ArmControllerSimParams = params_model(
    "ArmControllerSimParams",
    """Parameters of the controller twin node (SI units). ``port`` and ``period`` default by protocol.

    ``protocol``, ``host`` and ``port`` are the node's own; every other param is a field of — defined,
    defaulted and range-checked in — :class:`flexsheet.twin.controller_config.ControllerTwinConfig`.
    """,
    {"protocol": (Literal["modbus", "mxt"],
                  Field(default="modbus", description="modbus (TCP register map) or "
                        "mxt (MELFA real-time external control, UDP)")),
     "host": (str, Field(default="127.0.0.1", description="listen address")),
     "port": (int | None, Field(default=None, ge=0, le=65535, description="TCP (modbus) or UDP (mxt) port; "
                                "0 = any free port; default 15020 (modbus) / 10000 (mxt)"))},
    config_fields(ControllerTwinConfig),
    validators={"_protocol_defaults": model_validator(mode="after")(protocol_defaults)},
    module=__name__,
)


class ArmControllerSimNode(Node):
    """Node ``arm_controller_sim``: serves one controller twin over Modbus TCP or MXT/UDP (no topics besides
    diagnostics; the heartbeat message carries the MXT session counters)."""

    Params = ArmControllerSimParams
    node_type = "arm_controller_sim"

    async def setup(self) -> None:
        p = self.params
        sp = ServoParams()
        servo = ServoParams(tau=p.tau, qd_max=sp.qd_max * p.speed_scale,
                            qdd_max=sp.qd_max * p.speed_scale * p.accel_factor)
        if p.protocol == "mxt" and self.clock.simulated:
            raise ValueError("protocol mxt needs the wall clock (launch file clock: wall)")
        if p.protocol == "mxt":
            self.core = MxtCore(np.array(p.initial_joints), period=p.period, servo=servo, timeout=p.timeout_s,
                                on_timeout=p.on_timeout, step_tolerance=p.step_tolerance,
                                now=time.monotonic(),
                                owner_timeout=p.owner_timeout_s)
            self.twin = MxtTwin(self.core, p.host, p.port)
            port = await self.twin.start()
            self.state_message = f"mxt listening on udp {p.host}:{port}"
            self.timer(1.0, self._diagnose)
        else:
            self.core = ControllerCore(np.array(p.initial_joints), period=p.period, servo=servo,
                                       watchdog_periods=p.watchdog_periods, step_tolerance=p.step_tolerance,
                                       now=self.monotonic())
            # no socket: the bridge of this process calls the core at simulated instants
            if self.clock.simulated:
                loopback.register(p.host, p.port, self.core, self.now)
                self._reset_mtime = self._reset_file_mtime()
                self.timer(p.period, self._sim_tick)
                self.timer(1.0, self._diagnose)
                self.twin = None
                self.state_message = f"in-process at {p.host}:{p.port} (simulated clock)"
                self.log.info("arm controller twin (modbus) in-process at %s:%d (simulated clock, period "
                              "%.5f s)",
                              p.host, p.port, p.period)
                return
            self.twin = ControllerTwin(self.core, p.host, p.port, reset_file=p.estop_reset_path)
            port = await self.twin.start()
            self.state_message = f"listening on {p.host}:{port}"
            self.timer(1.0, self._diagnose)
        self.log.info("arm controller twin (%s) listening on %s:%d (period %.5f s)", p.protocol, p.host, port,
                      p.period)

    def _reset_file_mtime(self) -> int | None:
        path = self.params.estop_reset_path
        try:
            return os.stat(path).st_mtime_ns if path else None
        except OSError:
            return None

    def _sim_tick(self) -> None:
        """Simulated clock: one servo period; a change of ``estop_reset_path``'s mtime is the local reset."""
        now = self.now()
        self.core.advance(now)
        m = self._reset_file_mtime()
        if m is not None and m != self._reset_mtime:
            self._reset_mtime = m
            if self.core.local_reset(now):
                self.log.warning("local reset (%s): controller fault cleared", self.params.estop_reset_path)

    def _diagnose(self) -> None:
        where = (f"udp {self.params.host}:{self.twin.port}" if self.params.protocol == "mxt" else
                 f"{self.params.host}:{self.params.port}" + (" (in-process)" if self.twin is None else ""))
        self.state_message = f"{where}; {self.core.summary()}"

    async def teardown(self) -> None:
        if getattr(self, "twin", None) is not None:
            await self.twin.stop()
        elif getattr(self, "core", None) is not None:
            loopback.unregister(self.params.host, self.params.port)
