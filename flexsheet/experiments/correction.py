"""``flexsheet experiment correction``: the paper's Figs. 11 and 13 measured on the honest twin.

The renderer corrects with **calibrated values only** and the twin's measurement camera photographs where that
light lands on the **true** sheet, lit by the **true** projector (issue 15):

* *Estimator side* (:class:`DisplayEstimator`, built from :class:`CalibratedDisplay` — ``display.yaml`` of the
  registration procedures run in the twin, :func:`flexsheet.calibration.procedures.sim_display_calib`): the
  bridges' IK/FK at the calibrated arm bases (nominal URDF), the renderer's sheet
  (:class:`nodes.renderer.state.RendererState` from those clamp poses and the tracked fingertip), its model
  choice (:class:`nodes.renderer.state.ErrorTable`, ``auto``) and its drawing through the calibrated projector
  (K_p, distortion, pose) for the calibrated eye (:class:`nodes.renderer.scene.StereoRenderer`).
* *Twin side* (:class:`TwinWorld`, built from :class:`flexsheet.model.truth.TwinTruth`): the true clamp poses
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
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from flexsheet.experiments.measurement import MeasurementCamera, measure_edges, measure_sizes
from flexsheet.model import scene
from flexsheet.model.display_calib import DisplayCalib, load_display_calib, nominal_display_calib
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface, clamp_half_span, clamp_poses, frame_from_clamps
from flexsheet.model.truth import TwinTruth

__all__ = ["main", "run", "inclined_pose", "CalibratedDisplay", "DisplayEstimator", "TwinWorld", "Measurer",
           "PIXEL", "STRETCH", "PAPER", "sweep_tension", "sweep_projector", "perturbed_projector"]

#: one projector pixel on the imaginary screen, m: the target (issue 15)
PIXEL = scene.PIXEL_ON_SCREEN
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
    "The measurement camera sits at the paper's fixed viewpoint V (scene.EYE); the renderer draws for the "
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
    R = scene.CYLINDER_RADIUS
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

    ``config``: the renderer's :class:`nodes.renderer.state.SheetConfig`; ``sheet_model``: optional pushed-sheet
    model for the ``fem_nominal`` correction (:class:`nodes.renderer.sheet_model.NominalSheetModel`);
    ``samples``: MSAA samples; ``target`` m: the ``auto`` model choice's accuracy target. Raises ``TypeError``
    if ``cal`` is not a :class:`CalibratedDisplay`.
    """

    def __init__(self, cal: CalibratedDisplay, config=None, *, sheet_model=None, samples: int = 4,
                 target: float = PIXEL) -> None:
        from flexsheet.model.kinematics import ArmKinematics
        from nodes.renderer.scene import StereoRenderer, cylinder_mesh
        from nodes.renderer.state import ErrorTable, SheetConfig, silhouette_probes

        if not isinstance(cal, CalibratedDisplay):
            raise TypeError(f"DisplayEstimator takes a CalibratedDisplay, got {type(cal).__name__}")
        self.cal = cal
        self.config = config or SheetConfig()
        self.sheet_model = sheet_model
        self.target = float(target)
        self.kin = {s: ArmKinematics(s, cal.bases[s]) for s in ("left", "right")}
        self.renderer = StereoRenderer(cal.projector, distortion=cal.distortion, eye=cal.eye, ipd=cal.ipd,
                                       samples=samples, shading=False)
        v, f = cylinder_mesh()
        self.renderer.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], clamp_half_span(STRETCH))
        self.table = ErrorTable.build(silhouette_probes(v), eye=cal.eye, projector=cal.projector.position,
                                      screen_point=scene.SCREEN_POINT, screen_normal=scene.SCREEN_NORMAL, sheet=home,
                                      sheet_model=sheet_model)

    def joints(self, origin, normal, axis_u, stretch: float = STRETCH) -> dict[str, np.ndarray]:
        """The bridges' joint commands (side → (6,) rad) for the commanded sheet pose: IK of the clamp poses
        (:func:`flexsheet.model.sheet.clamp_poses`) at the calibrated bases. Raises ``ValueError`` if an arm
        cannot reach it."""
        from flexsheet.model.kinematics import home_joints

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
        """The renderer's sheet (:meth:`nodes.renderer.state.RendererState.current_sheet`) from the bridges'
        clamp poses and the tracked fingertip ``finger`` (3,) m or None; when pushed, its membrane is the
        ``sheet_model``'s (``fem_nominal``), or with ``series`` (or no sheet model) the config's sine series."""
        from nodes.renderer.state import RendererState

        st = RendererState(self.cal.eye, self.cal.projector.position, self.config,
                           sheet_model=None if series else self.sheet_model)
        Tl, Tr = self.clamps(q)
        st.set_arm_pose("left", Tl)
        st.set_arm_pose("right", Tr)
        st.set_fingertip(None if finger is None else np.asarray(finger, float), 0.0)
        return st.current_sheet()

    def pick(self, sheet: SheetSurface) -> str:
        """The model the renderer's ``auto`` picks for ``sheet`` (:func:`nodes.renderer.state.pick_model`)."""
        from nodes.renderer.state import pick_model

        return pick_model("auto", sheet, self.table, self.target)

    def draw(self, model: str, sheet: SheetSurface) -> np.ndarray:
        """The projector image (H, W) float in [0, 1] drawn with ``model`` (one of
        :data:`nodes.renderer.correction.MODELS`; ``fine`` uses ``sheet``'s membrane) for the calibrated eye."""
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
        b = scene.SHEET_SIZE / 2
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


