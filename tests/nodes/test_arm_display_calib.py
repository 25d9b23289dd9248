"""The arm bridge takes its base pose from display.yaml (every node's geometry from the registration)."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest

from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.runtime.config import ConfigError
from flexsheet.runtime.testing import NodeHarness
from nodes.arm_bridge.node import ArmBridgeNode


def _calib_with_left_base_moved(path, dx: float) -> np.ndarray:
    calib = nominal_display_calib()
    T = calib.arms["left"].T_display_base.copy()
    T[0, 3] += dx
    calib.arms["left"] = replace(calib.arms["left"], T_display_base=T)
    write_display_calib(str(path), calib)
    return load_display_calib(str(path)).arms["left"].T_display_base


def test_bridge_kinematics_use_the_registered_base(tmp_path):
    T = _calib_with_left_base_moved(tmp_path / "display.yaml", 0.005)
    nominal = nominal_display_calib().arms["left"].T_display_base
    assert abs(T[0, 3] - nominal[0, 3] - 0.005) < 1e-9      # the file really moved it by 5 mm

    async def scenario():
        params = {"arm": "left", "host": "127.0.0.1", "port": 1,
                  "display_calib": str(tmp_path / "display.yaml")}
        async with NodeHarness(ArmBridgeNode, params, name="arm_left") as h:
            return h.node.kin.T_display_base.copy(), h.node.fk_kin.T_display_base.copy()

    ik_T, fk_T = asyncio.run(scenario())
    np.testing.assert_allclose(ik_T, T, atol=1e-12)
    np.testing.assert_allclose(fk_T, T, atol=1e-12)


def test_a_display_yaml_without_this_arm_is_a_configuration_error(tmp_path):
    calib = nominal_display_calib()
    calib.arms.pop("right")
    write_display_calib(str(tmp_path / "display.yaml"), calib)

    async def scenario():
        params = {"arm": "right", "host": "127.0.0.1", "port": 1,
                  "display_calib": str(tmp_path / "display.yaml")}
        async with NodeHarness(ArmBridgeNode, params, name="arm_right"):
            pass

    with pytest.raises(ConfigError, match="arms.right"):
        asyncio.run(scenario())
