"""``flexsheet experiment correction``: the paper's Figs. 11 and 13 measured on the honest twin.

The renderer corrects with **calibrated values only** and the twin's measurement camera photographs where that
light lands on the **true** sheet, lit by the **true** projector (issue 15):

* *Estimator side* (:class:`DisplayEstimator`, built from :class:`CalibratedDisplay` — ``display.yaml`` of the
  registration procedures run in the twin, :func:`flexsheet.twin.registration.sim_display_calib`): the
  bridges' IK/FK at the calibrated arm bases (nominal URDF), the renderer's sheet
  (:class:`flexsheet.rendering.state.RendererState` from those clamp poses and the tracked fingertip), its model
  choice (:class:`flexsheet.rendering.state.ErrorTable`, ``auto``) and its drawing through the calibrated projector
  (K_p, distortion, pose) for the calibrated eye (:class:`flexsheet.rendering.stereo_renderer.StereoRenderer`).
* *Twin side* (:class:`TwinWorld`, built from :class:`flexsheet.twin.truth.TwinTruth`): the true clamp poses
  (true forward kinematics of the commanded joints: true bases, link lengths, joint zeros), the true pushed
  shape (the nonlinear membrane FEM of :mod:`flexsheet.model.sheet_fem` with the truth's E, pre-strain and
  tension ratio), the true projector (K, distortion, pose). Only the measurement uses it.
* *Commanded inputs* (known to both): the sheet pose the planner commands (inclined tangent plane at θ, or
  the home pose), the clamp stretch, and the finger's position (the scripted finger of the world, tracked
  perfectly: fingertip tracking error is not part of this experiment).

Sizes (h, u, d on the inclined sheet; h, w on the pushed sheet) are measured on the imaginary screen from the
eye (:mod:`flexsheet.experiments.measurement`) and compared with the proper image (the object's perspective
image on the imaginary screen, paper §VI). ``corrected_mm`` is the mean absolute size error of the model the
renderer picks (``auto``); every model's error is reported beside it.

Stability (``--stability``, "test stability where methods fail"): the pushed error against the size of the
tension-ratio error (true β / assumed β), and both figures' errors against a scaled projector calibration
error; the breaking point is where the corrected error passes one projector pixel (0.7 mm).

Writes DIR/summary.json, DIR/fig11_inclined.png, DIR/fig13_pushed.png, DIR/photos.png and, with
``--stability``, DIR/stability.png + DIR/stability.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from flexsheet.calibration.display_calib import DisplayCalib, load_display_calib, nominal_display_calib
from flexsheet.experiments.measurement import (
    MeasurementCamera,
    measure_edges,
    measure_sizes,
    projector_pixels,
)
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface, clamp_half_span, clamp_poses, frame_from_clamps
from flexsheet.twin.truth import TwinTruth

__all__ = ["main", "run", "inclined_pose", "CalibratedDisplay", "DisplayEstimator", "TwinWorld", "Measurer",
           "PIXEL", "STRETCH", "PAPER", "sweep_sheet", "sweep_projector", "breaking_point",
           "scaled_error", "mapping_error_px", "perturbed_projector"]

#: one projector pixel on the imaginary screen, m: the target (issue 15)
PIXEL = geometry.PIXEL_ON_SCREEN
#: clamp strain of both experiments: the planner's stretch for the default 30 N/m object
#: (``stretch_for_stiffness`` → 0.0388), rounded to the world's FEM table node (``FemSettings.stretch_step``)
STRETCH = 0.04
#: depths (m) of the true sheet's FEM table (centre contact; solved directly at Fig. 13's depths)
FEM_DEPTHS = (0.005, 0.010, 0.020, 0.030, 0.040, 0.050, 0.060)
#: contact positions of the true sheet's table: the centre only (the true contact is within a few mm of it; the
#: table's remapping moves the solution there, :class:`flexsheet.model.sheet_fem.IndentTable`)
FEM_POSITIONS = (0.0,)

PAPER = {
    "inclined": {"50": {"uncorrected_mm": 27.5, "corrected_mm": 2.1},
                 "max_corrected_mm": {"h": 4.9, "u": 2.1, "d": 2.1},
                 "mean_corrected_mm": {"h": 2.5, "u": 1.1, "d": 1.1}},
    "pushed": {"50": {"uncorrected_mm": 15.8, "four_triangle_mm": 2.1},
               "max_corrected_mm": {"h": 4.2, "w": 2.8}, "mean_corrected_mm": {"h": 2.8, "w": 1.7}},
    "pixel_mm": 0.7,
}

ASSUMPTIONS = [
    "Inclined sheet = tangent plane of the cylinder at angle θ, tilted down (contact (−R+R cosθ, 0, −R sinθ), "
    "normal (cosθ, 0, −sinθ)); the planner commands it, the bridges solve the joints with the calibrated "
    "bases, the true arms put the sheet where the true kinematics of those joints say.",
    "Pushed sheet: the home pose; the finger is commanded to S behind the commanded sheet centre along its "
    "normal; the true depth and contact point follow from the true sheet plane; tracking is perfect.",
    f"Clamp stretch {STRETCH} in both (the planner's for the default 30 N/m object).",
    "Sizes on the imaginary screen seen from the eye: h at the centre column, u/d 10 % of h inside the "
    "top/bottom edges, w at the middle row; 0.5-crossings of the anti-aliased photograph. corrected_mm = mean "
    "absolute size error of the model the renderer picks; position_mm = shift of the image's centre.",
    "The measurement camera sits at the paper's fixed viewpoint V (geometry.EYE); the renderer draws for the "
    "eye of display.yaml.",
    "The drawn object is the rigid cylinder (the paper draws the FEM-deformed one; its outline barely moves).",
]

MODEL_LABELS = {"none": "uncorrected", "flat": "flat", "four_triangle": "four_triangle", "fine": "fine",
                "fem_nominal": "fem_nominal"}


def inclined_pose(theta_deg: float, direction: str = "down") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Commanded sheet pose (origin (3,) m, normal (3,), axis_u (3,)) = the cylinder's tangent plane at θ (deg),
    tilted ``direction`` ("down" or "up"). Raises ``ValueError`` for another direction or a non-finite θ."""
    if direction not in ("down", "up") or not math.isfinite(theta_deg):
        raise ValueError(f"need direction 'down'/'up' and a finite theta, got {direction!r}, {theta_deg!r}")
    R = geometry.CYLINDER_RADIUS
    sg = -1.0 if direction == "down" else 1.0
    th = math.radians(theta_deg)
    return (np.array([-R + R * math.cos(th), 0.0, sg * R * math.sin(th)]),
            np.array([math.cos(th), 0.0, sg * math.sin(th)]), np.array([0.0, 1.0, 0.0]))


HOME_POSE = (np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))


# ============================================================================ the estimator side (no truth)
@dataclass(frozen=True)
class CalibratedDisplay:
    """Everything the estimators may know about the display: ``projector`` (calibrated K_p and pose),
    ``distortion`` (5,) its OpenCV distortion, ``eye`` (3,) m V, ``ipd`` m, ``bases`` side → T_display_base
    (4, 4) of the calibrated arms, ``source`` (where it came from: a ``display.yaml`` path or ``nominal``)."""

    projector: Projector
    distortion: np.ndarray
    eye: np.ndarray
    ipd: float
    bases: dict
    source: str

    @classmethod
    def from_display_calib(cls, dc: DisplayCalib, source: str = "") -> CalibratedDisplay:
        """From a ``display.yaml`` (:class:`DisplayCalib`); raises ``ValueError`` naming missing entries."""
        if not isinstance(dc, DisplayCalib):
            raise TypeError(f"from_display_calib takes a DisplayCalib, got {type(dc).__name__}")
        dc.require("projector", "eye", "arms.left", "arms.right")
        p = dc.projector
        return cls(p.projector(), np.asarray(p.D, float).ravel().copy(), np.asarray(dc.eye.V, float).copy(),
                   float(dc.eye.ipd), {s: np.asarray(dc.arms[s].T_display_base, float).copy() for s in ("left", "right")},
                   source or dc.path or "display calibration")

    @classmethod
    def nominal(cls) -> CalibratedDisplay:
        """The nominal display (code constants; nothing measured)."""
        return cls.from_display_calib(nominal_display_calib(), "nominal")


