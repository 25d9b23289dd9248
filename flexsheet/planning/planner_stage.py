"""The planner node's work as one stage (pure; time is passed in): inputs in, a plan and both arms' command
out.

:class:`PlannerStage` holds the :class:`~flexsheet.planning.surface_planner.SurfacePlanner`, the viewer's
:class:`~flexsheet.planning.head_guard.HeadGuard`, what the FEM said of the object (its latched force–depth
table, or its fresh dF/dd and press), and the :class:`~flexsheet.planning.arm_command.ArmCommander`. The node
turns messages into its calls and its results into messages. Each call returns the lines to log with it.

Units: m, N, N/m, s; display frame.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from flexsheet.model.force_depth import ForceDepth
from flexsheet.model.scenes import Scene, is_paper_cylinder
from flexsheet.model.sheet import frame_from_clamps, sheet_rotation
from flexsheet.planning.arm_command import ACCEL_SCALE, SPEED_SCALE, ArmCommand, ArmCommander
from flexsheet.planning.arm_reach import ArmReach
from flexsheet.planning.compliance import SceneCompliance
from flexsheet.planning.head_guard import HeadGuard
from flexsheet.planning.keepout import KeepOut
from flexsheet.planning.plan import Hold, Plan
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.scene_scale import scale_depths, sheet_scene_scale
from flexsheet.planning.shape import planner_shape
from flexsheet.planning.surface_planner import SurfacePlanner

__all__ = ["PlannerStage", "StageConfig", "fem_solves_scene", "held_sheet", "HEAD_WORDS"]

#: the sheet model's source, by whether it was identified
IDENTIFIED = {True: "identified from presses (display_calib sheet)",
              False: "the nominal string band (no identified sheet in display_calib)"}
#: the viewer's head state in words (the planner's log)
HEAD_WORDS = {"tracking": "tracked: the sheet keeps out of its keep-out volume",
              "lost": "lost: holding the sheet until the glasses are seen again"}


def fem_solves_scene(scene_key: str, sc: Scene, key: str | None = None) -> bool:
    """Whether a FEM message with ``scene_key`` is about scene ``sc``: it equals ``sc.key()`` (or ``key``,
    precomputed); an empty key (a message from before the FEM read scenes) counts only when ``sc`` is the
    paper's cylinder, the only object that FEM solved."""
    if scene_key:
        return scene_key == (key if key is not None else sc.key())
    return is_paper_cylinder(sc)


def held_sheet(left_pose, right_pose, size: float) -> tuple | None:
    """(origin (3,) m, rotation (3, 3), strain) of the sheet of side ``size`` m held by the measured clamp
    poses (4, 4) (display frame), or None when they do not hold a sheet
    (:func:`flexsheet.model.sheet.frame_from_clamps`); a slack sheet reads strain 0."""
    try:
        o, n, u, a = frame_from_clamps(np.asarray(left_pose, float), np.asarray(right_pose, float))
    except ValueError:
        return None
    return o, sheet_rotation(n, u), max(2.0 * a / size - 1.0, 0.0)


