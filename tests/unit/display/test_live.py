"""``flexsheet calibrate display --live`` without a graph (flexsheet.display.live): the plan checked against
the joint limits, and the live frame source's refusals (board not found, an arm refusing or not arriving) and
resume, on a scripted graph client. The whole run on the three-host graph:
tests/system/test_live_registration.py."""

import json
import os

import cv2
import numpy as np
import pytest

from flexsheet.calibration import camera_pose as cp
from flexsheet.calibration.procedures import FULL, QUICK
from flexsheet.display.live import LiveError, LiveSource, Roles, check_plan
from flexsheet.runtime.client import GraphClient
from flexsheet.runtime.services import ServiceError
from messages import ArmJointState, Header, StereoFrame, topics

ROLES = Roles("camera", "renderer", {"left": "arm_left", "right": "arm_right"})


class ScriptedGraph:
    """Stands in for :class:`GraphClient`: arms that arrive at once (or ``stuck``), a camera that delivers
    ``image`` (uint8 (512, 640)) in both eyes, and a log of the service calls."""

    launch = "scripted"
    wait = GraphClient.wait

    def __init__(self, image=None, stuck=False, refuse=None):
        self.image = np.zeros((512, 640), np.uint8) if image is None else image
        self.stuck, self.refuse = stuck, refuse
        self.calls: list[tuple[str, str, dict]] = []
        self.q = {"left": np.zeros(6), "right": np.zeros(6)}

    def watch(self, topic, keep_latest=True):
        pass

    def call(self, node, service, args=None, timeout=5.0):
        self.calls.append((node, service, args or {}))
        if service == "move_to":
            side = "left" if node == "arm_left" else "right"
            if self.refuse == side:
                raise ServiceError("joints outside the limits (with the bridge's margin): J3 59.0 deg "
                                   "outside")
            if not self.stuck:
                self.q[side] = np.asarray(args["joints"], float)
        if service == "home":
            side = "left" if node == "arm_left" else "right"
            self.q[side] = np.full(6, 0.1 if side == "left" else -0.1)
            return self.q[side].tolist()
        return None

    def now(self, node):
        return 100.0

    def latest(self, topic):
        side = "left" if topic is topics.ARM_LEFT_STATE else "right"
        z = np.zeros(6)
        return ArmJointState(header=Header(stamp=1.0), arm=side, position=self.q[side], velocity=z,
                             commanded=z,
                             executing=z, pose=np.eye(4), status=0)

    def collect(self, topic, n, after, timeout, stamp=None):
        return [StereoFrame(header=Header(stamp=after), left=self.image, right=self.image,
                            exposure_stamp=after,
                            exposure_time=0.004) for _ in range(n)]


def test_every_planned_pose_is_inside_the_bridges_joint_margin():
    lines, problems = check_plan(FULL)
    assert problems == []
    assert len(lines) == FULL.views + FULL.projector_poses + 2 * FULL.arm_configs == 59
    assert lines[0].startswith("board view 1/21: sheet at (+0, +0, +0) mm")


def test_a_pose_inside_the_margin_is_named(monkeypatch):
    """The plan's old 21st view (tilt 35°, turn 30°) put the left elbow 0.7° inside the bridges' margin."""
    monkeypatch.setattr(cp, "VIEW_PLAN", (*cp.VIEW_PLAN[:1], (-35, -30, (0, 0, 0))))
    _, problems = check_plan(QUICK.__class__(views=2, projector_poses=1, arm_configs=2))
    assert problems == ["board view 2/2, left arm: J3 60.7 deg outside [61.1, 153.9]"]


def test_the_world_is_paused_meanwhile_and_the_arms_go_home_before_they_follow_again(tmp_path):
    """begin() pauses the world twin's script; finish() clears the image, homes both arms and waits for them,
    releases them, gives the camera twin its finger back and resumes the script, in that order."""
    g = ScriptedGraph()
    roles = Roles("camera", "renderer", {"left": "arm_left", "right": "arm_right"}, world="world")
    src = LiveSource(g, roles, str(tmp_path), QUICK, twin=True, settle_s=0.0)
    src.begin()
    assert g.calls == [("world", "script/pause", {})]
    src._scene = "board"
    src.finish()
    assert [(n, s) for n, s, _ in g.calls[1:]] == [
        ("renderer", "clear_image"), ("arm_left", "home"), ("arm_right", "home"), ("arm_left", "release"),
        ("arm_right", "release"), ("camera", "twin/scene"), ("world", "script/resume")]
    assert np.allclose(g.q["left"], 0.1) and np.allclose(g.q["right"], -0.1)
    g2 = ScriptedGraph()
    LiveSource(g2, ROLES, str(tmp_path), QUICK, twin=True).begin()
    assert g2.calls == []                                  # a lab without a world twin: nothing to pause


