"""The display's registration driven through the live graph (``flexsheet calibrate display --live``): the
procedures of :mod:`flexsheet.calibration.procedures` on frames this module captures by moving the arms
(the bridges' ``move_to`` service), showing the Gray-code patterns (the renderer's ``show_image``) and
averaging the camera's ``/camera/stereo`` frames.

Every capture is written in the layout of :class:`flexsheet.calibration.sources.ImageDirSource` under
``OUT/frames`` (with its ``manifest.json``), so an interrupted run resumes where it stopped and ``flexsheet
calibrate display --images OUT/frames`` re-runs the fit offline. What the operator sets up by hand in the lab
(the board on the sheet, the room dark, the sheet unclamped for the arm step) is asked at the terminal; in
the twin (camera ``source: sim``) the camera twin's ``twin/scene`` service sets it.

The sheet poses are commanded as joints solved with the *nominal* kinematics
(:func:`flexsheet.twin.registration_camera.commanded_sheet_joints`), the arms being what is registered; the
bridges keep the RV-1A's joint limits (with their margin) and speed limits.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sys
from dataclasses import dataclass, field

import cv2
import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, home_joints, outside_limits
from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import camera_pose as cp_mod
from flexsheet.calibration import projector as pj_mod
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import write_display_calib
from flexsheet.calibration.procedures import Options, run_all
from flexsheet.calibration.sources import ImageDirSource
from flexsheet.runtime.client import GraphClient
from flexsheet.runtime.services import ServiceError
from flexsheet.twin.registration import score_registration, verdicts
from flexsheet.twin.registration_camera import commanded_sheet_joints
from flexsheet.twin.truth import TwinTruth
from messages import StereoFrame
from messages import topics as T

log = logging.getLogger(__name__)

__all__ = ["Roles", "roles_of", "plan", "check_plan", "LiveSource", "LiveError", "register_live"]

Pair = tuple[np.ndarray, np.ndarray]


class LiveError(RuntimeError):
    """A step of the live registration that cannot go on: one line saying which and why."""


@dataclass
class Roles:
    """The launch file's nodes that the registration talks to."""

    camera: str
    renderer: str
    arms: dict[str, str]                 # side → arm bridge node
    hosts: dict[str, str] = field(default_factory=dict)   # node → host
    world: str | None = None             # the twin's world node (its script is paused meanwhile), if any


def roles_of(lf) -> Roles:
    """The camera, renderer and both arm bridges of launch file ``lf``; raises ``LiveError`` naming a
    missing one."""
    by_type: dict[str, list[str]] = {}
    for name, spec in lf.nodes.items():
        by_type.setdefault(spec.type, []).append(name)
    arms = {}
    for name in by_type.get("arm_bridge", []):
        arms[lf.nodes[name].params.get("arm", "left")] = name
    for what, found in (("camera", by_type.get("camera")), ("renderer", by_type.get("renderer"))):
        if not found:
            raise LiveError(f"the launch file has no {what} node: the registration needs one")
    for side in ("left", "right"):
        if side not in arms:
            raise LiveError(f"the launch file has no arm_bridge node for the {side} arm")
    return Roles(by_type["camera"][0], by_type["renderer"][0], arms,
                 {n: s.host for n, s in lf.nodes.items()}, (by_type.get("world") or [None])[0])


def plan(opts: Options) -> dict:
    """The poses the registration commands: ``board`` and ``projector`` (lists of sheet poses (4, 4), display
    frame) and ``arms`` (side → list of (6,) rad; planned from the nominal camera: the live run plans them
    from the measured one)."""
    nom = nominal_display_calib()
    cam = nom.camera
    return {"board": cp_mod.plan_board_views(opts.views),
            "projector":
                pj_mod.plan_projector_poses(min(max(opts.projector_poses, 1), len(pj_mod.POSE_PLAN))),
            "arms": {s: arms_mod.plan_arm_configs(s, opts.arm_configs, nom.arms[s].T_display_base,
                                                  nom.arms[s].marker_offset, cam.stereo, cam.T_display_camera)
                     for s in ("left", "right")}}