@dataclass(frozen=True)
class StageConfig:
    """What the stage reads, built once from its node's params (the planner node's ``stage_config``).

    ``planner``: the :class:`PlannerConfig` (material and reach registered); ``bases``: {"left", "right"}:
    each arm's base as its bridge takes it ((4, 4) T_display_base registered, or (x, y, z, yaw)); None: the
    reach model's; ``sheet_identified``: the material carries terms identified from presses (display_calib);
    ``stiffness_from_scene``: the scene's compliance estimate, from ``min_contact_depth`` m; the head's
    keep-out ``head_radius`` + ``keepout_margin`` m; ``pull_margin`` (0, 1]; ``arm_speed_scale``,
    ``arm_accel_scale`` 1/s: the bridges' scales; ``use_fem_stiffness`` while fresher than ``fem_timeout`` s,
    the median over ``fem_window`` s; ``scale_given``: ``stiffness_scale`` was set (the scene's own scale is
    not fitted). Raises ``ValueError`` on a value out of range."""

    planner: PlannerConfig = field(default_factory=PlannerConfig)
    bases: dict | None = None
    sheet_identified: bool = False
    stiffness_from_scene: bool = True
    min_contact_depth: float = 5e-4
    head_radius: float = 0.10
    keepout_margin: float = 0.05
    pull_margin: float = 0.9
    arm_speed_scale: float = SPEED_SCALE
    arm_accel_scale: float = ACCEL_SCALE
    use_fem_stiffness: bool = True
    fem_timeout: float = 0.5
    fem_window: float = 0.0
    scale_given: bool = False

    def __post_init__(self) -> None:
        for name in ("min_contact_depth", "head_radius", "pull_margin", "arm_speed_scale", "arm_accel_scale",
                     "fem_timeout"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not (self.keepout_margin >= 0.0 and self.fem_window >= 0.0):
            raise ValueError(f"keepout_margin and fem_window must be >= 0, got {self.keepout_margin!r}, "
                             f"{self.fem_window!r}")

    def arm_bases(self) -> dict:
        """{"left", "right"}: :attr:`bases`, else the reach model's (x, y, z, yaw)."""
        r = self.planner.reach
        return self.bases if self.bases is not None else {"left": r.left_base, "right": r.right_base}


class PlannerStage:
    """The planner's state and decisions. ``scene``: the object; ``cfg``: the :class:`StageConfig` (a plain
    config built once from the node's params). Raises ``ValueError`` on an inconsistent config."""

    def __init__(self, scene: Scene, cfg: StageConfig) -> None:
        self.scene, self.cfg = scene, cfg
        shape = planner_shape(scene)
        compliance = (SceneCompliance(scene, shape, cfg.min_contact_depth) if cfg.stiffness_from_scene
                      else None)
        self.key = scene.key()
        pc = cfg.planner
        self.guard = HeadGuard(KeepOut(head_radius=cfg.head_radius, margin=cfg.keepout_margin),
                               pc.material.size)
        bases = cfg.arm_bases()                 # the arms' IK and joint rates: the bridges' own bases
        self.arm_reach = ArmReach(bases)
        self.planner = SurfacePlanner(shape, pc, compliance, self.guard, self.arm_reach)
        self.commander = ArmCommander(bases, pc.material, cfg.pull_margin, cfg.arm_speed_scale,
                                      cfg.arm_accel_scale, self.arm_reach)
        self.k_fem: float | None = None
        self._k_fem_at = 0.0
        self._press: tuple[float, float] | None = None
        self._k_hist: deque[tuple[float, float]] = deque(maxlen=256)
        self.fem_other_scene = 0
        self.scene_scale = None
        self._source = ""
        limit, self.first_line = self.commander.home_limit()
        self.planner.set_pull_limit(limit)

    def describe_sheet(self) -> str:
        """The sheet model in words: identified from presses (``display_calib``'s ``sheet`` entry) or
        nominal."""
        m = self.planner.cfg.material
        return (f"{IDENTIFIED[self.cfg.sheet_identified]} "
                f"(w {m.contact_width * 1e3:.1f} mm, growth {m.contact_growth:.2f}, own {m.own_stiffness:.3g}"
                f" N + {m.own_growth:.3g} N/m, stretching {m.stretching:.3g} N/m³, strain offset "
                f"{m.strain_offset:+.4f}, position {m.position_u:+.3f} along / {m.position_v:+.3f} across)")

    def set_force_depth(self, table: ForceDepth) -> str:
        """The object's force–depth from its FEM: the request from now on. Unless ``stiffness_scale`` was set,
        the scene's one scale (:func:`flexsheet.model.force_depth.scene_scale`) maps it between the sheet's
        force at its least stretch and at the arms' pull at the home pose. Returns the line to log (''
        none)."""
        cfg, line = self.planner.cfg, ""
        if not self.cfg.scale_given:
            stroke_depth = self.scene.use.stroke_depth
            sc = sheet_scene_scale(table, cfg.material, self.planner.max_stretch, stroke_depth,
                                   cfg.contrast_gain)
            self.planner.cfg = replace(cfg, stiffness_scale=sc.scale)
            self.scene_scale = sc
            d_lo, d_hi = scale_depths(stroke_depth)
            line = (f"object's force-depth from its FEM ({len(table.names)} points): one scale "
                    f"{sc.scale:.3g} for the scene (presentable from {sc.low:.3g} to {sc.high:.3g} over "
                    f"{d_lo * 1e3:.0f}-{d_hi * 1e3:.0f} mm; {'it fits' if sc.fits else 'it does NOT fit'}, "
                    f"{100 * sc.saturated:.0f} % of its samples saturate)")
        self.planner.set_force_depth(table)
        return line

    def set_fem(self, now: float, scene_key: str, stiffness: float, contact_force: float,
                depth: float) -> None:
        """The FEM's local stiffness N/m and press (force N at depth m) of a valid solution at ``now`` s, kept
        when positive and about this scene (:func:`fem_solves_scene`); with ``fem_window`` > 0 the median of
        the last ``fem_window`` s."""
        if not stiffness > 0.0:
            return
        if not fem_solves_scene(scene_key, self.scene, self.key):
            self.fem_other_scene += 1
            return
        self._k_hist.append((now, float(stiffness)))
        w = self.cfg.fem_window
        recent = [k for t, k in self._k_hist if now - t <= w] if w > 0 else [float(stiffness)]
        self.k_fem = float(np.median(recent))
        self._k_fem_at = now
        self._press = (float(contact_force), float(depth))

    def stiffness(self, now: float) -> tuple[float | None, str]:
        """(stiffness N/m, source): the FEM's while fresh ("fem"); ``None`` for the planner's compliance model
        ("scene"); else ``object_stiffness`` ("param")."""
        c = self.cfg
        if c.use_fem_stiffness and self.k_fem is not None and now - self._k_fem_at <= c.fem_timeout:
            return self.k_fem, "fem"
        if self.planner.compliance is None:
            return self.planner.cfg.object_stiffness, "param"
        return None, "scene"

    def plan(self, now: float, t: float | None, pos) -> tuple[Plan | None, str]:
        """The plan for a fingertip at ``pos`` (3,) m seen at ``t`` s (None: the marker is lost: hold), at
        ``now`` s; a lost head holds the pose while the stretch follows the push. Returns (plan or None when
        there is no safe pose yet, a line on a change of the stiffness' source or '')."""
        if t is None:
            return self.planner.hold(Hold.MARKER_LOST), ""
        k, source = self.stiffness(now)
        press = self._press if source == "fem" else None
        if self.guard.lost and not self.guard.near:
            plan = self.planner.hold_pose(Hold.HEAD_LOST, t, pos, k, now=now, object_press=press)
        else:
            plan = self.planner.update(t, pos, k, now=now, object_press=press)
        line = ""
        if plan is not None and not plan.status.startswith("hold"):
            line = self._note_source("table" if plan.k_source == "table" else source)
        return plan, line

    def command(self, plan: Plan, now: float, held: Callable[[float], tuple | None]) -> ArmCommand:
        """Both arms' command for ``plan`` (:meth:`ArmCommander.command`, under the planner's current
        limits). Call :meth:`cap_pull` once it is sent."""
        return self.commander.command(plan, now, self.planner.limiter.limits, held)

    def cap_pull(self) -> str:
        """Cap the next plans' pull at the arms' torque-limited pull at the last command's targets
        (:meth:`ArmCommander.cap_pull`); a line to log when the limit moved, else ''."""
        limit, said = self.commander.cap_pull()
        self.planner.set_pull_limit(limit)
        return said

    def _note_source(self, source: str) -> str:
        """The stiffness' source in words when it changed, else ''."""
        text = {"table": "the object's force-depth from its FEM (/object/force_depth)",
                "fem": "the FEM's dF/dd, and its force from 2 mm deep",
                "scene": "the scene's estimate at the contact (Hertz contact + inclusions, "
                         "flexsheet/planning/compliance.py)",
                "param": f"object_stiffness {self.planner.cfg.object_stiffness:g} N/m"}[source]
        if self.fem_other_scene and source != "fem":
            text += (f"; the FEM's stiffness is not used: it solves another object than scene "
                     f"{self.scene.name!r} ({self.fem_other_scene} messages so far)")
        cfg = self.planner.cfg
        if cfg.stiffness_scale != 1.0:
            text += (f"; x {cfg.stiffness_scale:.4g} (stiffness_scale"
                     + (", the scene's)" if self.scene_scale else ")"))
        if cfg.contrast_gain != 1.0:
            text += f"; contrast_gain {cfg.contrast_gain:g}"
        if text == self._source:
            return ""
        self._source = text
        return text
