"""The arm bridge's settings (:class:`BridgeConfig`): one definition of each — name, type, default and range —
that ``nodes/arm_bridge``'s ``ArmBridgeParams`` is built from
(:func:`flexsheet.runtime.params.config_fields`), and the controller protocols' defaults
(:data:`DEFAULT_PORT`, :data:`DEFAULT_PERIOD`) that the bridge and the controller twin fill in. Pure: no
transport; the ranges are pydantic ``Field`` constraints in the annotations, checked when the params are
(``flexsheet launch FILE --check`` included): every time, scale and tolerance has an upper bound as well, so a
value like ``target_timeout: 1e9`` is refused naming the field and the value. Which arm and controller
(``arm``, ``protocol``, ``host``, ``port``, ``device_id``) and the registration file (``display_calib``) are
the node's own params."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from pydantic import Field

from messages import mxt

__all__ = ["BridgeConfig", "DEFAULT_PORT", "DEFAULT_PERIOD", "protocol_defaults"]

#: the controller's port by protocol: Modbus TCP, MXT UDP
DEFAULT_PORT = {"modbus": 15020, "mxt": mxt.DEFAULT_PORT}
#: the controller cycle by protocol, s (MXT: CR750-Q, CR800-Q; 0.0035 for CR800-R/D)
DEFAULT_PERIOD = {"modbus": 0.0071, "mxt": 0.00711}


def protocol_defaults(params):
    """Fill ``params.port`` and ``params.period`` left None with their ``params.protocol``'s defaults
    (:data:`DEFAULT_PORT`, :data:`DEFAULT_PERIOD`); returns ``params`` (a pydantic ``after`` validator)."""
    if params.port is None:
        params.port = DEFAULT_PORT[params.protocol]
    if params.period is None:
        params.period = DEFAULT_PERIOD[params.protocol]
    return params


@dataclass(frozen=True)
class BridgeConfig:
    """How one arm bridge streams (SI units: m, rad, s): the arm's base, the cycle, the target timeout, the
    command limits, bring-up switches and the link's timeouts. ``None`` for ``base``/``period``: the design
    base / the protocol's cycle. Each field's description says what it is."""

    base: Annotated[list[float] | None,
                    Field(min_length=4, max_length=4, description="arm base (x, y, z, yaw) in "
                          "the display frame, only without display_calib; default "
                          "kinematics.LEFT_BASE / RIGHT_BASE (the design values)")] = None
    period: Annotated[float | None,
                      Field(gt=0.0, le=0.05,
                            description="controller cycle = stream period, s; default 0.0071 "
                            "(modbus) / 0.00711 (mxt: CR750-Q, CR800-Q; 0.0035 for CR800-R/D)")] = None
    target_timeout: Annotated[float,
                              Field(gt=0.0, le=5.0, description="hold after this long without a target, "
                                    "s")] = 0.25
    speed_scale: Annotated[float, Field(gt=0.0, le=1.0, description="commanded speed limit × URDF "
                                                                    "speed")] = 0.5
    accel_scale: Annotated[float, Field(gt=0.0, le=100.0, description="commanded accel limit = scale × speed "
                                        "limit, 1/s (6: a joint reaches its speed limit in 1/6 s; an "
                                        "assumption, no RV-1A figure found: three quarters of the controller "
                                        "twin's limit, accel_factor 4 × the full URDF speed)")] = 6.0
    limit_margin: Annotated[float, Field(ge=0.0, le=0.2, description="kept from each joint limit, "
                                                                     "rad")] = 0.02
    max_ik_jump: Annotated[float, Field(gt=0.0, le=1.0, description="largest joint change one target may "
                                                                    "ask, rad")] = 0.5
    span_band: Annotated[tuple[float, float] | None,
                         Field(description="[lo, hi] m: the clamp span the two arms "
                                                         "keep (this arm's command to the partner's measured "
                                                         "clamp); a step further outside waits; None: no "
                                                         "guard. Default: clamp strain 0.005-0.10 of the "
                                                         "0.240 m sheet: the planner's 0.01 least stretch "
                                                         "with room below for the arms' "
                                                         "tracking")] = (0.2412, 0.264)
    keepout_margin: Annotated[float,
                              Field(ge=0.0, le=0.3, description="m: the last line behind the planner's head "
                                    "guard: a target that puts this arm's links (0.05 m capsules) or its "
                                    "clamp within this margin of the tracked head's 0.10 m sphere is "
                                    "refused (hold:keep_out); the planner keeps 0.05 m")] = 0.03
    enabled: Annotated[bool, Field(description="false: read the controller every cycle and command nothing "
                                   "(MXT: NULL packets; Modbus: reads only) — first bring-up")] = True
    auto_reset: Annotated[bool, Field(description="reset watchdog faults automatically (never "
                                                  "e-stops)")] = True
    request_timeout: Annotated[float, Field(gt=0.0, le=2.0, description="Modbus request timeout, s")] = 0.1
    backoff_min: Annotated[float, Field(gt=0.0, le=10.0, description="first reconnect delay, s")] = 0.05
    backoff_max: Annotated[float, Field(gt=0.0, le=60.0, description="largest reconnect delay, s")] = 2.0
    mxt_open_timeout: Annotated[float,
                                Field(gt=0.0, le=5.0,
                                      description="mxt: wait for the NULL packet's reply, s")] = 0.2
    mxt_lost_cycles: Annotated[int,
                               Field(ge=2, le=10_000,
                                     description="mxt: cycles without a reply before reopening")] = 50