# ============================================================================ measurement
class Measurer:
    """The measurement camera (:class:`flexsheet.experiments.measurement.MeasurementCamera`) at the paper's
    viewpoint V, and the proper image's sizes (the cylinder's perspective image on the imaginary screen, drawn
    by a nominal pinhole projector onto the screen itself: no correction is involved, so any projector gives
    it up to pixel sampling). ``pixel`` m per camera pixel on the screen."""

    def __init__(self, pixel: float = 0.00035) -> None:
        from nodes.renderer.scene import StereoRenderer, cylinder_mesh

        self.cam = MeasurementCamera(pixel=pixel, extent=(0.26, 0.22))
        r = StereoRenderer(samples=4, shading=False)
        v, f = cylinder_mesh()
        r.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        with r.ctx:
            self.proper_photo = self.cam.photograph(r.render_single(scene.EYE), r.projector, home)
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
    if picked == "fine" and est.sheet_model is not None:
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
    procedures run in the twin (:func:`flexsheet.calibration.procedures.sim_display_calib`, cached per seed;
    ``quick``: its quick preset). Returns (display, info with the path and, when known, the registration's own
    errors against the truth from its summary.json)."""
    if path is None:
        from flexsheet.calibration.procedures import sim_display_calib

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
    models = ("none", "four_triangle", "fine") + (("fem_nominal",) if model_obj is not None else ())
    for S in depths:
        s["pushed"][f"{S:g}"] = r = measure_pushed(est, world, meas, S, models, photos)
        say(f"[correction] seed {truth_seed} {realism}: pushed {S:g} mm: " + ", ".join(
            f"{MODEL_LABELS[m]} {r[MODEL_LABELS[m] + '_mm']:.2f}" for m in models) + f" mm; picked {r['model']}")
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
            "tension_ratio": sweep_tension(est, truth, meas, progress=say, quick=quick),
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
#: tension-ratio factors (true β / the estimator's assumed β); quick: the ends
TENSION_FACTORS = (0.5, 0.7, 0.85, 1.0, 1.2, 1.4, 2.0)
#: projector calibration error scales (× :data:`PROJECTOR_UNIT_ERROR`)
PROJECTOR_SCALES = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
#: one unit of projector calibration error: the registration target of issue 14 (2 mm, 0.2°) in a fixed random
#: direction per seed, with 0.5 px of principal point and 0.1 % of focal length
PROJECTOR_UNIT_ERROR = {"translation_mm": 2.0, "rotation_deg": 0.2, "principal_point_px": 0.5, "focal_rel": 0.001}


def breaking_point(xs, ys, limit: float):
    """Smallest x (linear interpolation) at which y first exceeds ``limit`` going along ``xs``; None if never."""
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        if y > limit:
            if i == 0:
                return float(x)
            x0, y0 = xs[i - 1], ys[i - 1]
            return float(x0 + (limit - y0) * (x - x0) / (y - y0))
    return None


def sweep_tension(est: DisplayEstimator, truth: TwinTruth, meas: Measurer, factors=TENSION_FACTORS,
                  depth_mm: float = 50.0, quick: bool = False, progress=None) -> dict:
    """Pushed error (``depth_mm``) of every model against the true tension ratio β = factor × the estimator's
    assumed β (1.0): the truth's other values kept, its β replaced (one FEM table per factor)."""
    factors = (0.7, 1.0, 1.4) if quick else factors
    models = ("none", "four_triangle", "fine") + (("fem_nominal",) if est.sheet_model is not None else ())
    rows = []
    for f in factors:
        tw = TwinWorld(dataclasses.replace(truth, tension_ratio=float(f)))
        r = measure_pushed(est, tw, meas, depth_mm, models)
        rows.append({"factor": float(f), **{MODEL_LABELS[m] + "_mm": r[MODEL_LABELS[m] + "_mm"] for m in models},
                     "picked": r["model"], "corrected_mm": r["corrected_mm"]})
        if progress:
            progress(f"[correction] stability: true β = {f:g} × assumed: picked {r['model']} {r['corrected_mm']:.2f} mm")
    out: dict = {"depth_mm": depth_mm, "assumed_ratio": 1.0, "rows": rows, "criterion_mm": PIXEL * 1e3}
    for m in ("corrected", *[MODEL_LABELS[m] for m in models]):
        up = [(r["factor"], r[f"{m}_mm"]) for r in rows if r["factor"] >= 1.0]
        down = [(1.0 / r["factor"], r[f"{m}_mm"]) for r in rows if r["factor"] <= 1.0]
        hi = breaking_point(*zip(*sorted(up), strict=True), PIXEL * 1e3) if up else None
        lo = breaking_point(*zip(*sorted(down), strict=True), PIXEL * 1e3) if down else None
        out[f"{m}_breaks_at_factor"] = {"above": hi, "below": None if lo is None else 1.0 / lo}
    return out