def _limits_problem(q: np.ndarray, margin: float) -> str:
    return "; ".join(outside_limits(q, Q_LOWER + margin, Q_UPPER - margin))


def check_plan(opts: Options, margin: float = BridgeConfig.limit_margin) -> tuple[list[str], list[str]]:
    """(lines describing every commanded pose and its joints, problems): a pose whose nominal IK fails or
    whose joints leave the RV-1A's limits less ``margin`` rad (default: the bridges' ``limit_margin``)."""
    p = plan(opts)
    lines, problems = [], []
    cache: dict = {}

    def sheet(label: str, Tc: np.ndarray) -> None:
        n = Tc[:3, 0]
        tilt = math.degrees(math.atan2(n[1], n[0])), math.degrees(math.asin(np.clip(n[2], -1, 1)))
        head = (f"{label}: sheet at ({Tc[0, 3] * 1e3:+.0f}, {Tc[1, 3] * 1e3:+.0f}, {Tc[2, 3] * 1e3:+.0f}) "
                f"mm, normal yaw {tilt[0]:+.1f}° pitch {tilt[1]:+.1f}°")
        try:
            qs = commanded_sheet_joints(Tc, 0.0, cache)
        except ValueError as exc:
            problems.append(f"{label}: {exc}")
            lines.append(f"{head}: UNREACHABLE")
            return
        for side, q in qs.items():
            bad = _limits_problem(q, margin)
            if bad:
                problems.append(f"{label}, {side} arm: {bad}")
        lines.append(f"{head}; " + "; ".join(f"{s} [{', '.join(f'{math.degrees(v):.1f}' for v in q)}]°"
                                             for s, q in qs.items()))

    for k, Tc in enumerate(p["board"]):
        sheet(f"board view {k + 1}/{len(p['board'])}", Tc)
    for k, Tc in enumerate(p["projector"]):
        sheet(f"projector pose {k + 1}/{len(p['projector'])}", Tc)
    for side, qs in p["arms"].items():
        for k, q in enumerate(qs):
            bad = _limits_problem(q, margin)
            if bad:
                problems.append(f"arm {side} configuration {k + 1}: {bad}")
            lines.append(f"arm {side} configuration {k + 1}/{len(qs)}: "
                         f"[{', '.join(f'{math.degrees(v):.1f}' for v in q)}]°"
                         + (" OUTSIDE THE LIMITS" if bad else ""))
    return lines, problems


def _mean(frames: list[StereoFrame]) -> Pair:
    """The frames averaged (each already quantised by the camera), rounded to uint8."""
    left = np.mean([f.left for f in frames], axis=0, dtype=np.float64)
    right = np.mean([f.right for f in frames], axis=0, dtype=np.float64)
    return (np.clip(np.rint(left), 0, 255).astype(np.uint8), np.clip(np.rint(right), 0, 255).astype(np.uint8))


