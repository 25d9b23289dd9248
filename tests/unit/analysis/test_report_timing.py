"""The latency chain from a bag (flexsheet.analysis.report_timing): every hop a difference of the nodes'
stamps, the ends their sums."""

from __future__ import annotations

import numpy as np
import pytest


def test_latency_chain_comes_from_the_nodes_stamps_and_adds_up():
    """One fingertip sample through both chains, with made-up stamps (s): every hop is a difference of stamps
    the nodes set (the recorder's arrival times, here absurd on purpose, are never used); the ends are the
    sums; the sheet is at its pose at the later of the two arms' first readbacks within 0.1 mm and 0.05
    deg."""
    from types import SimpleNamespace as NS

    from flexsheet.analysis.report_timing import latency_hops
    from flexsheet.model.timing import LAB

    e = 100.0
    goal = np.eye(4)
    near = np.eye(4)
    near[:3, 3] = [5e-5, 0.0, 0.0]                     # 0.05 mm off: at the pose
    far = np.eye(4)
    far[:3, 3] = [2e-4, 0.0, 0.0]                      # 0.2 mm off: not yet
    tip = NS(exposure_stamp=e, frame_stamp=e + 0.006, sent_stamp=e + 0.007)
    d = {"/fingertip": [(999.0, tip)],
         "/sheet/target": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0075)))],
         "/object/deformation": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0074)))],
         "/render/stereo": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0114)))]}
    for arm, t_write, t_at in (("left", e + 0.0080, e + 0.0200), ("right", e + 0.0078, e + 0.0271)):
        d[f"/arm/{arm}/target"] = [(0.0, NS(source_stamp=e, pose=goal))]
        d[f"/arm/{arm}/joint_state"] = [
            (0.0, NS(target_stamp=e, write_stamp=t_write, pose=far, header=NS(stamp=t_write + 0.001))),
            (0.0, NS(target_stamp=e, write_stamp=t_write, pose=near, header=NS(stamp=t_at)))]
    out = latency_hops(d)
    c = {k: v["median"] for k, v in out["chain"].items()}
    assert (c["exposure_to_camera_frame"] == pytest.approx(6.0)
            and c["camera_frame_to_fingertip"] == pytest.approx(1.0))
    assert c["fingertip_to_sheet_target"] == pytest.approx(0.5)
    assert c["sheet_target_to_arm_command"] == pytest.approx(0.3)  # the earlier of the two arms' writes
    assert c["exposure_to_arm_command"] == pytest.approx(7.8)
    assert c["arm_command_to_sheet_at_pose"] == pytest.approx(27.1 - 7.8)   # the later arm at its pose
    assert c["exposure_to_sheet_at_pose"] == pytest.approx(27.1) and out["sheet_at_pose_reached"] == 1.0
    projected = (LAB.projected_at(e + 0.0114) - e) * 1e3
    assert c["exposure_to_projected"] == pytest.approx(projected)
    assert c["exposure_to_projected"] == pytest.approx(sum(c[h] for h in (
        "exposure_to_camera_frame", "camera_frame_to_fingertip", "fingertip_to_deformation",
        "deformation_to_rendered_frame", "rendered_to_projected")))
    assert (11.4 + 0.0 < projected <= 11.4 + 1e3 / LAB.projector_refresh_hz
            + LAB.projector_input_latency_s * 1e3)
