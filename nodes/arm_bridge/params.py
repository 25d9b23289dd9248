"""The arm bridge's parameters (:data:`ArmBridgeParams`): the node's own (which arm, protocol, controller
source and address, registration) and every field of :class:`flexsheet.arm.bridge_config.BridgeConfig`."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from flexsheet.arm.bridge_config import BridgeConfig, protocol_defaults
from flexsheet.arm.controller_port import SOURCES_GROUP
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.runtime.plugins import EntryName

__all__ = ["ArmBridgeParams"]




#: which arm and controller, and the registration file: the node's own
_DEVICE = {
    "arm": (str,
            Field(default="left", pattern="^(left|right)$", description="which sheet edge: left or right")),
    "protocol": (Literal["modbus", "mxt"],
                 Field(default="modbus", description="modbus (Modbus TCP register map) "
                       "or mxt (MELFA real-time external control, UDP)")),
    "source": (EntryName(SOURCES_GROUP, "controller source"),
               Field(default="tcp", description="where the controller is, an entry point of "
                     "flexsheet.controller_sources (flexsheet/arm/controller_port.py): tcp, over the network "
                     "on the wall clock; sim, the controller twin of this process on a simulated clock")),
    "host": (str, Field(default="127.0.0.1", description="controller (or twin) address")),
    "twin": (TruthChoice, Field(default_factory=TruthChoice, description="source sim: the hidden truth "
                                "that draws this arm PC's clock offset from main "
                                "(flexsheet/twin/lab_clock.py)")),
    "port": (int | None, Field(default=None, ge=1, le=65535, description="controller port: Modbus TCP "
                               "(default 15020) or MXT UDP (default 10000)")),
    "device_id": (int, Field(default=1, ge=0, le=255, description="Modbus unit id")),
    "display_calib": (str | None, Field(default=None, description="display.yaml (the registration): this "
                                        "arm's base pose comes from its arms.<arm> entry (flexsheet "
                                        "calibrate arms); the launch file's display_calib fills it")),
}

ArmBridgeParams = params_model(
    "ArmBridgeParams",
    """Parameters of one arm bridge (SI units: m, rad, s).

    ``arm``, ``protocol``, ``source``, ``host``, ``port``, ``device_id``, ``display_calib`` and ``twin`` are
    the node's own (``port`` defaults by protocol); every other param is a field of — defined, defaulted and
    range-checked in — :class:`flexsheet.arm.bridge_config.BridgeConfig` (``period`` defaults by protocol).
    """,
    _DEVICE,
    config_fields(BridgeConfig),
    validators={"_protocol_defaults": model_validator(mode="after")(protocol_defaults)},
    module=__name__,
)