class LiveSource:
    """A frame source for the procedures (the interface of :class:`ImageDirSource`) that captures through the
    live graph (module doc). ``client``: a :class:`flexsheet.runtime.client.GraphClient`; ``roles``: from
    :func:`roles_of`; ``out``: the run's folder (frames under ``out/frames``); ``opts``: the procedures'
    options (frames averaged per capture, board); ``twin``: the camera is the twin (scenes set by its
    service, not asked); ``settle_s``: after the arms arrive or a pattern is shown, before frames count;
    ``ask``: how the operator is asked (default: a line on stderr, Enter on stdin)."""

    kind = "live"

    def __init__(self, client, roles: Roles, out: str, opts: Options, twin: bool, settle_s: float = 0.3,
                 move_timeout_s: float = 60.0, ask=None):
        self.client, self.roles, self.opts, self.twin = client, roles, opts, twin
        self.root = os.path.join(out, "frames")
        self.settle_s, self.move_timeout_s = float(settle_s), float(move_timeout_s)
        self.ask = ask or self._ask_terminal
        self.manifest: dict = {}
        self._scene = None
        self.client.watch(T.ARM_LEFT_STATE)
        self.client.watch(T.ARM_RIGHT_STATE)
        self.client.watch(T.STEREO, keep_latest=False)

    @property
    def label(self) -> str:
        return f"live graph {self.client.launch}" + (" (camera twin)" if self.twin else "")

    # ------------------------------------------------------------------ operator / scene
    @staticmethod
    def _ask_terminal(line: str) -> None:
        if not sys.stdin.isatty():
            raise LiveError(f"an operator must {line} — stdin is not a terminal to confirm it on")
        print(f"==> {line}, then press Enter", file=sys.stderr, flush=True)
        sys.stdin.readline()

    _ASK = {"board": "clamp the calibration board ({board}) flat on the sheet, printed side toward the "
                     "camera",
            "patterns": "take the board off the sheet and darken the room (the projector lights the bare "
                        "sheet)",
            "markers": "unclamp the sheet from both arms and keep the room dark (only the clamp markers lit)",
            "finger": "take away what the registration needed (board, dark room): the display runs again"}

    def _set_scene(self, scene: str) -> None:
        if scene == self._scene:
            return
        if self.twin:
            self.client.call(self.roles.camera, "twin/scene", {"scene": scene, "board": self.opts.board,
                                                              "square": self.opts.square,
                                                              "offset": self.opts.board_offset})
        else:
            self.ask(self._ASK[scene].format(board=f"{self.opts.board}, {self.opts.square * 1e3:g} mm "
                                                   "squares"))
        self._scene = scene

    def begin(self) -> None:
        """Before the first capture: the world twin's script paused (its finger away, so the planner holds and
        nothing strokes the sheet the registration moves)."""
        if self.roles.world is not None:
            self.client.call(self.roles.world, "script/pause")
            log.info("live: the world's script is paused while the registration runs")

    def _home(self) -> None:
        """Both arms to the home sheet's clamp poses (the bridges' ``home``), waited for: the display's
        targets start near there."""
        goals = {side: np.asarray(self.client.call(node, "home"), float) for side,
                 node in self.roles.arms.items()}
        self._wait_there(goals, "home")

    def finish(self) -> None:
        """Back to the display: the scene drawn again, the arms home and following targets, the camera twin's
        finger, the world's script running on."""
        steps = [lambda: self.client.call(self.roles.renderer, "clear_image"), self._home,
                 *(lambda n=n: self.client.call(n, "release") for n in self.roles.arms.values()),
                 lambda: self._set_scene("finger")]
        if self.roles.world is not None:
            steps.append(lambda: self.client.call(self.roles.world, "script/resume"))
        for step in steps:
            try:
                step()
            except Exception as exc:  # noqa: BLE001 - best effort on the way out; said, not raised
                log.info(f"live: cleanup: {exc}")

    # ------------------------------------------------------------------ arms and camera
    def _move(self, goals: dict[str, np.ndarray], what: str) -> None:
        """Command each arm of ``goals`` (side → (6,) rad) and wait until each is there and still."""
        for side, q in goals.items():
            try:
                self.client.call(self.roles.arms[side], "move_to", {"joints": [float(v) for v in q]})
            except Exception as exc:  # noqa: BLE001 - one line naming the pose
                raise LiveError(f"{what}: the {side} arm refused it: {exc}") from None
        self._wait_there(goals, what)

    def _wait_there(self, goals: dict[str, np.ndarray], what: str) -> None:
        """Wait until each arm of ``goals`` (side → (6,) rad) is there and still; :class:`LiveError` after the
        move timeout, saying how far each still is."""
        topic = {"left": T.ARM_LEFT_STATE, "right": T.ARM_RIGHT_STATE}

        def there() -> bool:
            for side, q in goals.items():
                m = self.client.latest(topic[side])
                if m is None or np.max(np.abs(m.position - q)) > 2e-5 or np.max(np.abs(m.velocity)) > 1e-3:
                    return False
            return True

        try:
            self.client.wait(what, there, self.move_timeout_s)
        except TimeoutError:
            far = {s: float(np.degrees(np.max(np.abs(self.client.latest(topic[s]).position - q))))
                   for s, q in goals.items() if self.client.latest(topic[s]) is not None}
            raise LiveError(f"{what}: the arms did not arrive within {self.move_timeout_s:g} s (still "
                            + ", ".join(f"{s} {d:.3f}°" for s, d in far.items()) + " away)") from None

    def _capture(self, n: int, what: str, after: float | None = None) -> Pair:
        """``n`` camera frames exposed after ``after`` (default: now + settle), averaged."""
        if after is None:
            after = self.client.now(self.roles.camera) + self.settle_s
        try:
            frames = self.client.collect(T.STEREO, n, after, timeout=30.0 + n,
                                         stamp=lambda m: m.exposure_stamp)
        except TimeoutError as exc:
            raise LiveError(f"{what}: no camera frames ({exc})") from None
        return _mean(frames)

    @staticmethod
    def _save(path_left: str, pair: Pair) -> None:
        os.makedirs(os.path.dirname(path_left), exist_ok=True)
        for p, img in zip((path_left, path_left.replace("_left.png", "_right.png")), pair, strict=True):
            tmp = p + ".tmp.png"
            cv2.imwrite(tmp, img)
            os.replace(tmp, p)          # a half-written frame is never resumed from

    @staticmethod
    def _load(path_left: str) -> Pair | None:
        right = path_left.replace("_left.png", "_right.png")
        if not (os.path.isfile(path_left) and os.path.isfile(right)):
            return None
        return cv2.imread(path_left, cv2.IMREAD_GRAYSCALE), cv2.imread(right, cv2.IMREAD_GRAYSCALE)

    def _sheet(self, T_cmd: np.ndarray, what: str) -> None:
        try:
            qs = commanded_sheet_joints(np.asarray(T_cmd, float))
        except ValueError as exc:
            raise LiveError(f"{what}: {exc}") from None
        self._move(qs, what)

    # ------------------------------------------------------------------ the procedures' interface
    def _lit_by(self, stamp: float) -> dict | None:
        st = self.client.call(self.roles.camera, "twin/state")
        return st if st["projector_stamp"] == stamp else None

    def board_views(self, board, sheet_poses: list[np.ndarray], offset: float = 0.0) -> list[Pair]:
        """One averaged pair per sheet pose (home first); a view whose board is not found in either image is
        refused."""
        out = []
        for k, Tc in enumerate(sheet_poses):
            path = os.path.join(self.root, "camera_pose", f"view{k:02d}_left.png")
            pair = self._load(path)
            what = f"camera-pose: view {k + 1}/{len(sheet_poses)}"
            if pair is None:
                self._set_scene("board")
                self._sheet(Tc, what)
                pair = self._capture(self.opts.board_frames, what)
                for side, img in zip(("left", "right"), pair, strict=True):
                    if cp_mod.detect_corners(img, board) is None:
                        bad = path.replace("_left.png", f"_{side}.rejected.png")
                        os.makedirs(os.path.dirname(bad), exist_ok=True)
                        cv2.imwrite(bad, img)
                        raise LiveError(f"{what}: the board ({self.opts.board}) is not found in the {side} "
                                        f"image (saved as {bad})")
                self._save(path, pair)
                log.info(f"{what}: captured ({self.opts.board_frames} frames)")
            out.append(pair)
        return out

    def pattern_frames(self, patterns: list[np.ndarray], sheet_pose: np.ndarray, index: int) -> list[Pair]:
        """A pair of every pattern (shown by the renderer) with the sheet at ``sheet_pose``."""
        d = os.path.join(self.root, "projector", f"pose{index:02d}")
        paths = [os.path.join(d, f"img{k:02d}_left.png") for k in range(len(patterns))]
        have = [self._load(p) for p in paths]
        if all(h is not None for h in have):
            return have
        what = f"projector: pose {index + 1}"
        self._set_scene("patterns")
        self._sheet(sheet_pose, what)
        pdir = os.path.join(os.path.dirname(self.root), "patterns")
        os.makedirs(pdir, exist_ok=True)
        out = []
        for k, (pat, path) in enumerate(zip(patterns, paths, strict=True)):
            if have[k] is not None:
                out.append(have[k])
                continue
            file = os.path.abspath(os.path.join(pdir, f"pattern{k:02d}.png"))
            if not os.path.isfile(file):
                cv2.imwrite(file, pat)
            try:
                shown = self.client.call(self.roles.renderer, "show_image", {"path": file})
            except Exception as exc:  # noqa: BLE001 - one line naming the pattern
                raise LiveError(f"{what}: the renderer could not show pattern {k + 1}: {exc}") from None
            after = float(shown["stamp"]) + self.settle_s
            if self.twin:       # the twin's light is a message: frames count once the camera twin has it
                st = self.client.wait(f"{what}, pattern {k + 1}: the camera twin lit by it",
                                      lambda stamp=shown["stamp"]: self._lit_by(stamp), timeout=30.0)
                after = max(after, float(st["now"]))
            pair = self._capture(self.opts.pattern_frames, f"{what}, pattern {k + 1}", after=after)
            self._save(path, pair)
            out.append(pair)
        self.client.call(self.roles.renderer, "clear_image")
        man = self._manifest()
        man["projector"] = {"width": int(patterns[0].shape[1]), "height": int(patterns[0].shape[0])}
        self._write_manifest(man)
        log.info(f"{what}: {len(patterns)} patterns captured")
        return out

    def marker_frames(self, side: str, joints: list[np.ndarray]) -> tuple[list[Pair], list[np.ndarray]]:
        """Pairs of the clamp markers while arm ``side`` visits ``joints`` (the other arm at its home joints);
        returns (frames, the joints commanded)."""
        d = os.path.join(self.root, "arms", side)
        man = self._manifest()
        done = man.get("arms", {}).get(side, {}).get("joints", [])
        if len(done) == len(joints) and np.allclose(done, joints, atol=1e-9):
            return ImageDirSource(self.root).marker_frames(side)
        self._set_scene("markers")
        other = "right" if side == "left" else "left"
        self._move({other: home_joints(other)}, f"arms: {other} arm to its home joints")
        frames = []
        for k, q in enumerate(joints):
            what = f"arms: {side} configuration {k + 1}/{len(joints)}"
            path = os.path.join(d, f"config{k:02d}_left.png")
            pair = self._load(path) if k < len(done) and np.allclose(done[k], q, atol=1e-9) else None
            if pair is None:
                self._move({side: np.asarray(q, float)}, what)
                pair = self._capture(self.opts.marker_frames, what)
                self._save(path, pair)
                man.setdefault("arms",
                               {})[side] = {"joints": [np.asarray(v, float).tolist() for v in joints[:k + 1]]}
                self._write_manifest(man)
            frames.append(pair)
        log.info(f"arms: {side}: {len(joints)} configurations captured")
        return frames, [np.asarray(q, float) for q in joints]

    # ------------------------------------------------------------------ manifest
    def _manifest(self) -> dict:
        path = os.path.join(self.root, "manifest.json")
        if os.path.isfile(path):
            with open(path) as fh:
                return json.load(fh)
        return {}

    def _write_manifest(self, man: dict) -> None:
        os.makedirs(self.root, exist_ok=True)
        path = os.path.join(self.root, "manifest.json")
        with open(path + ".tmp", "w") as fh:
            json.dump(man, fh, indent=1)
        os.replace(path + ".tmp", path)


