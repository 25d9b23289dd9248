"""The world twin's truth: its clamps are the *true* arms' forward kinematics of the measured joints (they
differ from the bridge model's FK under a realistic truth and equal it under the ideal one, three truth
seeds), it starts at once for a new truth seed (nothing to build), and a true-sheet family missing a table
stops it at setup."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.model.sheet import clamp_poses, frame_from_clamps
from flexsheet.runtime.config import ConfigError
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world import TruePhysics
from messages import ArmJointState, Header
from messages import topics as T
from nodes.world.node import WorldNode, WorldParams


def _home_joints_and_bridge_fk(stretch: float = 0.04):
    """Joints that hold a home sheet by the bridge's (nominal) model, and that model's FK of them."""
    nom = nominal_display_calib()
    Tl, Tr = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), stretch)
    q, fk = {}, {}
    for side, T_t in (("left", Tl), ("right", Tr)):
        kin = ArmKinematics(side, nom.arms[side].T_display_base)
        res = kin.ik(T_t, home_joints(side))
        assert res.ok
        q[side], fk[side] = res.q, kin.fk(res.q)
    return q, fk


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_true_clamps_differ_from_the_bridge_model_under_realistic_truth_and_equal_it_under_ideal(seed):
    q, fk = _home_joints_and_bridge_fk()
    real = TruePhysics(TwinTruth.draw(seed, "realistic"))
    ideal = TruePhysics(TwinTruth.draw(seed, "ideal"))
    for side in ("left", "right"):
        Tr_ = real.clamp_pose(side, q[side])
        Ti = ideal.clamp_pose(side, q[side])
        assert np.abs(Ti - fk[side]).max() < 1e-12
        d = np.linalg.norm(Tr_[:3, 3] - fk[side][:3, 3])
        assert 0.3e-3 < d < 25e-3  # mm-level: base 3 mm σ, links, zero offsets
        ang = np.degrees(np.arccos(np.clip((np.trace(Tr_[:3, :3].T @ fk[side][:3, :3]) - 1) / 2, -1, 1)))
        assert 0.005 < ang < 2.0
    # the sheet they hold: off the commanded home pose under the realistic truth, exactly on it under ideal
    o_i, n_i, _, _ = frame_from_clamps(ideal.clamp_pose("left", q["left"]),
                                       ideal.clamp_pose("right", q["right"]))
    o_r, n_r, _, _ = frame_from_clamps(real.clamp_pose("left", q["left"]),
                                       real.clamp_pose("right", q["right"]))
    assert np.abs(o_i).max() < 1e-9 and n_i == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    assert np.linalg.norm(o_r) > 0.3e-3


def _state(arm: str, q: np.ndarray, pose: np.ndarray, stamp: float) -> ArmJointState:
    return ArmJointState(header=Header(stamp=stamp), arm=arm, position=q, velocity=np.zeros(6), commanded=q,
                         executing=q,
                         pose=pose, status=0)


@pytest.mark.parametrize("realism", ["realistic", "ideal"])
def test_world_node_publishes_the_sheet_of_the_true_kinematics(realism, tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))
    q, fk = _home_joints_and_bridge_fk()
    truth = TwinTruth.draw(1, realism)
    o_t, n_t, u_t, a_t = frame_from_clamps(truth.clamp_pose("left", q["left"]),
                                           truth.clamp_pose("right", q["right"]))
    o_b, _, _, _ = frame_from_clamps(fk["left"], fk["right"])

    async def scenario():
        params = {"start_delay": 0.0, "script": [{"mode": "stroke", "moving_time": 2.0}], "rate_hz": 50.0,
                  "sheet_rate_hz": 50.0, "twin": {"realism": realism, "truth_seed": 1}}
        async with NodeHarness(WorldNode, params=params) as h:
            t_meas = h.node.now() - 0.300           # joints measured 0.3 s before the world got them
            h.inject(T.ARM_LEFT_STATE, _state("left", q["left"], fk["left"], t_meas))
            h.inject(T.ARM_RIGHT_STATE, _state("right", q["right"], fk["right"], t_meas + 0.004))
            sheet = (await h.wait_for(T.SHEET_STATE, n=1, timeout=5.0))[-1]
            # stamped when that pose was true (the joints' mean stamp), not when the world published it
            assert sheet.header.stamp == pytest.approx(t_meas + 0.002, abs=1e-6)
            assert (sheet.origin == pytest.approx(o_t, abs=1e-12)
                    and sheet.normal == pytest.approx(n_t, abs=1e-12))
            # signed: negative when slack
            assert sheet.stretch == pytest.approx(2 * a_t / 0.24 - 1, abs=1e-12)
            if realism == "ideal":
                assert np.linalg.norm(sheet.origin - o_b) < 1e-12
            else:
                assert np.linalg.norm(sheet.origin - o_b) > 0.3e-3   # not the bridge's FK
    asyncio.run(scenario())


def test_world_params_take_the_twin_and_refuse_bad_values():
    p = WorldParams(twin={"realism": "ideal", "truth_seed": 4})
    assert (p.twin.realism, p.twin.truth_seed) == ("ideal", 4)
    assert WorldParams().twin.realism == "realistic"
    with pytest.raises(ValueError, match="realism"):
        WorldParams(twin={"realism": "perfect"})
    with pytest.raises(ValueError, match="truth_seed"):
        WorldParams(twin={"truth_seed": -1})
    with pytest.raises(ValueError, match="sheet_fem"):                 # the true sheet has no settings
        WorldParams(sheet_fem={"prebuild": []})


def _heartbeat(node: str, stamp: float):
    from messages import Heartbeat

    return Heartbeat(header=Header(stamp=stamp), node=node, node_type=node)


def test_world_script_waits_for_the_heartbeats_of_start_after_then_starts(tmp_path, monkeypatch):
    """The finger holds its first pose (approach start, 30 mm off the surface) until every node named in
    ``start_after`` has sent a heartbeat; a heartbeat of another node does not count; then the script runs."""
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))

    async def scenario():
        params = {"start_delay": 0.0, "start_after": ["fem", "renderer"], "rate_hz": 50.0,
                  "sheet_rate_hz": 10.0,
                  "script":
                      [{"mode": "stroke", "moving_time": 2.0, "approach_time": 0.2, "hold_before": 0.0}]}
        async with NodeHarness(WorldNode, params=params) as h:
            await asyncio.sleep(0.8)
            h.inject(T.DIAGNOSTICS, _heartbeat("planner", h.node.now()))     # not one of start_after
            h.inject(T.DIAGNOSTICS, _heartbeat("fem", h.node.now()))
            await asyncio.sleep(0.8)
            held = h.messages(T.FINGER_TRUTH)
            assert len(held) > 40 and h.node.t0 is None and h.node.waiting_for == {"renderer"}
            p0 = np.array([m.position for m in held])
            assert np.abs(p0 - p0[0]).max() < 1e-12 and {m.phase for m in held} == {"approach"}
            h.inject(T.DIAGNOSTICS, _heartbeat("renderer", h.node.now()))
            await asyncio.sleep(0.8)
            moved = h.messages(T.FINGER_TRUTH)[len(held):]
            assert h.node.t0 is not None and "stroke" in {m.phase for m in moved}
            p1 = np.array([m.position for m in moved])
            assert np.linalg.norm(p1 - p0[0], axis=1).max() > 0.02      # left the held pose (30 mm approach)
    asyncio.run(scenario())


def test_world_script_starts_after_start_timeout_without_the_heartbeats(tmp_path, monkeypatch, caplog):
    """A node of ``start_after`` that never comes up (a typo, a dead host) delays the script by
    ``start_timeout`` s, with a warning naming it — never forever."""
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))

    async def scenario():
        params = {"start_delay": 0.0, "start_after": ["fme"], "start_timeout": 0.5, "rate_hz": 50.0,
                  "sheet_rate_hz": 10.0,
                  "script":
                      [{"mode": "stroke", "moving_time": 2.0, "approach_time": 0.2, "hold_before": 0.0}]}
        async with NodeHarness(WorldNode, params=params) as h:
            await asyncio.sleep(0.3)
            assert h.node.t0 is None
            await asyncio.sleep(1.2)
            assert h.node.t0 is not None and "stroke" in {m.phase for m in h.messages(T.FINGER_TRUTH)}
    with caplog.at_level("WARNING"):
        asyncio.run(scenario())
    assert any("without a heartbeat from fme" in r.getMessage() for r in caplog.records), caplog.text
    with pytest.raises(ValueError, match="start_timeout"):
        WorldParams(start_timeout=0.0)


def test_world_starts_without_building_and_a_family_missing_a_table_stops_it_at_setup(monkeypatch):
    """A new truth seed's world is ready at once (no table to build: the family is shipped); a family that
    lacks a table is an error at setup naming the command that ships it, never a build while simulated time
    runs."""
    import time

    from flexsheet.twin import truth_sheet

    params = {"start_delay": 0.0, "rate_hz": 50.0, "sheet_rate_hz": 10.0, "twin": {"truth_seed": 9137},
              "script": [{"mode": "stroke", "moving_time": 2.0}]}

    async def ready() -> float:
        t0 = time.monotonic()
        async with NodeHarness(WorldNode, params=params) as h:
            assert h.node.t0 is not None                               # the script clock armed in setup
            return time.monotonic() - t0

    assert asyncio.run(ready()) < 10.0                                 # s, on a loaded 2-core machine
    monkeypatch.setattr(truth_sheet, "_FAMILIES", {})
    monkeypatch.setattr(truth_sheet, "node_path", lambda lay, s, folder="": f"/nonexistent/{lay}{s}.npz")
    with pytest.raises(ConfigError, match="lacks 15 of 15 tables: build and ship them with .*truth_sheet "
                                          "--ship"):
        asyncio.run(ready())