class DisplayEstimator:
    """The display's estimators for one :class:`CalibratedDisplay` (and nothing else — by construction it takes
    no truth): the bridges' kinematics at the calibrated bases, the renderer's sheet, model choice and drawing.

    ``config``: the renderer's :class:`flexsheet.rendering.state.SheetConfig`; ``sheet_model``: the renderer's
    pushed-sheet model (:class:`flexsheet.model.sheet_model.NominalSheetModel`; None: the node's own,
    :func:`flexsheet.rendering.state.sheet_model_for` ``config``), the ``fem_nominal`` column;
    ``samples``: MSAA samples; ``target`` m: the ``auto`` model choice's accuracy target. Raises ``TypeError``
    if ``cal`` is not a :class:`CalibratedDisplay`.
    """

    def __init__(self, cal: CalibratedDisplay, config=None, *, sheet_model=None, samples: int = 4,
                 target: float = PIXEL) -> None:
        from flexsheet.arm.kinematics import ArmKinematics
        from flexsheet.rendering.state import ErrorTable, SheetConfig, sheet_model_for, silhouette_probes
        from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_mesh

        if not isinstance(cal, CalibratedDisplay):
            raise TypeError(f"DisplayEstimator takes a CalibratedDisplay, got {type(cal).__name__}")
        self.cal = cal
        self.config = config or SheetConfig()
        self.sheet_model = sheet_model if sheet_model is not None else sheet_model_for(self.config)
        self.target = float(target)
        self.kin = {s: ArmKinematics(s, cal.bases[s]) for s in ("left", "right")}
        self.renderer = StereoRenderer(cal.projector, distortion=cal.distortion, eye=cal.eye, ipd=cal.ipd,
                                       samples=samples, shading=False)
        v, f = cylinder_mesh()
        self.renderer.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], clamp_half_span(STRETCH))
        self.table = ErrorTable.build(silhouette_probes(v), eye=cal.eye, projector=cal.projector.position,
                                      screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL, sheet=home,
                                      sheet_model=self.sheet_model)

    def joints(self, origin, normal, axis_u, stretch: float = STRETCH) -> dict[str, np.ndarray]:
        """The bridges' joint commands (side → (6,) rad) for the commanded sheet pose: IK of the clamp poses
        (:func:`flexsheet.model.sheet.clamp_poses`) at the calibrated bases. Raises ``ValueError`` if an arm
        cannot reach it."""
        from flexsheet.arm.kinematics import home_joints

        Tl, Tr = clamp_poses(origin, normal, axis_u, stretch)
        out = {}
        for side, T in (("left", Tl), ("right", Tr)):
            q = home_joints(side)
            for _ in range(4):
                r = self.kin[side].ik(T, q, max_jump=3.0)
                q = r.q
                if r.ok:
                    break
            if not r.ok:
                raise ValueError(f"commanded sheet pose not reachable by the {side} arm ({r.status})")
            out[side] = q
        return out

    def clamps(self, q: dict) -> tuple[np.ndarray, np.ndarray]:
        """The bridges' clamp poses (FK of the measured joints at the calibrated bases), (left, right) (4, 4)."""
        return self.kin["left"].fk(q["left"]), self.kin["right"].fk(q["right"])

    def sheet(self, q: dict, finger=None, series: bool = False) -> SheetSurface:
        """The renderer's sheet (:meth:`flexsheet.rendering.state.RendererState.current_sheet`, the node's code path)
        from the bridges' clamp poses and the tracked fingertip ``finger`` (3,) m or None; when pushed, its
        membrane is the ``sheet_model``'s (``fem_nominal``). ``series``: instead the renderer's OLD pushed-sheet
        model, the 16-mode sine series (:class:`flexsheet.model.sheet.Membrane`, tension ratio 1), for the
        comparison column ``fine`` only; the renderer no longer uses it."""
        from flexsheet.rendering.state import RendererState

        Tl, Tr = self.clamps(q)
        if series:
            flat = SheetSurface.from_clamps(Tl, Tr, half_width=self.config.half_width)
            if finger is None or -float((np.asarray(finger, float) - flat.origin) @ flat.normal) <= \
                    self.config.push_threshold:
                return flat
            return SheetSurface.from_clamps(Tl, Tr, half_width=self.config.half_width,
                                            pushed_point=np.asarray(finger, float), membrane_kwargs={"modes": 16})
        st = RendererState(self.cal.eye, self.cal.projector.position, self.config, sheet_model=self.sheet_model)
        st.set_arm_pose("left", Tl)
        st.set_arm_pose("right", Tr)
        st.set_fingertip(None if finger is None else np.asarray(finger, float), 0.0)
        return st.current_sheet()

    def pick(self, sheet: SheetSurface) -> str:
        """The model the renderer's ``auto`` picks for ``sheet`` (:func:`flexsheet.rendering.state.pick_model`)."""
        from flexsheet.rendering.state import pick_model

        return pick_model("auto", sheet, self.table, self.target)

    def draw(self, model: str, sheet: SheetSurface) -> np.ndarray:
        """The projector image (H, W) float in [0, 1] drawn with ``model`` (one of
        :data:`flexsheet.rendering.correction.MODELS`; ``fine`` uses ``sheet``'s membrane) for the calibrated eye."""
        with self.renderer.ctx:           # another renderer's (standalone) context may be current
            self.renderer.set_model(model, None if model == "none" else sheet)
            return self.renderer.render_single(self.cal.eye)

    def release(self) -> None:
        self.renderer.release()


# ============================================================================ the twin side (truth only)
class TwinWorld:
    """The hidden truth's display, for the measurement only: the true projector (K, distortion, pose), the true
    clamp poses of commanded joints, the true sheet (flat, or pushed: the FEM table of
    :class:`flexsheet.model.sheet_fem.IndentTable` with the truth's material, cached in ``cache_dir``)."""

    def __init__(self, truth: TwinTruth, *, cache_dir: str | None = None, fem_mesh: dict | None = None,
                 depths=FEM_DEPTHS, positions=FEM_POSITIONS, stretch: float = STRETCH) -> None:
        from flexsheet.model.sheet_fem import default_cache_dir

        self.truth = truth
        T = np.asarray(truth.T_display_projector, float)
        w, h = truth.projector_size
        self.projector = Projector(np.asarray(truth.projector_K, float), T[:3, :3].copy(), T[:3, 3].copy(), int(w), int(h))
        self.distortion = np.asarray(truth.projector_D, float).ravel().copy()
        self.cache_dir = cache_dir or default_cache_dir()
        self.fem_mesh = dict(fem_mesh or {})
        self.depths, self.positions, self.stretch = tuple(depths), tuple(positions), float(stretch)
        self._table = None

    def table(self):
        """The true sheet's FEM table at the commanded stretch (built once, ~3 s per table, cached on disk)."""
        if self._table is None:
            from flexsheet.model.sheet_fem import IndentTable, SheetPhysics

            self._table = IndentTable(SheetPhysics.from_truth(self.truth, self.stretch), self.depths, self.positions,
                                      mesh=self.fem_mesh, cache_dir=self.cache_dir)
        return self._table

    def clamps(self, q: dict) -> tuple[np.ndarray, np.ndarray]:
        """True clamp poses (left, right) (4, 4) of the commanded joints."""
        return self.truth.clamp_pose("left", q["left"]), self.truth.clamp_pose("right", q["right"])

    def sheet(self, q: dict, finger=None) -> tuple[SheetSurface, dict]:
        """The true sheet held by the true clamps, pushed by the finger at ``finger`` (3,) m when it is behind
        the true sheet plane; returns (surface, info: true depth and contact, m)."""
        origin, n, eu, a = frame_from_clamps(*self.clamps(q))
        b = geometry.SHEET_SIZE / 2
        info = {"origin": origin, "normal": n}
        mem = None
        if finger is not None:
            d = np.asarray(finger, float) - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            info.update(depth=depth, push_u=pu, push_v=pv)
            if depth > 0.0:
                mem = self.table().shape(depth, pu, pv, a)
        return SheetSurface(origin, n, eu, a, b, mem), info