def perturbed_projector(projector: Projector, scale: float, seed: int) -> Projector:
    """``projector`` moved by ``scale`` × :data:`PROJECTOR_UNIT_ERROR` in a fixed random direction per ``seed``
    (translation, rotation axis, principal-point direction; focal length up)."""
    rng = np.random.default_rng([int(seed), 4242])
    u = PROJECTOR_UNIT_ERROR
    dt = rng.normal(size=3)
    dt *= scale * u["translation_mm"] * 1e-3 / np.linalg.norm(dt)
    ax = rng.normal(size=3)
    ax *= scale * math.radians(u["rotation_deg"]) / np.linalg.norm(ax)
    dc = rng.normal(size=2)
    dc *= scale * u["principal_point_px"] / np.linalg.norm(dc)
    K = np.asarray(projector.K, float).copy()
    K[0, 0] *= 1.0 + scale * u["focal_rel"]
    K[1, 1] *= 1.0 + scale * u["focal_rel"]
    K[:2, 2] += dc
    R = cv2.Rodrigues(ax)[0] @ np.asarray(projector.R, float)
    return Projector(K, R, np.asarray(projector.position, float) + dt, projector.width, projector.height)


def sweep_projector(cal: CalibratedDisplay, truth: TwinTruth, meas: Measurer, scales=PROJECTOR_SCALES,
                    theta: float = 50.0, depth_mm: float = 50.0, sheet_model=None, quick: bool = False,
                    progress=None) -> dict:
    """Both figures' corrected errors when the renderer's projector is the TRUE one (incl. distortion) moved by
    ``scale`` × :data:`PROJECTOR_UNIT_ERROR` (a sensitivity study: this estimator input is built from the truth
    on purpose; scale 0 is a perfectly registered projector). Eye and arm bases stay the calibrated ones."""
    scales = (0.0, 4.0, 16.0) if quick else scales
    world = TwinWorld(truth)
    rows = []
    for k in scales:
        p = perturbed_projector(world.projector, k, truth.seed)
        c = dataclasses.replace(cal, projector=p, distortion=world.distortion.copy(), source=f"truth + {k:g} × unit")
        est = DisplayEstimator(c, sheet_model=sheet_model)
        ri = measure_inclined(est, world, meas, theta)
        rp = measure_pushed(est, world, meas, depth_mm, ())
        est.release()
        rows.append({"scale": float(k), "inclined_corrected_mm": ri["corrected_mm"],
                     "inclined_position_mm": ri["corrected_position_mm"], "pushed_corrected_mm": rp["corrected_mm"],
                     "pushed_model": rp["model"]})
        if progress:
            progress(f"[correction] stability: projector error × {k:g}: inclined {ri['corrected_mm']:.2f} mm, "
                     f"pushed {rp['corrected_mm']:.2f} mm")
    xs = [r["scale"] for r in rows]
    lim = PIXEL * 1e3
    return {"unit": PROJECTOR_UNIT_ERROR, "theta_deg": theta, "depth_mm": depth_mm, "rows": rows,
            "criterion_mm": lim,
            "inclined_breaks_at_scale": breaking_point(xs, [r["inclined_corrected_mm"] for r in rows], lim),
            "pushed_breaks_at_scale": breaking_point(xs, [r["pushed_corrected_mm"] for r in rows], lim)}