def test_a_board_not_found_is_refused_in_one_line_and_kept(tmp_path):
    g = ScriptedGraph()                                   # a black image: no board
    src = LiveSource(g, ROLES, str(tmp_path), QUICK, twin=True, settle_s=0.0)
    with pytest.raises(LiveError, match=r"^camera-pose: view 1/2: the board \(chessboard:9x8\) is not found "
                                        r"in the left image \(saved as .*view00_left.rejected.png\)$"):
        src.board_views(QUICK.board_spec(), cp.plan_board_views(2))
    assert os.path.isfile(tmp_path / "frames" / "camera_pose" / "view00_left.rejected.png")
    assert not os.path.exists(tmp_path / "frames" / "camera_pose" / "view00_left.png")
    assert ("camera", "twin/scene", {"scene": "board", "board": "chessboard:9x8", "square": 0.022,
                                     "offset": 0.0}) in g.calls


def test_captured_views_are_resumed_without_moving(tmp_path):
    d = tmp_path / "frames" / "camera_pose"
    d.mkdir(parents=True)
    img = np.full((512, 640), 77, np.uint8)
    for k in range(2):
        for side in ("left", "right"):
            cv2.imwrite(str(d / f"view{k:02d}_{side}.png"), img)
    g = ScriptedGraph()
    views = LiveSource(g, ROLES, str(tmp_path), QUICK, twin=True).board_views(
        QUICK.board_spec(), cp.plan_board_views(2))
    assert len(views) == 2 and all(int(a[0, 0]) == 77 for a, _ in views)
    assert g.calls == []


def test_an_arm_that_refuses_or_does_not_arrive_stops_the_run_naming_it(tmp_path):
    src = LiveSource(ScriptedGraph(refuse="right"), ROLES, str(tmp_path), QUICK, twin=True)
    with pytest.raises(LiveError, match="^camera-pose: view 1/2: the right arm refused it: joints outside "
                                        "the limits"):
        src.board_views(QUICK.board_spec(), cp.plan_board_views(2))
    src = LiveSource(ScriptedGraph(stuck=True), ROLES, str(tmp_path), QUICK, twin=True, move_timeout_s=0.2)
    with pytest.raises(LiveError, match=r"did not arrive within 0.2 s \(still left [0-9.]+°, right [0-9.]+° "
                                        r"away\)"):
        src.board_views(QUICK.board_spec(), cp.plan_board_views(2))


def test_marker_captures_resume_from_the_manifest(tmp_path):
    """Arm configurations captured before an interruption are read back (their commanded joints from the
    manifest); the rest are captured, and the manifest ends with every one."""
    qs = [np.full(6, 0.1 * k) for k in range(3)]
    d = tmp_path / "frames" / "arms" / "left"
    d.mkdir(parents=True)
    for side in ("left", "right"):
        cv2.imwrite(str(d / f"config00_{side}.png"), np.full((512, 640), 9, np.uint8))
    (tmp_path / "frames"
     / "manifest.json").write_text(json.dumps({"arms": {"left": {"joints": [qs[0].tolist()]}}}))
    g = ScriptedGraph(image=np.full((512, 640), 50, np.uint8))
    frames, used = LiveSource(g, ROLES, str(tmp_path), QUICK, twin=True, settle_s=0.0).marker_frames("left",
                                                                                                     qs)
    assert [int(a[0, 0]) for a, _ in frames] == [9, 50, 50]
    moved = [np.asarray(a["joints"]) for n, s, a in g.calls if s == "move_to" and n == "arm_left"]
    assert len(moved) == 2 and np.allclose(moved[0], qs[1])
    man = json.loads((tmp_path / "frames" / "manifest.json").read_text())
    assert np.allclose(man["arms"]["left"]["joints"], qs)