# ============================================================================ the live renderer's path, ray-traced
class LivePath:
    """The renderer node's pushed-sheet correction measured on the true sheet without GL (``live_path`` of the
    summary; ``tests/unit/rendering/test_render_live_sheet.py``).

    Renderer side, as ``RendererNode.setup`` builds it: the sheet model of
    :func:`flexsheet.rendering.state.sheet_model_for` ``config`` (or ``sheet_model``), a
    :class:`flexsheet.rendering.state.RendererState` fed both clamp poses (the home pose at ``stretch``) and the
    fingertip, the :class:`flexsheet.rendering.state.ErrorTable` and ``auto`` :func:`flexsheet.rendering.state.pick_model`,
    and the picked model's correction in numpy (the shader's twin, equal to 2e-6 m). Truth side: the twin's
    FEM sheet (:meth:`TwinWorld.table`, the truth's E, pre-strain and tension ratio) at the same clamps, lit
    along the projector's rays and traced by the measurement camera's bisection (:func:`trace_to_sheet` on a
    241×241 grid), not the renderer's Newton solver. Eye V and projector P are the same on both sides, so the
    error is the sheet model's alone: per probe (the object's silhouette points), the distance on the imaginary
    screen seen from the eye between where the light for A' lands and where the eye expects A."""

    def __init__(self, stretch: float = STRETCH, config=None, sheet_model=None, eye=geometry.EYE,
                 projector=geometry.PROJECTOR) -> None:
        from flexsheet.rendering.state import (
            ErrorTable,
            RendererState,
            SheetConfig,
            sheet_model_for,
            silhouette_probes,
        )
        from flexsheet.rendering.stereo_renderer import cylinder_mesh

        self.config = config or SheetConfig()
        self.eye, self.projector = np.asarray(eye, float), np.asarray(projector, float)
        self.stretch = float(stretch)
        model = sheet_model if sheet_model is not None else sheet_model_for(self.config)
        v, f = cylinder_mesh()
        self.probes = silhouette_probes(v)
        self.clamps = clamp_poses(*HOME_POSE, self.stretch)
        self.table = ErrorTable.at_home(self.probes, eye=self.eye, projector=self.projector,
                                        stretch_node=self.stretch, config=self.config,
                                        sheet_model=sheet_model if sheet_model is not None else sheet_model_for(self.config))
        self.state = RendererState(self.eye, self.projector, self.config, mesh=(v, f), sheet_model=model)
        self.state.set_arm_pose("left", self.clamps[0])
        self.state.set_arm_pose("right", self.clamps[1])

    def sheet(self, finger) -> tuple[SheetSurface, str]:
        """(the renderer's sheet, the model ``auto`` picks) for the fingertip ``finger`` (3,) m."""
        from flexsheet.rendering.state import pick_model

        self.state.set_fingertip(np.asarray(finger, float), 0.0)
        sheet, warn = self.state.sheet_for_frame()
        if warn:
            raise ValueError(warn)
        return sheet, pick_model("auto", sheet, self.table, PIXEL)

    def corrected(self, model: str, sheet: SheetSurface) -> np.ndarray:
        """A' (N, 3) m of the probes for ``model`` on ``sheet``."""
        from flexsheet.rendering.correction import (
            correct_vertices,
            correct_vertices_fine,
            correct_vertices_pushed,
        )

        c = dict(eye=self.eye, projector=self.projector, screen_point=geometry.SCREEN_POINT,
                 screen_normal=geometry.SCREEN_NORMAL)
        if model == "fine":
            return correct_vertices_fine(self.probes, sheet=sheet, **c)
        if model == "four_triangle":
            return correct_vertices_pushed(self.probes, pushed_point=sheet.pushed_point, corners=sheet.corners, **c)
        if model == "flat":
            return correct_vertices(self.probes, sheet_point=sheet.origin, sheet_normal=sheet.normal, **c)
        return self.probes.copy()

    def true_sheet(self, world: TwinWorld, finger) -> SheetSurface:
        """The twin's sheet at these clamps pushed by ``finger`` (3,) m (its FEM at the truth's material)."""
        origin, n, eu, a = frame_from_clamps(*self.clamps)
        d = np.asarray(finger, float) - origin
        depth, pu, pv = -float(d @ n), float(d @ eu), float(d @ np.cross(n, eu))
        mem = world.table().shape(depth, pu, pv, a) if depth > 0.0 else None
        return SheetSurface(origin, n, eu, a, geometry.SHEET_SIZE / 2, mem)

    def landing_error(self, a_hat, true: SheetSurface) -> np.ndarray:
        """Per probe, m: where the light for ``a_hat`` lands on ``true``, seen from the eye, against the probe."""
        from flexsheet.experiments.measurement import trace_to_sheet
        from flexsheet.rendering.correction import project_vertices

        scr = dict(eye=self.eye, screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL)
        b = project_vertices(a_hat, **scr)                            # where the projector aims (its pinhole)
        grid = true.membrane.grid(241) if true.membrane is not None else None
        c, hit = trace_to_sheet(self.projector, b - self.projector, true, grid)
        if not hit.all():
            raise ValueError(f"{int((~hit).sum())} projector rays miss the true sheet")
        return np.linalg.norm(project_vertices(c, **scr) - project_vertices(self.probes, **scr), axis=1)

    def measure(self, world: TwinWorld, depth: float) -> dict:
        """The live path at push ``depth`` m at the sheet centre: the picked model's max and mean landing error,
        and (for comparison only) the uncorrected image's and the old series model's, mm."""
        finger = HOME_POSE[0] - depth * HOME_POSE[1]
        sheet, model = self.sheet(finger)
        true = self.true_sheet(world, finger)
        err = self.landing_error(self.corrected(model, sheet), true)
        row = {"model": model, "max_mm": float(err.max() * 1e3), "mean_mm": float(err.mean() * 1e3),
               "terms": int(len(sheet.membrane.coef)) if sheet.membrane is not None else 0,
               "uncorrected_max_mm": float(self.landing_error(self.probes, true).max() * 1e3)}
        if depth > 0.0:
            old = SheetSurface.from_clamps(*self.clamps, half_width=self.config.half_width, pushed_point=finger,
                                           membrane_kwargs={"modes": 16})
            row["series_max_mm"] = float(self.landing_error(self.corrected("fine", old), true).max() * 1e3)
        return row


def live_path(truth: TwinTruth, depths_mm=(0, 10, 30, 50), progress=None) -> dict:
    """:class:`LivePath` rows for ``truth`` at each depth (mm), keyed by the depth."""
    lp, world = LivePath(), TwinWorld(truth)
    out = {}
    for d in depths_mm:
        out[f"{d:g}"] = r = lp.measure(world, d * 1e-3)
        if progress:
            progress(f"[correction] live path {d:g} mm: {r['model']} max {r['max_mm']:.2f} mm, mean "
                     f"{r['mean_mm']:.2f} mm (uncorrected max {r['uncorrected_max_mm']:.2f} mm)")
    return out