# ============================================================================ sheet model choice
def _sheet_model(name: str, quick: bool = False, progress=None):
    """The nominal pushed-sheet model for ``fem_nominal`` (``auto``/``fem``) or None (``series``); ``quick``:
    its table for centre contacts only (the experiment pushes at the centre; the node needs the full table)."""
    if name == "series":
        return None
    if name not in ("auto", "fem"):
        raise ValueError(f"sheet model must be 'auto', 'fem' or 'series', got {name!r}")
    try:
        from nodes.renderer.sheet_model import NominalSheetModel
    except ImportError:
        if name == "fem":
            raise
        return None
    kw = {"positions": (0.0,)} if quick else {}
    return NominalSheetModel.nominal(stretch=STRETCH, progress=progress, **kw)


def _model_info(model) -> dict:
    if model is None:
        return {"name": "series", "note": "renderer's fine model: sine-series membrane, tension ratio 1"}
    return model.describe()


# ============================================================================ charts
def _charts(out: Path, s: dict, thetas, depths, photos) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tw = f"{s['twin']['realism']} twin, truth seed {s['twin']['truth_seed']}"
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for size, mk in (("h", "o"), ("u", "s"), ("d", "^")):
        ax.plot(thetas, [s["inclined"][f"{t:g}"]["uncorrected_sizes_mm"][size] for t in thetas], "--" + mk,
                label=f"Δ{size} uncorrected")
        ax.plot(thetas, [s["inclined"][f"{t:g}"]["corrected_sizes_mm"][size] for t in thetas], "-" + mk,
                label=f"Δ{size} corrected (picked model)")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [27.5], "k*", ms=12, label="paper θ=50° uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper θ=50° corrected mean")
    ax.set_xlabel("sheet inclination θ [deg]")
    ax.set_ylabel("absolute size error [mm]")
    ax.set_title(f"Fig. 11 on the {tw}", fontsize=9)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig11_inclined.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    names = [n for n in ("uncorrected", "four_triangle", "fine", "fem_nominal") if f"{n}_mm" in s["pushed"][f"{depths[0]:g}"]]
    for name in names:
        ax.plot(depths, [s["pushed"][f"{d:g}"][f"{name}_mm"] for d in depths], "--o" if name == "uncorrected" else "-o",
                label=f"{name} (mean of Δh, Δw)")
    ax.plot(depths, [s["pushed"][f"{d:g}"]["corrected_mm"] for d in depths], "k-", lw=2.5, alpha=0.35,
            label="picked by the renderer")
    ax.axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel (0.7 mm)")
    ax.plot([50], [15.8], "k*", ms=12, label="paper S=50 uncorrected mean")
    ax.plot([50], [2.1], "r*", ms=12, label="paper S=50 4-triangle mean")
    ax.set_xlabel("push depth S [mm]")
    ax.set_ylabel("mean absolute size error [mm]")
    ax.set_title(f"Fig. 13 on the {tw} (true sheet: FEM)", fontsize=9)
    ax.set_yscale("symlog", linthresh=1.0)
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