def _residual_summary(cam_r, proj_r, arms: dict) -> dict:
    """What a lab can know without a truth: each procedure's residuals."""
    return {"camera": {"rms_px": cam_r.rms_px, "residual_mm": cam_r.residual_mm, "views": cam_r.n_views},
            "projector": {"reprojection_px": proj_r.reprojection_px, "poses": proj_r.n_poses,
                          "points": proj_r.n_inliers},
            "arms": {s: {"residual_mm": r.residual_mm, "configs": r.n_configs} for s, (_, r) in arms.items()}}


def register_live(launch: str, out: str, opts: Options, truth_seed: int | None = None,
                  host: str | None = None,
             settle_s: float = 0.3, ask=None) -> dict:
    """Drive the registration through the running graph of ``launch`` (module doc); write ``out/display.yaml``
    and ``out/summary.json`` (the keys of ``calibrate display --sim``; errors against the truth only when the
    camera is the twin). ``truth_seed``: must be the camera twin's (a check). Returns the summary. Raises
    :class:`LiveError` (one line) when a step cannot go on; captured frames stay for the next run."""
    import time
    from dataclasses import asdict

    t_all = time.monotonic()
    os.makedirs(out, exist_ok=True)
    client = GraphClient(launch, host)
    try:
        roles = roles_of(client.lf)
        if host is not None and roles.hosts.get(roles.renderer) != host:
            raise LiveError(f"the renderer runs on host {roles.hosts.get(roles.renderer)!r}, not {host!r}: "
                            "it reads the pattern files, so run this on the renderer's host")
        try:
            kind = client.call(roles.camera, "param/get", {"name": "source"}, timeout=10.0)
            twin_spec = client.call(roles.camera, "param/get", {"name": "twin"}) if kind == "sim" else None
        except (TimeoutError, ServiceError) as exc:
            raise LiveError(f"the graph of {launch} is not running (start it with flexsheet launch): "
                            f"{exc}") from None
        truth = None
        if twin_spec is not None:
            if truth_seed is not None and int(twin_spec["truth_seed"]) != int(truth_seed):
                raise LiveError(f"--truth-seed {truth_seed} but the camera twin renders truth seed "
                                f"{twin_spec['truth_seed']} (launch it with --set "
                                f"twin.truth_seed={truth_seed})")
            truth = TwinTruth.draw(int(twin_spec["truth_seed"]), twin_spec["realism"])
        elif truth_seed is not None:
            raise LiveError("--truth-seed scores against the camera twin's truth, but the camera's source "
                            f"is {kind!r}")
        src = LiveSource(client, roles, out, opts, twin=truth is not None, settle_s=settle_s,
                         ask=ask)
        try:
            src.begin()
            reg = run_all(src, opts)
        except (ServiceError, TimeoutError) as exc:
            raise LiveError(str(exc)) from None
        finally:
            src.finish()
        write_display_calib(os.path.join(out, "display.yaml"), reg.calib)
        summary: dict = {"mode": "live", "launch": launch, "options": asdict(opts)}
        if truth is not None:
            summary.update(seed=truth.seed, realism=truth.realism)
            summary.update(score_registration(truth, reg.camera_entry, reg.camera, reg.projector_entry,
                                              reg.projector, reg.arms))
            summary["verdicts"] = verdicts(summary)
        else:
            summary.update(_residual_summary(reg.camera, reg.projector, reg.arms))
        summary["timings"] = {**reg.timings, "total_s": time.monotonic() - t_all}
        with open(os.path.join(out, "summary.json"), "w") as fh:
            json.dump(summary, fh, indent=1)
        return summary
    finally:
        client.close()