# ============================================================================ measurement
class Measurer:
    """The measurement camera (:class:`flexsheet.experiments.measurement.MeasurementCamera`) at the paper's
    viewpoint V, and the proper image's sizes (the cylinder's perspective image on the imaginary screen, drawn
    by a nominal pinhole projector onto the screen itself: no correction is involved, so any projector gives
    it up to pixel sampling). ``pixel`` m per camera pixel on the screen."""

    def __init__(self, pixel: float = 0.00035) -> None:
        from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_mesh

        self.cam = MeasurementCamera(pixel=pixel, extent=(0.26, 0.22))
        r = StereoRenderer(samples=4, shading=False)
        v, f = cylinder_mesh()
        r.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        with r.ctx:
            self.proper_photo = self.cam.photograph(r.render_single(geometry.EYE), r.projector, home)
        r.release()
        self.proper = self.sizes(self.proper_photo)
        self.proper_centre = self.centre(self.proper_photo)

    def sizes(self, photo) -> dict[str, float]:
        """Sizes (mm) of a photograph."""
        return {k: v * 1e3 for k, v in measure_sizes(photo, self.cam.pixel).items()}

    def centre(self, photo) -> np.ndarray:
        """Centre (mm, right/up on the screen) of the object's h and w spans."""
        e = measure_edges(photo, self.cam.pixel)
        return np.array([0.5 * (e["left"] + e["right"]), 0.5 * (e["top"] + e["bottom"])]) * 1e3

    def shoot(self, image, world: TwinWorld, true_sheet: SheetSurface) -> np.ndarray:
        """Photograph of the projector ``image`` lit by the true projector onto ``true_sheet``."""
        return self.cam.photograph(image, world.projector, true_sheet, distortion=world.distortion)

    def errors(self, photo, keys: str) -> dict:
        """{"mean_mm", "sizes_mm": {k: |size − proper|}, "position_mm"} of a photograph."""
        s = self.sizes(photo)
        d = {k: abs(s[k] - self.proper[k]) for k in keys}
        pos = float(np.linalg.norm(self.centre(photo) - self.proper_centre))
        return {"mean_mm": float(np.mean(list(d.values()))), "sizes_mm": d, "position_mm": pos}


# ============================================================================ the experiment
def _pose_dev(world_info: dict, est: SheetSurface) -> dict:
    dn = float(np.degrees(np.arccos(np.clip(world_info["normal"] @ est.normal, -1.0, 1.0))))
    return {"sheet_origin_error_mm": float(np.linalg.norm(world_info["origin"] - est.origin) * 1e3),
            "sheet_normal_error_deg": dn}


def measure_inclined(est: DisplayEstimator, world: TwinWorld, meas: Measurer, theta: float,
                     photos: dict | None = None, direction: str = "down") -> dict:
    """Fig. 11 at inclination ``theta`` deg: the uncorrected image and the picked model's, on the true sheet."""
    q = est.joints(*inclined_pose(theta, direction))
    sheet = est.sheet(q)
    true, info = world.sheet(q)
    picked = est.pick(sheet)
    row: dict = {"model": picked, **_pose_dev(info, sheet)}
    for name, model in (("uncorrected", "none"), ("corrected", picked)):
        ph = meas.shoot(est.draw(model, sheet), world, true)
        e = meas.errors(ph, "hud")
        row[f"{name}_mm"], row[f"{name}_sizes_mm"], row[f"{name}_position_mm"] = e["mean_mm"], e["sizes_mm"], e["position_mm"]
        if photos is not None:
            photos[f"inclined_{theta:g}_{name}"] = ph
    return row


def measure_pushed(est: DisplayEstimator, world: TwinWorld, meas: Measurer, depth_mm: float,
                   models=("none", "four_triangle", "fine"), photos: dict | None = None) -> dict:
    """Fig. 13 at push depth ``depth_mm``: each of ``models`` and the picked one, on the true (FEM) sheet."""
    origin, normal, axis_u = HOME_POSE
    q = est.joints(origin, normal, axis_u)
    finger = origin - depth_mm * 1e-3 * normal            # commanded, known to both sides
    sheet = est.sheet(q, finger)                          # the renderer's sheet (its shape model)
    sheets = {"fine": est.sheet(q, finger, series=True), "fem_nominal": sheet}
    true, info = world.sheet(q, finger)
    picked = est.pick(sheet)
    if picked == "fine":
        picked = "fem_nominal"
    row: dict = {"model": picked, "true_depth_mm": info["depth"] * 1e3,
                 "true_contact_mm": [info["push_u"] * 1e3, info["push_v"] * 1e3], **_pose_dev(info, sheet)}
    for model in dict.fromkeys((*models, picked)):
        gl = "fine" if model == "fem_nominal" else model
        ph = meas.shoot(est.draw(gl, sheets.get(model, sheet)), world, true)
        e = meas.errors(ph, "hw")
        lab = MODEL_LABELS[model]
        row[f"{lab}_mm"], row[f"{lab}_sizes_mm"], row[f"{lab}_position_mm"] = e["mean_mm"], e["sizes_mm"], e["position_mm"]
        if photos is not None:
            photos[f"pushed_{depth_mm:g}_{lab}"] = ph
    row["corrected_mm"] = row[f"{MODEL_LABELS[picked]}_mm"]
    row["corrected_sizes_mm"] = row[f"{MODEL_LABELS[picked]}_sizes_mm"]
    row["corrected_position_mm"] = row[f"{MODEL_LABELS[picked]}_position_mm"]
    return row


def display_calib_for(seed: int, realism: str, path: str | None = None, quick: bool = False,
                      progress=None) -> tuple[CalibratedDisplay, dict]:
    """The estimator's display for truth ``seed``: ``path`` (a display.yaml) if given, else the registration
    procedures run in the twin (:func:`flexsheet.twin.registration.sim_display_calib`, cached per seed;
    ``quick``: its quick preset). Returns (display, info with the path and, when known, the registration's own
    errors against the truth from its summary.json)."""
    if path is None:
        from flexsheet.twin.registration import sim_display_calib

        path = sim_display_calib(int(seed), realism, quick=quick, progress=progress)
    cal = CalibratedDisplay.from_display_calib(load_display_calib(path), path)
    info: dict = {"display_calib": path}
    sj = Path(path).with_name("summary.json")
    if sj.is_file():
        try:
            s = json.loads(sj.read_text())
            info["registration_errors"] = {k: s[k] for k in ("camera", "projector", "arms") if k in s}
        except (OSError, ValueError):
            pass
    return cal, info