def _stability_chart(path: Path, stab: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    t = stab["tension_ratio"]
    xs = [r["factor"] for r in t["rows"]]
    for k in [k for k in t["rows"][0] if k.endswith("_mm")]:
        ax[0].plot(xs, [r[k] for r in t["rows"]], "-o", label=k[:-3])
    ax[0].axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel")
    ax[0].set_xscale("log")
    ax[0].set_xlabel("true tension ratio / assumed (1.0)")
    ax[0].set_ylabel(f"pushed S = {t['depth_mm']:g} mm: mean size error [mm]")
    ax[0].set_title("wrong tension ratio", fontsize=9)
    ax[0].legend(fontsize=7)
    p = stab["projector"]
    xs = [r["scale"] for r in p["rows"]]
    ax[1].plot(xs, [r["inclined_corrected_mm"] for r in p["rows"]], "-o", label=f"inclined θ={p['theta_deg']:g}° size")
    ax[1].plot(xs, [r["inclined_position_mm"] for r in p["rows"]], "--s", label="inclined: image position")
    ax[1].plot(xs, [r["pushed_corrected_mm"] for r in p["rows"]], "-^", label=f"pushed S={p['depth_mm']:g} mm size")
    ax[1].axhline(0.7, color="grey", lw=0.8, ls=":", label="1 projector pixel")
    u = p["unit"]
    ax[1].set_xlabel(f"projector error scale (1 = {u['translation_mm']:g} mm, {u['rotation_deg']:g}°, "
                     f"{u['principal_point_px']:g} px, {u['focal_rel'] * 100:g} % f)", fontsize=8)
    ax[1].set_ylabel("mean size error / position error [mm]")
    ax[1].set_xscale("symlog", linthresh=0.5)
    ax[1].set_yscale("symlog", linthresh=1.0)
    ax[1].set_title("projector calibration error", fontsize=9)
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ============================================================================ CLI
def main(argv: list[str] | None = None) -> int:
    """Entry point of ``flexsheet experiment correction``; returns the exit code."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment correction", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: flexsheet experiment correction --twin realistic --truth-seed 0 --quick --out /tmp/corr")
    ap.add_argument("--out", required=True, type=Path, help="output directory")
    ap.add_argument("--twin", choices=("realistic", "ideal"), default="realistic", help="the truth's realism")
    ap.add_argument("--truth-seed", type=int, default=0, help="hidden truth seed (>= 0)")
    ap.add_argument("--display-calib", default=None,
                    help="display.yaml for the estimators (default: run the registration in the twin, cached)")
    ap.add_argument("--quick", action="store_true", help="θ = 10, 50°, S = 10, 50 mm, quick registration")
    ap.add_argument("--thetas", type=float, nargs="+", default=None, help="inclinations, deg (default 10..50)")
    ap.add_argument("--depths", type=float, nargs="+", default=None, help="push depths, mm (default 10..50)")
    ap.add_argument("--pixel", type=float, default=0.35, help="measurement camera pixel on the screen, mm")
    ap.add_argument("--sheet-model", choices=("auto", "fem", "series"), default="auto",
                    help="renderer's pushed-sheet model for the fine correction (auto: nominal FEM if available)")
    ap.add_argument("--stability", action="store_true", help="also sweep tension-ratio and projector errors")
    args = ap.parse_args(argv)
    if args.truth_seed < 0:
        ap.error("--truth-seed must be >= 0")
    thetas = args.thetas or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    depths = args.depths or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    if any(not (0.0 <= t <= 60.0) for t in thetas) or any(not (0.0 < d <= 60.0) for d in depths):
        ap.error("--thetas must lie in [0, 60] deg and --depths in (0, 60] mm")
    s = run(args.out, args.truth_seed, args.twin, thetas=thetas, depths=depths, display_calib=args.display_calib,
            quick=args.quick, pixel=args.pixel * 1e-3, sheet_model=args.sheet_model, stability=args.stability)
    h = s["headline"]
    print(f"inclined max corrected {h['inclined_max_corrected_mm']:.2f} mm, pushed max corrected "
          f"{h['pushed_max_corrected_mm']:.2f} mm (target {PIXEL * 1e3:.1f} mm); models {s['models_picked']}")
    print(f"wrote {args.out}/summary.json in {s['elapsed_s']:.0f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
