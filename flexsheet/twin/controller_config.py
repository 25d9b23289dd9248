"""The controller twin's settings (:class:`ControllerTwinConfig`): one definition of each — name, type,
default and range — that ``nodes/arm_controller_sim``'s ``ArmControllerSimParams`` is built from
(:func:`flexsheet.runtime.params.config_fields`). Pure: no transport; the ranges are pydantic ``Field``
constraints in the annotations, checked when the params are (``--check`` included; every time, factor and
tolerance is bounded above too). The protocol and the listen address (``protocol``, ``host``, ``port``) are
the node's own params; the protocols' default port and cycle are
:data:`flexsheet.arm.bridge_config.DEFAULT_PORT` / :data:`~flexsheet.arm.bridge_config.DEFAULT_PERIOD`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import Field

from flexsheet.arm.kinematics import Q_HOME

__all__ = ["ControllerTwinConfig"]


@dataclass(frozen=True)
class ControllerTwinConfig:
    """How the RV-1A controller twin servos and times out (SI units): the control cycle (``None``: the
    protocol's), the joints at start, the servo lag and limits, the command-step check, the Modbus watchdog
    and local e-stop reset, the MXT timeout and session ownership. Each field's description says what it
    is."""

    period: Annotated[float | None,
                      Field(gt=0.0, le=0.05,
                            description="control cycle, s; default 0.0071 (modbus) / 0.00711 "
                            "(mxt, CR750-Q/CR800-Q; 0.0035 for CR800-R/D)")] = None
    initial_joints: Annotated[list[float], Field(min_length=6, max_length=6, description="joints at start, "
                                                 "rad")] = field(default_factory=lambda: Q_HOME.tolist())
    tau: Annotated[float, Field(gt=0.0, le=1.0, description="servo first-order lag time constant, s")] = 0.015
    speed_scale: Annotated[float, Field(gt=0.0, le=1.0, description="joint speed limits × URDF limits")] = 1.0
    accel_factor: Annotated[float,
                            Field(gt=0.0, le=100.0,
                                  description="acceleration limits = factor × speed limits, "
                                  "1/s")] = 4.0
    step_tolerance: Annotated[float,
                              Field(ge=1.0, le=3.0,
                                    description="largest accepted command step per cycle, × speed "
                                    "limit × period")] = 1.5
    watchdog_periods: Annotated[int, Field(ge=1, le=100, description="modbus: periods the watchdog counter "
                                           "may stall")] = 3
    timeout_s: Annotated[float, Field(le=60.0, description="mxt: no-packet timeout, s (<= 0: never, MXTTOUT "
                                                           "= -1)")] = 0.5
    on_timeout: Annotated[Literal["hold", "fault"], Field(description="mxt: after the timeout keep servoing "
                                                          "to the last command (hold) or stop and end the "
                                                          "session")] = "hold"
    owner_timeout_s: Annotated[float,
                               Field(gt=0.0, le=60.0, description="mxt: another address/port's NULL takes "
                                     "the session over only after its owner was silent this long, "
                                     "s")] = 1.0
    estop_reset_path: Annotated[str | None, Field(description="modbus: the twin's local reset (the "
                                                  "operator's reset key): each change of this file's "
                                                  "modification time (touch FILE) clears a latched e-stop; "
                                                  "the network cannot")] = None