def run(out: Path, truth_seed: int = 0, realism: str = "realistic", *, thetas=(10, 20, 30, 40, 50),
        depths=(10, 20, 30, 40, 50), display_calib: str | None = None, quick: bool = False,
        pixel: float = 0.00035, sheet_model: str = "auto", stability: bool = False, charts: bool = True,
        progress=print) -> dict:
    """Run the experiment for one truth and write ``out/summary.json`` (+ charts); returns the summary."""
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda _m: None)
    truth = TwinTruth.draw(int(truth_seed), realism)
    cal, cal_info = display_calib_for(truth_seed, realism, display_calib, quick, progress)
    model_obj = _sheet_model(sheet_model, quick=quick, progress=say)
    est = DisplayEstimator(cal, sheet_model=model_obj)
    world = TwinWorld(truth)
    meas = Measurer(pixel)
    photos: dict = {}
    s: dict = {"twin": {"realism": realism, "truth_seed": int(truth_seed),
                        "truth_sheet": {"young_Pa": truth.sheet_young, "prestrain": truth.sheet_prestrain,
                                        "tension_ratio": truth.tension_ratio}},
               "estimator": {"source": cal.source, **cal_info, "sheet_model": _model_info(model_obj)},
               "target_mm": PIXEL * 1e3, "proper_mm": meas.proper, "paper": PAPER, "assumptions": ASSUMPTIONS,
               "stretch": STRETCH, "quick": bool(quick), "measurement_pixel_mm": pixel * 1e3}
    s["inclined"] = {}
    for th in thetas:
        s["inclined"][f"{th:g}"] = r = measure_inclined(est, world, meas, th, photos)
        say(f"[correction] seed {truth_seed} {realism}: inclined {th:g}°: uncorrected {r['uncorrected_mm']:.2f} mm, "
            f"{r['model']} {r['corrected_mm']:.2f} mm")
    s["pushed"] = {}
    models = ("none", "four_triangle", "fine", "fem_nominal")
    for S in depths:
        s["pushed"][f"{S:g}"] = r = measure_pushed(est, world, meas, S, models, photos)
        say(f"[correction] seed {truth_seed} {realism}: pushed {S:g} mm: " + ", ".join(
            f"{MODEL_LABELS[m]} {r[MODEL_LABELS[m] + '_mm']:.2f}" for m in models) + f" mm; picked {r['model']}")
    s["live_path"] = {"note": "the renderer node's code path (RendererState, ErrorTable, auto) on the true FEM "
                              "sheet, ray-traced, same eye/projector both sides; max/mean over the silhouette, mm",
                      "rows": live_path(truth, (0, 10, 30, 50), say)}
    s["models_picked"] = {"inclined": sorted({r["model"] for r in s["inclined"].values()}),
                          "pushed": sorted({r["model"] for r in s["pushed"].values()})}
    s["choice_table_m"] = est.table.rows
    tmax, dmax = f"{max(thetas):g}", f"{max(depths):g}"
    s["headline"] = {"inclined_max_corrected_mm": max(r["corrected_mm"] for r in s["inclined"].values()),
                     "pushed_max_corrected_mm": max(r["corrected_mm"] for r in s["pushed"].values()),
                     f"inclined_{tmax}_corrected_mm": s["inclined"][tmax]["corrected_mm"],
                     f"pushed_{dmax}_corrected_mm": s["pushed"][dmax]["corrected_mm"]}
    s["headline"]["meets_target"] = {
        "inclined": s["headline"]["inclined_max_corrected_mm"] <= PIXEL * 1e3,
        "pushed": s["headline"]["pushed_max_corrected_mm"] <= PIXEL * 1e3}
    if stability:
        s["stability"] = stab = {
            "tension_ratio": sweep_sheet(est, truth, meas, "tension_ratio", progress=say, quick=quick),
            "prestrain": sweep_sheet(est, truth, meas, "prestrain", progress=say, quick=quick),
            "projector": sweep_projector(cal, truth, meas, sheet_model=model_obj, progress=say, quick=quick)}
        (out / "stability.json").write_text(json.dumps(stab, indent=1))
        if charts:
            _stability_chart(out / "stability.png", stab)
    est.release()
    s["elapsed_s"] = time.perf_counter() - t0
    (out / "summary.json").write_text(json.dumps(s, indent=1))
    if charts:
        _charts(out, s, thetas, depths, photos)
    return s


# ============================================================================ stability sweeps
#: true tension ratios (the estimator assumes β = 1; the truth's spread is log-normal 20 %)
TENSION_FACTORS = (0.3, 0.5, 0.7, 0.85, 1.0, 1.2, 1.4, 2.0, 3.0)
#: true pre-strains (the estimator assumes 0; the truth's spread is |N(0, 0.5 %)|)
PRESTRAINS = (0.0, 0.005, 0.01, 0.02, 0.04)
#: projector calibration error scales: × the registration's own error (direction "calibrated"), and × one
#: :data:`PROJECTOR_UNIT_ERROR` in random directions
PROJECTOR_SCALES = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0)
RANDOM_SCALES = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
#: one unit of random projector error: the registration target of issue 14 (2 mm, 0.2°) in a random direction,
#: with 0.5 px of principal point and 0.1 % of focal length (unlike a calibration's error, it is not constrained
#: by the reprojection of the calibration points, so it moves the image: 0.2° is ~5 px on the screen)
PROJECTOR_UNIT_ERROR = {"translation_mm": 2.0, "rotation_deg": 0.2, "principal_point_px": 0.5, "focal_rel": 0.001}
#: points where the induced mapping error is taken: the imaginary screen ±100 × ±80 mm and 50 mm behind it
_MAP_POINTS = np.array([[x, y, z] for x in (0.0, -0.05) for y in np.linspace(-0.1, 0.1, 9)
                        for z in np.linspace(-0.08, 0.08, 7)])


def breaking_point(xs, ys, limit: float):
    """Smallest x (linear interpolation) at which y first exceeds ``limit`` going along ``xs``; None if never."""
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        if y > limit:
            if i == 0:
                return float(x)
            x0, y0 = xs[i - 1], ys[i - 1]
            return float(x0 + (limit - y0) * (x - x0) / (y - y0))
    return None


def sweep_sheet(est: DisplayEstimator, truth: TwinTruth, meas: Measurer, kind: str, values=None,
                depth_mm: float = 50.0, quick: bool = False, progress=None) -> dict:
    """Pushed error (``depth_mm``) of every model against an error in the true sheet the estimator cannot see:
    ``kind`` ``tension_ratio`` — the true β = value × the estimator's assumed β (1.0); ``prestrain`` — the true
    pre-strain = value (the estimator assumes 0; the same as an error in the clamp strain it measures). The
    truth's other values are kept (one FEM table per value). The breaking point is where the renderer's
    picked model passes one projector pixel, going away from the assumption on each side."""
    if kind == "tension_ratio":
        values = values or ((0.5, 1.0, 2.0) if quick else TENSION_FACTORS)
        assumed = 1.0
    elif kind == "prestrain":
        values = values or ((0.0, 0.02) if quick else PRESTRAINS)
        assumed = 0.0
    else:
        raise ValueError(f"kind must be 'tension_ratio' or 'prestrain', got {kind!r}")
    models = ("none", "four_triangle", "fine", "fem_nominal")
    rows = []
    for x in values:
        t = dataclasses.replace(truth, **({"tension_ratio": float(x)} if kind == "tension_ratio"
                                          else {"sheet_prestrain": float(x)}))
        r = measure_pushed(est, TwinWorld(t), meas, depth_mm, models)
        rows.append({"value": float(x), **{MODEL_LABELS[m] + "_mm": r[MODEL_LABELS[m] + "_mm"] for m in models},
                     "picked": r["model"], "corrected_mm": r["corrected_mm"]})
        if progress:
            progress(f"[correction] stability: true {kind} {x:g}: picked {r['model']} {r['corrected_mm']:.2f} mm")
    lim = PIXEL * 1e3
    out: dict = {"kind": kind, "depth_mm": depth_mm, "assumed": assumed, "rows": rows, "criterion_mm": lim}
    for m in ("corrected", *[MODEL_LABELS[m] for m in models]):
        if kind == "tension_ratio":          # distance from the assumption as a factor, both ways
            up = sorted((r["value"], r[f"{m}_mm"]) for r in rows if r["value"] >= assumed)
            down = sorted((1.0 / r["value"], r[f"{m}_mm"]) for r in rows if r["value"] <= assumed)
            hi = breaking_point(*zip(*up, strict=True), lim) if up else None
            lo = breaking_point(*zip(*down, strict=True), lim) if down else None
            out[f"{m}_breaks_at"] = {"above": hi, "below": None if lo is None else 1.0 / lo}
        else:
            up = sorted((r["value"], r[f"{m}_mm"]) for r in rows)
            out[f"{m}_breaks_at"] = {"above": breaking_point(*zip(*up, strict=True), lim)}
    return out


def perturbed_projector(projector: Projector, scale: float, seed: int, direction: int = 0) -> Projector:
    """``projector`` moved by ``scale`` × :data:`PROJECTOR_UNIT_ERROR` in the random direction number
    ``direction`` of ``seed`` (translation, rotation axis, principal-point direction, sign of the focal error)."""
    rng = np.random.default_rng([int(seed), 4242, int(direction)])
    u = PROJECTOR_UNIT_ERROR
    dt = rng.normal(size=3)
    dt *= scale * u["translation_mm"] * 1e-3 / np.linalg.norm(dt)
    ax = rng.normal(size=3)
    ax *= scale * math.radians(u["rotation_deg"]) / np.linalg.norm(ax)
    dc = rng.normal(size=2)
    dc *= scale * u["principal_point_px"] / np.linalg.norm(dc)
    sf = 1.0 if rng.random() < 0.5 else -1.0
    K = np.asarray(projector.K, float).copy()
    K[0, 0] *= 1.0 + sf * scale * u["focal_rel"]
    K[1, 1] *= 1.0 + sf * scale * u["focal_rel"]
    K[:2, 2] += dc
    R = cv2.Rodrigues(ax)[0] @ np.asarray(projector.R, float)
    return Projector(K, R, np.asarray(projector.position, float) + dt, projector.width, projector.height)


