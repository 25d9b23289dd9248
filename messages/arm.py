"""Arm messages: measured joint state with the FK pose and status bits."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["ArmJointState"]


class ArmJointState(Message):
    """Measured state of one RV-1A, read back from its controller (Modbus TCP or MXT).

    ``position`` (6,) rad, J1..J6 measured; ``velocity`` (6,) rad/s (finite difference of measurements);
    ``commanded`` (6,) rad, the last joint target written; ``executing`` (6,) rad, the joint target the
    controller reports it is executing in the same reply as ``position`` (MXT: the JOINT monitor slot; Modbus:
    the ACTIVE input registers), so ``position - executing`` is the servo's own lag, free of the host link's
    delay, and ``executing - commanded`` is the link's (a command still in flight, or one the controller
    refused); ``pose`` (4, 4): FK of the measured joints, T_display_clamp (sheet-clamp tool frame in the
    display frame), m. ``status``: controller status word bits (see docs/register_map.md); ``fault``: fault
    code (0 = none). ``manipulability``: Yoshikawa's sqrt(det(J Jᵀ)). ``target_stamp``: source stamp of the
    arm target being executed, s. ``write_stamp``: time the current joint target left the bridge (Modbus write
    / MXT MOVE), s (bridge clock). ``bridge_status``: "ok", "hold:no_target", "hold:limit", "fault:watchdog"…
    """

    SCHEMA = "flexsheet/ArmJointState"
    VERSION = 2    # v2: ``executing``

    arm: str = Field(pattern="^(left|right)$", description="which arm: left or right")
    position: ndarray("float64", (6,), "measured joint angles, rad")
    velocity: ndarray("float64", (6,), "joint velocities, rad/s")
    commanded: ndarray("float64", (6,), "last commanded joint angles, rad")
    executing: ndarray("float64", (6,), "joint target the controller reports executing (MXT JOINT / Modbus "
                                        "ACTIVE), rad")
    pose: ndarray("float64", (4, 4), "FK pose T_display_clamp, m")
    status: int = Field(ge=0, description="controller status bits")
    fault: int = Field(default=0, ge=0, description="controller fault code")
    manipulability: float = Field(default=0.0, ge=0.0, description="Yoshikawa manipulability")
    target_stamp: float = Field(default=0.0, description="source stamp of the executed target, s")
    write_stamp: float = Field(default=0.0, description="time the last command left the bridge (Modbus write "
                                                        "/ MXT MOVE), s")
    bridge_status: str = Field(default="ok", description="bridge state or hold reason")