def scaled_error(true: Projector, true_D, est: Projector, est_D, scale: float) -> tuple[Projector, np.ndarray]:
    """The projector whose error against ``true`` is ``scale`` × the error of ``est`` (K, D and centre
    linearly; the rotation along the geodesic, exp(s·log(R_est R_trueᵀ)) R_true)."""
    K = true.K + scale * (est.K - true.K)
    D = np.asarray(true_D, float) + scale * (np.asarray(est_D, float) - np.asarray(true_D, float))
    w = cv2.Rodrigues(np.asarray(est.R, float) @ np.asarray(true.R, float).T)[0]
    R = cv2.Rodrigues(scale * w)[0] @ np.asarray(true.R, float)
    P = np.asarray(true.position, float) + scale * (np.asarray(est.position, float) - np.asarray(true.position, float))
    return Projector(K, R, P, true.width, true.height), D


def mapping_error_px(true: Projector, true_D, est: Projector, est_D) -> float:
    """RMS distance (projector px) between the pixels the two projectors give the points of the imaginary
    screen (±100 × ±80 mm) and of a plane 50 mm behind it: how far the renderer's screen → pixel map is off."""
    a, _ = projector_pixels(_MAP_POINTS, true, true_D)
    b, _ = projector_pixels(_MAP_POINTS, est, est_D)
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def sweep_projector(cal: CalibratedDisplay, truth: TwinTruth, meas: Measurer, scales=PROJECTOR_SCALES,
                    random_scales=RANDOM_SCALES, theta: float = 50.0, depth_mm: float = 50.0, directions: int = 2,
                    sheet_model=None, quick: bool = False, progress=None) -> dict:
    """Both figures' corrected errors against a scaled projector calibration error (a sensitivity study: these
    estimator inputs are built from the truth on purpose). Two families, eye and arm bases kept calibrated:

    * ``calibrated``: the registration's own error (``cal`` − truth: K, D, pose) × each of ``scales`` (1 = the
      ``display.yaml`` as registered, 0 = perfect);
    * ``random``: the true projector moved by each of ``random_scales`` × :data:`PROJECTOR_UNIT_ERROR` in
      ``directions`` random directions (the worst direction is kept).

    Each row also gives the induced screen → pixel mapping error (:func:`mapping_error_px`), the common x-axis
    of both families; the breaking point is where the corrected error passes one projector pixel."""
    world = TwinWorld(truth)
    if quick:
        scales, random_scales, directions = (0.0, 1.0, 30.0), (1.0,), 1

    def measure(p, D, label):
        c = dataclasses.replace(cal, projector=p, distortion=np.asarray(D, float).copy(), source=label)
        est = DisplayEstimator(c, sheet_model=sheet_model)
        ri = measure_inclined(est, world, meas, theta)
        rp = measure_pushed(est, world, meas, depth_mm, ())
        est.release()
        return {"mapping_px": mapping_error_px(world.projector, world.distortion, p, D),
                "inclined_corrected_mm": ri["corrected_mm"], "inclined_position_mm": ri["corrected_position_mm"],
                "pushed_corrected_mm": rp["corrected_mm"], "pushed_model": rp["model"]}

    fam: dict = {"calibrated": [], "random": []}
    for k in scales:
        p, D = scaled_error(world.projector, world.distortion, cal.projector, cal.distortion, k)
        fam["calibrated"].append({"scale": float(k), **measure(p, D, f"truth + {k:g} × registration error")})
        if progress:
            r = fam["calibrated"][-1]
            progress(f"[correction] stability: registration error × {k:g} ({r['mapping_px']:.2f} px): inclined "
                     f"{r['inclined_corrected_mm']:.2f} mm, pushed {r['pushed_corrected_mm']:.2f} mm")
    for k in random_scales:
        acc = [measure(*(perturbed_projector(world.projector, k, truth.seed, d), world.distortion),
                       f"truth + {k:g} × unit (direction {d})") for d in range(directions)]
        worst = max(acc, key=lambda r: r["inclined_corrected_mm"])
        fam["random"].append({"scale": float(k), **worst, "directions": len(acc),
                              "mapping_px_all": [r["mapping_px"] for r in acc],
                              "inclined_corrected_all_mm": [r["inclined_corrected_mm"] for r in acc],
                              "pushed_corrected_all_mm": [r["pushed_corrected_mm"] for r in acc]})
        if progress:
            progress(f"[correction] stability: random projector error × {k:g}: worst inclined "
                     f"{worst['inclined_corrected_mm']:.2f} mm at {worst['mapping_px']:.2f} px")
    lim = PIXEL * 1e3
    out: dict = {"unit": PROJECTOR_UNIT_ERROR, "theta_deg": theta, "depth_mm": depth_mm, "criterion_mm": lim,
                 "directions": directions, **fam}
    for name, rows in fam.items():
        rows_px = sorted(rows, key=lambda r: r["mapping_px"])
        for fig in ("inclined", "pushed"):
            ys = [r[f"{fig}_corrected_mm"] for r in rows]
            out[f"{name}_{fig}_breaks_at_scale"] = breaking_point([r["scale"] for r in rows], ys, lim)
            out[f"{name}_{fig}_breaks_at_px"] = breaking_point([r["mapping_px"] for r in rows_px],
                                                               [r[f"{fig}_corrected_mm"] for r in rows_px], lim)
    return out


# ============================================================================ sheet model choice
def _sheet_model(name: str, quick: bool = False, progress=None):
    """The renderer's pushed-sheet model (``auto``/``fem``: the nominal FEM fit, the node's
    :func:`flexsheet.rendering.state.sheet_model_for`); ``quick``: its table for centre contacts only (the experiment
    pushes at the centre; the node uses the full table)."""
    if name not in ("auto", "fem"):
        raise ValueError(f"sheet model must be 'auto' or 'fem', got {name!r}")
    from flexsheet.model.sheet_model import NominalSheetModel

    kw = {"positions": (0.0,)} if quick else {}
    return NominalSheetModel.nominal(stretch=STRETCH, progress=progress, **kw)


def _model_info(model) -> dict:
    return model.describe()


# ============================================================================ charts
def _charts(out: Path, s: dict, thetas, depths, photos) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tw = f"{s['twin']['realism']} twin, truth seed {s['twin']['truth_seed']}"
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for size, mk in (("h", "o"), ("u", "s"), ("d", "^")):
        ax.plot(thetas, [max(s["inclined"][f"{t:g}"]["uncorrected_sizes_mm"][size], 0.01) for t in thetas],
                "--" + mk, label=f"Δ{size} uncorrected")
        ax.plot(thetas, [max(s["inclined"][f"{t:g}"]["corrected_sizes_mm"][size], 0.01) for t in thetas],
                "-" + mk, label=f"Δ{size} corrected (picked model)")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [27.5], "k*", ms=12, label="paper θ=50° uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper θ=50° corrected mean")
    ax.set_xlabel("sheet inclination θ [deg]")
    ax.set_ylabel("absolute size error [mm]")
    ax.set_title(f"Fig. 11 on the {tw}", fontsize=9)
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig11_inclined.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    names = [n for n in ("uncorrected", "four_triangle", "fine", "fem_nominal") if f"{n}_mm" in s["pushed"][f"{depths[0]:g}"]]
    for name in names:
        ax.plot(depths, [max(s["pushed"][f"{d:g}"][f"{name}_mm"], 0.01) for d in depths],
                "--o" if name == "uncorrected" else "-o", label=f"{name} (mean of Δh, Δw)")
    ax.plot(depths, [max(s["pushed"][f"{d:g}"]["corrected_mm"], 0.01) for d in depths], "k-", lw=4, alpha=0.25,
            label="picked by the renderer")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [15.8], "k*", ms=12, label="paper S=50 uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper S=50 4-triangle mean")
    ax.set_xlabel("push depth S [mm]")
    ax.set_ylabel("mean absolute size error [mm]")
    ax.set_title(f"Fig. 13 on the {tw} (true sheet: FEM)", fontsize=9)
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig13_pushed.png", dpi=110)
    plt.close(fig)

    keys = [k for k in photos if k.startswith(("inclined_50", "pushed_50"))][:6]
    if keys:
        fig, axes = plt.subplots(1, len(keys), figsize=(3 * len(keys), 2.8))
        for a, k in zip(np.atleast_1d(axes), keys, strict=False):
            a.imshow(photos[k], cmap="gray", vmin=0, vmax=1)
            a.set_title(k, fontsize=8)
            a.axis("off")
        fig.tight_layout()
        fig.savefig(out / "photos.png", dpi=90)
        plt.close(fig)


def _fmt(x, unit: str = "", nd: int = 2) -> str:
    return "not within the sweep" if x is None else f"{x:.{nd}f}{unit}"


def _stability_chart(path: Path, stab: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, NullLocator, ScalarFormatter

    floor = 0.01
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.6))
    for a, key, xlabel in ((ax[0], "tension_ratio", "true tension ratio T_v/T_u (estimator assumes 1)"),
                           (ax[1], "prestrain", "true pre-strain (estimator assumes 0)")):
        t = stab[key]
        xs = [r["value"] for r in t["rows"]]
        for k in [k for k in t["rows"][0] if k.endswith("_mm") and k != "corrected_mm"]:
            a.plot(xs, [max(r[k], floor) for r in t["rows"]], "-o", label=k[:-3])
        a.plot(xs, [max(r["corrected_mm"], floor) for r in t["rows"]], "k-", lw=4, alpha=0.25,
               label="picked by the renderer")
        a.axhline(0.7, color="grey", lw=0.8, ls="--", label="1 projector pixel (0.7 mm)")
        b = t["corrected_breaks_at"]
        if key == "tension_ratio":
            a.set_xscale("log")
            a.xaxis.set_major_locator(FixedLocator([x for x in xs if x in (0.3, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0)] or xs))
            a.xaxis.set_minor_locator(NullLocator())
            a.xaxis.set_major_formatter(ScalarFormatter())
            title = f"wrong tension ratio: picked model > 0.7 mm below β = {_fmt(b['below'])}, above β = {_fmt(b['above'])}"
        else:
            title = f"wrong pre-strain: picked model > 0.7 mm above {_fmt(b['above'])}"
        a.set_title(title, fontsize=8)
        a.set_xlabel(xlabel, fontsize=8)
        a.set_ylabel(f"pushed S = {t['depth_mm']:g} mm: mean size error [mm]", fontsize=8)
        a.set_yscale("log")
        a.set_ylim(floor, 30)
        a.legend(fontsize=7)
    p = stab["projector"]
    for name, mk in (("calibrated", "o"), ("random", "^")):
        rows = sorted(p[name], key=lambda r: r["mapping_px"])
        xs = [max(r["mapping_px"], 1e-3) for r in rows]
        ax[2].plot(xs, [max(r["inclined_corrected_mm"], floor) for r in rows], "-" + mk,
                   label=f"inclined θ={p['theta_deg']:g}°, {name} error")
        ax[2].plot(xs, [max(r["pushed_corrected_mm"], floor) for r in rows], "--" + mk, mfc="none",
                   label=f"pushed S={p['depth_mm']:g} mm, {name} error")
    reg = [r for r in p["calibrated"] if r["scale"] == 1.0]
    if reg:
        ax[2].axvline(max(reg[0]["mapping_px"], 1e-3), color="green", lw=0.8, ls=":", label="as registered")
    ax[2].axhline(0.7, color="grey", lw=0.8, ls="--", label="1 projector pixel (0.7 mm)")
    ax[2].set_xscale("log")
    ax[2].set_yscale("log")
    ax[2].set_ylim(floor, 30)
    ax[2].set_xlabel("projector screen→pixel mapping error, RMS [projector px] (0.001 = exact)", fontsize=8)
    ax[2].set_ylabel("mean size error [mm]", fontsize=8)
    ax[2].set_title(f"projector error: inclined > 0.7 mm from {_fmt(p['calibrated_inclined_breaks_at_px'], ' px')}\n"
                    f"(registration error scaled), {_fmt(p['random_inclined_breaks_at_px'], ' px')} (random directions)",
                    fontsize=8)
    ax[2].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def model_speed(sheet_model=None, repeats: int = 10) -> dict:
    """Median ms per 2×1024×768 stereo pair (shaded, no MSAA, as the node draws) per model on the nominal
    projector: none, flat, four_triangle, fine (16-mode series) and, with ``sheet_model``, fine with its
    64-term nominal FEM fit; plus the GL renderer's name."""
    from flexsheet.benches.render import time_models
    from flexsheet.model.sheet import Membrane
    from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_mesh

    a = clamp_half_span(STRETCH)
    home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], a)
    tilt = SheetSurface(*inclined_pose(30))
    series = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], a,
                          membrane=Membrane(a, 0.12, 0.0, 0.0, 0.03, modes=16))
    rt = StereoRenderer()
    v, f = cylinder_mesh()
    rt.set_mesh(v, f)
    t = time_models(rt, repeats, sheets={"none": home, "flat": tilt, "four_triangle": series, "fine": series})
    out = {m: d["median_ms"] for m, d in t.items()}
    if sheet_model is not None:
        fem = sheet_model.surface(series)
        out["fem_nominal"] = time_models(rt, repeats, models=("fine",), sheets={"fine": fem})["fine"]["median_ms"]
    out["gl_renderer"] = rt.ctx.info.get("GL_RENDERER", "?")
    rt.release()
    return out


def aggregate(out: Path, runs: dict, speed: dict | None = None) -> dict:
    """``out/seeds.json`` + ``out/seeds.png``: the headline numbers of each (realism, seed) run side by side."""
    doc: dict = {"target_mm": PIXEL * 1e3, "runs": {}}
    for key, s in runs.items():
        doc["runs"][key] = {
            "realism": s["twin"]["realism"], "truth_seed": s["twin"]["truth_seed"],
            "truth_sheet": s["twin"]["truth_sheet"],
            "registration_errors": s["estimator"].get("registration_errors"),
            "inclined": {k: {f: r[f] for f in ("uncorrected_mm", "corrected_mm", "corrected_position_mm", "model")}
                         for k, r in s["inclined"].items()},
            "pushed": {k: {f: r[f] for f in r if f.endswith("_mm") and not f.endswith(("sizes_mm", "contact_mm"))}
                       | {"model": r["model"]} for k, r in s["pushed"].items()},
            "headline": s["headline"]}
    if speed:
        doc["stereo_pair_ms"] = speed
    (out / "seeds.json").write_text(json.dumps(doc, indent=1))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    for key, s in runs.items():
        ls = "-" if s["twin"]["realism"] == "realistic" else ":"
        th = [float(k) for k in s["inclined"]]
        ax[0].plot(th, [max(r["corrected_mm"], 0.01) for r in s["inclined"].values()], ls + "o",
                   label=f"{key} corrected")
        ds = [float(k) for k in s["pushed"]]
        ax[1].plot(ds, [max(r["corrected_mm"], 0.01) for r in s["pushed"].values()], ls + "o",
                   label=f"{key} picked model")
        if "fine_mm" in next(iter(s["pushed"].values())):
            ax[1].plot(ds, [r["fine_mm"] for r in s["pushed"].values()], ls + "x", alpha=0.5,
                       label=f"{key} series fine (old)")
    for a, t in ((ax[0], "Fig. 11: inclined sheet, flat correction"), (ax[1], "Fig. 13: pushed sheet")):
        a.axhline(0.7, color="grey", lw=0.8, ls="--", label="target: 1 projector pixel")
        a.set_yscale("log")
        a.set_ylim(0.01, 10)
        a.set_title(t + " (solid: realistic twin, dotted: ideal)", fontsize=9)
        a.set_ylabel("mean absolute size error [mm]")
        a.legend(fontsize=6, ncol=2)
    ax[0].set_xlabel("θ [deg]")
    ax[1].set_xlabel("S [mm]")
    fig.tight_layout()
    fig.savefig(out / "seeds.png", dpi=110)
    plt.close(fig)
    if speed:
        _accuracy_vs_speed(out, runs, speed)
    return doc


def _accuracy_vs_speed(out: Path, runs: dict, speed: dict) -> None:
    """``accuracy_vs_speed.{json,png}``: each model's stereo-pair time against its error at the largest θ and S
    (mean over the realistic runs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    real = [s for s in runs.values() if s["twin"]["realism"] == "realistic"] or list(runs.values())
    tmax = max(real[0]["inclined"], key=float)
    dmax = max(real[0]["pushed"], key=float)

    def mean(f):
        return float(np.mean([f(s) for s in real]))

    pts = {"none": (mean(lambda s: s["inclined"][tmax]["uncorrected_mm"]), mean(lambda s: s["pushed"][dmax]["uncorrected_mm"])),
           "flat": (mean(lambda s: s["inclined"][tmax]["corrected_mm"]), mean(lambda s: s["pushed"][dmax]["uncorrected_mm"])),
           "four_triangle": (None, mean(lambda s: s["pushed"][dmax]["four_triangle_mm"])),
           "fine": (None, mean(lambda s: s["pushed"][dmax]["fine_mm"]))}
    if "fem_nominal" in speed and "fem_nominal_mm" in real[0]["pushed"][dmax]:
        pts["fem_nominal"] = (None, mean(lambda s: s["pushed"][dmax]["fem_nominal_mm"]))
    doc = {m: {"stereo_pair_ms": speed[m], f"inclined_{tmax}_error_mm": ei, f"pushed_{dmax}_error_mm": ep}
           for m, (ei, ep) in pts.items()}
    doc["gl_renderer"] = speed.get("gl_renderer", "?")
    doc["runs"] = sorted(k for k, s in runs.items() if s in real)
    (out / "accuracy_vs_speed.json").write_text(json.dumps(doc, indent=1))
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for m, (ei, ep) in pts.items():
        ax.plot(speed[m], max(ep, 0.01), "o", ms=9, label=f"{m}: pushed S={dmax} mm")
        if ei is not None:
            ax.plot(speed[m], max(ei, 0.01), "s", ms=6, mfc="none", label=f"{m}: inclined θ={tmax}°")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="target: 1 pixel (0.7 mm)")
    ax.axvline(1000 / 120, color="red", lw=0.8, ls=":", label="120 Hz budget (8.3 ms)")
    ax.set_xlabel(f"time per stereo pair, 2×1024×768 [ms] ({doc['gl_renderer'].split('(')[0].strip()})")
    ax.set_ylabel("mean absolute size error [mm], realistic twin")
    ax.set_yscale("log")
    ax.set_ylim(0.01, 50)
    ax.set_title("Correction models: accuracy against speed", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "accuracy_vs_speed.png", dpi=110)
    plt.close(fig)


# ============================================================================ CLI
def main(argv: list[str] | None = None) -> int:
    """Entry point of ``flexsheet experiment correction``; returns the exit code."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment correction", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  flexsheet experiment correction --twin realistic --truth-seed 0 --quick --out /tmp/corr\n"
               "  flexsheet experiment correction --twin both --seeds 0 1 2 --stability --speed "
               "--out docs/figures/renderer")
    ap.add_argument("--out", required=True, type=Path, help="output directory")
    ap.add_argument("--twin", choices=("realistic", "ideal", "both"), default="realistic",
                    help="the truth's realism (both: realistic and ideal columns)")
    ap.add_argument("--truth-seed", type=int, default=None, help="hidden truth seed (>= 0; default 0)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="several truth seeds: each run goes to OUT/<realism>-<seed>/, the table to OUT/seeds.json")
    ap.add_argument("--display-calib", default=None,
                    help="display.yaml for the estimators (default: run the registration in the twin, cached per seed)")
    ap.add_argument("--quick", action="store_true", help="θ = 10, 50°, S = 10, 50 mm, quick registration")
    ap.add_argument("--thetas", type=float, nargs="+", default=None, help="inclinations, deg (default 10..50)")
    ap.add_argument("--depths", type=float, nargs="+", default=None, help="push depths, mm (default 10..50)")
    ap.add_argument("--pixel", type=float, default=0.35, help="measurement camera pixel on the screen, mm")
    ap.add_argument("--sheet-model", choices=("auto", "fem"), default="auto",
                    help="renderer's pushed-sheet model (the nominal FEM fit; the old series model is the "
                         "comparison column 'fine')")
    ap.add_argument("--stability", action="store_true",
                    help="also sweep tension-ratio, pre-strain and projector errors (first realistic run)")
    ap.add_argument("--speed", action="store_true", help="time a stereo pair per model (OUT/seeds.json)")
    args = ap.parse_args(argv)
    seeds = args.seeds if args.seeds is not None else [0 if args.truth_seed is None else args.truth_seed]
    if args.seeds is not None and args.truth_seed is not None:
        ap.error("give --truth-seed or --seeds, not both")
    if any(x < 0 for x in seeds):
        ap.error("truth seeds must be >= 0")
    thetas = args.thetas or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    depths = args.depths or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    if any(not (0.0 <= t <= 60.0) for t in thetas) or any(not (0.0 < d <= 60.0) for d in depths):
        ap.error("--thetas must lie in [0, 60] deg and --depths in (0, 60] mm")
    realisms = ("realistic", "ideal") if args.twin == "both" else (args.twin,)
    single = len(seeds) == 1 and len(realisms) == 1
    if args.display_calib and not single:
        ap.error("--display-calib names one display: use it with one seed and one twin")
    t0 = time.perf_counter()
    runs, stab_done = {}, False
    for realism in realisms:
        for seed in seeds:
            out = args.out if single else args.out / f"{realism}-{seed}"
            stab = args.stability and realism == "realistic" and not stab_done
            head = single or (realism == realisms[0] and seed == seeds[0])
            s = run(out, seed, realism, thetas=thetas, depths=depths, display_calib=args.display_calib,
                    quick=args.quick, pixel=args.pixel * 1e-3, sheet_model=args.sheet_model, stability=stab,
                    charts=head or stab)
            stab_done |= stab
            if head and not single:                            # the headline run's charts go to OUT's top
                (args.out / "summary.json").write_bytes((out / "summary.json").read_bytes())
                names = ["fig11_inclined.png", "fig13_pushed.png", "photos.png"]
                for name in names + (["stability.json", "stability.png"] if stab else []):
                    (out / name).replace(args.out / name)
            runs[f"{realism}-{seed}"] = s
            h = s["headline"]
            print(f"{realism} seed {seed}: inclined max corrected {h['inclined_max_corrected_mm']:.2f} mm, pushed max "
                  f"corrected {h['pushed_max_corrected_mm']:.2f} mm (target {PIXEL * 1e3:.1f} mm); "
                  f"models {s['models_picked']}")
    if not single or args.speed:
        speed = model_speed(_sheet_model(args.sheet_model, args.quick)) if args.speed else None
        aggregate(args.out, runs, speed)
        if speed:
            print("stereo pair ms:", {k: (round(v, 2) if isinstance(v, float) else v) for k, v in speed.items()})
    print(f"wrote {args.out} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
