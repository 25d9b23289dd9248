"""The renderer's state and decisions, pure (numpy; no GL, no transport): what the node draws and with which
model.

* :class:`RendererState` — the newest inputs (object mesh, both clamp poses, fingertip) and the sheet they
  give (:meth:`SheetSurface.from_clamps`, paper §III-C), validated when they arrive; the last good sheet is
  kept for frames whose inputs give an unusable sheet. Thread-safe (input handlers run in worker threads, the
  drawing in the GL thread).
* :class:`ErrorTable` — each correction model's predicted image error against the renderer's pushed-sheet
  model (the gripped sheet's FEM depth table, :mod:`flexsheet.model.sheet_model`) over a range of push depths
  (:func:`flexsheet.rendering.correction.predict_model_errors`), computed once its first table is available.
* :func:`sheet_model_for`, :class:`SheetConfig` — that pushed-sheet model and its settings
  (:mod:`flexsheet.model.sheet_model`, re-exported here), built the same way for the node, the Foxglove
  bridge, the experiment and the tests; :func:`build_table` builds a missing table in a worker process.
* :func:`pick_model` — the model for a sheet: the configured one, or with ``"auto"`` the cheapest whose
  predicted error meets the accuracy target (:func:`flexsheet.rendering.correction.choose_sheet_model`).
* :func:`load_geometry` — what the node draws and through which projector: the scene's object
  (:mod:`flexsheet.model.scenes`) and the registered projector and eye (``display.yaml``,
  :mod:`flexsheet.calibration.display_calib`; the nominal geometry when none is named, said so in the log).

Units: m, display frame. Errors: ``ValueError`` naming the input and value (the node turns it into a counted
rejection).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model import geometry
from flexsheet.model.checks import check_pose
from flexsheet.model.projector import Projector
from flexsheet.model.scenes import Scene, load_scene, paper_scene
from flexsheet.model.sheet import SheetSurface, clamp_half_span, clamp_poses
from flexsheet.model.sheet_model import (
    NominalSheetModel,
    PendingPush,
    SheetConfig,
    believed_sheet,
    sheet_model_for,
)
from flexsheet.rendering.correction import MODELS, choose_sheet_model, predict_model_errors
from flexsheet.rendering.stereo_renderer import cylinder_draw_mesh, scaled_projector, vertex_normals
from flexsheet.runtime.background import lower_priority

__all__ = ["RendererState", "ErrorTable", "pick_model", "check_sheet", "silhouette_probes", "AUTO_MODELS",
           "RenderGeometry", "load_geometry", "build_table"]

#: models "auto" chooses among (cheapest first); "none" is never chosen automatically
AUTO_MODELS = ("flat", "four_triangle", "fine")


def check_sheet(sheet: SheetSurface, eye, projector) -> None:
    """Raise ``ValueError`` unless the eye (3,) m is in front of ``sheet`` and the projector (3,) m behind
    it."""
    if (np.asarray(eye, dtype=float) - sheet.origin) @ sheet.normal <= 1e-6:
        raise ValueError(f"eye on the wrong side of the sheet (normal {sheet.normal.round(3).tolist()})")
    if (np.asarray(projector, dtype=float) - sheet.origin) @ sheet.normal >= -1e-6:
        raise ValueError("projector is not behind the sheet")


def silhouette_probes(vertices, step: int = 7, center_x: float | None = None) -> np.ndarray:
    """Object points that decide the image error: every ``step``-th vertex on the user's side of the object's
    centre (x > ``center_x``; default the vertices' mean x, which is the axis x = −R for the cylinder mesh),
    (K, 3) float64 m. Raises ``ValueError`` for an empty or non-(N, 3) array."""
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"vertices must be a non-empty (N, 3) array, got shape {v.shape}")
    cx = float(v[:, 0].mean()) if center_x is None else float(center_x)
    return v[v[:, 0] > cx + 1e-9][::step]


@dataclass(frozen=True)
class ErrorTable:
    """Predicted image error per model: ``rows[model]`` = [(push depth m, max error m on the screen), ...],
    depths ascending. Build with :meth:`build`; query with :meth:`choose`."""

    rows: dict

    @classmethod
    def build(cls, probes, *, eye, projector, screen_point, screen_normal, sheet: SheetSurface,
              sheet_model: NominalSheetModel, depths=np.linspace(0.0, 0.06, 13)) -> ErrorTable:
        """Predict each model's error at each depth (m) for ``probes`` (N, 3) m on the unpushed ``sheet``
        (:func:`predict_model_errors`, ~0.1 s per depth) against ``sheet_model``'s shape pushed at the centre
        (:class:`flexsheet.model.sheet_model.NominalSheetModel`; also the ``fine`` model's shape). Builds the
        table of ``sheet``'s stretch node if it is not cached (~30 s). Raises ``ValueError`` on bad
        geometry."""
        rows = {m: [] for m in MODELS}

        def ref(s, depth):
            return sheet_model.shape(s.half_span, depth, 0.0, 0.0, s.half_width)

        for S in np.asarray(depths, dtype=float):
            pe = predict_model_errors(float(S), eye=eye, projector=projector, screen_point=screen_point,
                                      screen_normal=screen_normal, probes=probes, sheet=sheet, reference=ref)
            for m in MODELS:
                rows[m].append((float(S), pe[m]))
        return cls(rows)

    @classmethod
    def at_home(cls, probes, *, eye, projector, stretch_node: float, config: SheetConfig,
                sheet_model: NominalSheetModel) -> ErrorTable:
        """:meth:`build` on the home (unpushed, untilted) sheet at clamp stretch ``stretch_node`` with
        ``config``'s half width, on the paper's imaginary screen: the table the renderer node picks its models
        from (and the correction experiment's live path)."""
        home = SheetSurface(np.zeros(3), geometry.SCREEN_NORMAL, [0.0, 1.0, 0.0],
                            clamp_half_span(stretch_node),
                            config.half_width)
        return cls.build(probes, eye=eye, projector=projector, screen_point=geometry.SCREEN_POINT,
                         screen_normal=geometry.SCREEN_NORMAL, sheet=home, sheet_model=sheet_model)

    def choose(self, depth: float, target: float, models: tuple[str, ...] = AUTO_MODELS) -> str:
        """Cheapest of ``models`` whose predicted error at ``depth`` m is ≤ ``target`` m (else the best
        one)."""
        return choose_sheet_model(depth, self.rows, target, models=models)


def pick_model(correction: str, sheet: SheetSurface, table: ErrorTable | None, target: float) -> str:
    """The correction model to draw ``sheet`` with: ``correction`` itself unless it is ``"auto"``; then
    ``"flat"`` for an unpushed sheet, else the cheapest model meeting ``target`` m at the sheet's push depth.
    A push whose shape is not known yet (:class:`~flexsheet.model.sheet_model.PendingPush`: its stretch's
    table is being built), or ``auto`` before the error ``table`` exists (None), is drawn with
    ``"four_triangle"`` (``"fine"`` needs the shape)."""
    if correction not in MODELS and correction != "auto":
        raise ValueError(f"correction must be 'auto' or one of {MODELS}, got {correction!r}")
    pending = isinstance(sheet.membrane, PendingPush)
    if correction != "auto":
        return "four_triangle" if correction == "fine" and pending else correction
    if sheet.membrane is None:
        return "flat"
    if pending or table is None:
        return "four_triangle"
    return table.choose(sheet.membrane.depth, target)


def build_table(settings: dict, node: float, nice: int = 0) -> float:
    """Build the table of ``NominalSheetModel(**settings)`` at ``node`` and cache it on disk; returns
    ``node``. Module-level so that a worker process can run it (the node builds missing tables off its render
    loop, at ``nice`` below its priority, in the idle scheduling class:
    :func:`flexsheet.runtime.background.lower_priority`)."""
    if nice:
        lower_priority(nice)
    NominalSheetModel(**settings).table(float(node))
    return float(node)


class RendererState:
    """The renderer's newest inputs and the sheet they give (see the module docstring); thread-safe.

    ``eye`` (3,) m: cyclopean eye V; ``projector`` (3,) m: light source P (the sheet must lie between them);
    ``config``: :class:`SheetConfig`; ``mesh``: the rigid object's (vertices (N, 3) m, faces (M, 3)) drawn
    until the FEM publishes (the scene's :meth:`~flexsheet.model.scenes.Scene.surface_mesh`; default the
    paper's cylinder); ``sheet_model``: the pushed sheet's shape (:class:`NominalSheetModel`; None:
    :func:`sheet_model_for` ``config``); ``build``: False to never build a missing FEM table in the caller's
    thread (the node's drawing thread) — a push at a stretch whose table is not on disk yet then gets a
    :class:`PendingPush` and ``on_missing(node)`` is called (the node builds it in a worker process).
    Starts with both clamps in the home pose.
    """

    def __init__(self, eye, projector, config: SheetConfig = SheetConfig(), mesh=None,
                 sheet_model: NominalSheetModel | None = None, *, build: bool = True,
                 on_missing=None) -> None:
        self.eye = np.asarray(eye, dtype=float)
        self.projector = np.asarray(projector, dtype=float)
        self.config = config
        self.sheet_model = sheet_model if sheet_model is not None else sheet_model_for(config)
        self.build = bool(build)
        self.on_missing = on_missing
        self._lock = threading.Lock()
        v, f = (cylinder_draw_mesh() if mesh is None
                else (np.asarray(mesh[0], np.float32), np.asarray(mesh[1], np.int32)))
        self._mesh = (v, f, vertex_normals(v, f))
        self._mesh_dirty = True
        self._mesh_stamp = 0.0
        self.home = dict(zip(("left", "right"), clamp_poses(np.zeros(3), geometry.SCREEN_NORMAL,
                                                                  np.array([0.0, 1.0, 0.0]), 0.0),
                             strict=True))
        self._pose: dict[str, np.ndarray | None] = {"left": None, "right": None}
        self._finger: np.ndarray | None = None
        self._finger_stamp = 0.0
        self.last_good = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], half_width=config.half_width)

    # ------------------------------------------------------------------ inputs
    @property
    def mesh_vertices(self) -> np.ndarray:
        """The current object mesh's vertices (N, 3) float32 m."""
        with self._lock:
            return self._mesh[0]

    def set_mesh(self, vertices, faces, stamp: float) -> None:
        """New object mesh: ``vertices`` (N, 3) m, ``faces`` (M, 3) int indices < N; ``stamp`` its source
        exposure time, s. Raises ``ValueError`` for an empty mesh or face indices out of range."""
        v, f = np.asarray(vertices), np.asarray(faces)
        if len(v) == 0 or len(f) == 0:
            raise ValueError(f"deformation has {len(v)} vertices and {len(f)} faces")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"faces index out of range [0, {len(v)}): min {f.min()}, max {f.max()}")
        n = vertex_normals(v, f)
        with self._lock:
            self._mesh = (v, f, n)
            self._mesh_dirty = True
            self._mesh_stamp = float(stamp)

    def set_arm_pose(self, arm: str, T) -> None:
        """Clamp pose ``T`` (4, 4, display frame, m) of ``arm`` ("left"/"right"). Raises ``ValueError`` if it
        is not a rigid transform or, with the other arm's latest pose, gives a sheet with the eye behind it or
        the projector in front of it (the pose is then not taken)."""
        if arm not in ("left", "right"):
            raise ValueError(f"arm must be 'left' or 'right', got {arm!r}")
        T = check_pose(f"{arm} arm.pose", T, tol=1e-3)
        other_arm = "right" if arm == "left" else "left"
        with self._lock:
            other = self._pose[other_arm]
        if other is None:
            other = self.home[other_arm]
        Tl, Tr = (T, other) if arm == "left" else (other, T)
        try:
            sheet = SheetSurface.from_clamps(Tl, Tr, half_width=self.config.half_width)
            check_sheet(sheet, self.eye, self.projector)
        except ValueError as exc:
            raise ValueError(f"{arm} arm pose gives an unusable sheet: {exc}") from exc
        with self._lock:
            self._pose[arm] = T

    def set_fingertip(self, position, stamp: float) -> None:
        """Fingertip ``position`` (3,) m, or None when the tracker has no valid fix; ``stamp`` exposure time,
        s."""
        with self._lock:
            self._finger = None if position is None else np.asarray(position, dtype=float)
            self._finger_stamp = float(stamp)

    # ------------------------------------------------------------------ outputs
    def take_mesh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(vertices, faces, normals) if the mesh changed since the last call, else None."""
        with self._lock:
            if not self._mesh_dirty:
                return None
            self._mesh_dirty = False
            return self._mesh

    @property
    def fingertip_stamp(self) -> float:
        """Exposure stamp (s) of the newest fingertip taken (0 before any)."""
        with self._lock:
            return self._finger_stamp

    @property
    def source_stamp(self) -> float:
        """Newest exposure stamp (s) among the fingertip and the deformation drawn."""
        with self._lock:
            return max(self._finger_stamp, self._mesh_stamp)

    def current_sheet(self) -> SheetSurface:
        """The actual sheet from the latest clamp poses (home pose for an arm not heard from), pushed in by
        the fingertip when it is more than ``push_threshold`` behind the flat sheet: the shape of
        ``sheet_model`` at the clamps' stretch, the fingertip's depth and contact
        (:meth:`NominalSheetModel.pushed`), or a :class:`PendingPush` while that stretch's table is missing
        and ``build`` is False."""
        c = self.config
        with self._lock:
            Tl = self._pose["left"] if self._pose["left"] is not None else self.home["left"]
            Tr = self._pose["right"] if self._pose["right"] is not None else self.home["right"]
            finger = self._finger
        sheet = believed_sheet(Tl, Tr, finger, self.sheet_model, c, build=self.build)
        if isinstance(sheet.membrane, PendingPush) and self.on_missing is not None:
            self.on_missing(sheet.membrane.node)
        return sheet

    def sheet_for_frame(self) -> tuple[SheetSurface, str]:
        """(sheet to draw, warning): the current sheet if usable (it becomes the last good one), else the last
        good sheet and a one-line reason."""
        try:
            sheet = self.current_sheet()
            check_sheet(sheet, self.eye, self.projector)
        except ValueError as exc:
            return self.last_good, f"sheet unusable ({exc}); drawing the last good sheet"
        self.last_good = sheet
        return sheet, ""


@dataclass
class RenderGeometry:
    """What the renderer draws and through which projector (:func:`load_geometry`).

    ``scene``: the :class:`~flexsheet.model.scenes.Scene`; ``mesh``: its surface (vertices (N, 3) float32 m,
    faces (M, 3) int32); ``projector``: the registered :class:`Projector` at the drawing resolution;
    ``distortion`` (5,) its OpenCV distortion; ``eye`` (3,) m the cyclopean eye V; ``ipd`` m; ``nominal``:
    True when no ``display.yaml`` was named (code constants, nothing measured); ``log``: lines for the node's
    log (where each part came from); ``strain_offset``: the sheet's identified strain offset ε₀
    (``display.yaml``'s ``sheet`` entry, the planner's too; 0 without one), which the pushed-sheet model takes
    (:class:`~flexsheet.model.sheet_model.SheetConfig`)."""

    scene: Scene
    mesh: tuple[np.ndarray, np.ndarray]
    projector: Projector
    distortion: np.ndarray
    eye: np.ndarray
    ipd: float
    nominal: bool
    log: list[str] = field(default_factory=list)
    strain_offset: float = 0.0


def load_geometry(scene_file: str | None = None, display_calib: str | None = None, width: int | None = None,
                  height: int | None = None) -> RenderGeometry:
    """The renderer's geometry: the object of ``scene_file`` (None: the paper's cylinder,
    :func:`~flexsheet.model.scenes.paper_scene`) and the projector (K_p, D, pose, size) and eye (V, ipd) of
    ``display_calib`` (``display.yaml``; None:
    :func:`~flexsheet.calibration.display_calib.nominal_display_calib`, flagged ``nominal``).
    ``width``/``height`` px draw the same projector at another resolution
    (:func:`~flexsheet.rendering.stereo_renderer.scaled_projector`; None: the calibrated size).

    The imaginary screen → projector pixel mapping is then the calibration's: K_p, D and the pose from the
    file, nothing from constants. V ± IPD/2 are the eyes drawn for until ``/eye/pose`` tracks the viewer
    (:mod:`flexsheet.rendering.viewpoint`), whatever the entry's mode. Raises ``ValueError`` naming the file
    and key: scene invalid, display.yaml unreadable or without its ``projector`` or ``eye`` entry.
    """
    log = []
    sc = paper_scene() if not scene_file else load_scene(scene_file)
    log.append(f"drawing {sc.describe()}")
    if display_calib:
        dc = load_display_calib(display_calib, require=("projector", "eye"))
        nominal = False
    else:
        dc = nominal_display_calib()
        nominal = True
    pe, ee = dc.projector, dc.eye
    proj = scaled_projector(pe.projector(), width, height)
    if nominal:
        log.append("display_calib not set: using the NOMINAL projector and eye (code constants, nothing "
                   "measured; name a display.yaml in the launch file's display_calib: once `flexsheet "
                   "calibrate` has run)")
    else:
        P = pe.position
        log.append(f"projector from {display_calib} ({pe.provenance.source}, {pe.provenance.measured_at}): "
                   f"{pe.width}x{pe.height} px, f {pe.K[0, 0]:.1f}/{pe.K[1, 1]:.1f} px, "
                   f"P {np.round(P * 1e3, 1).tolist()} mm; eye V {np.round(ee.V * 1e3, 1).tolist()} mm, "
                   f"ipd {ee.ipd * 1e3:.1f} mm ({ee.provenance.source})")
    if (proj.width, proj.height) != (pe.width, pe.height):
        log.append(f"drawing the {pe.width}x{pe.height} projector at {proj.width}x{proj.height} px (K "
                   "rescaled)")
    sheet = None if nominal else dc.sheet
    if sheet is not None:
        log.append("pushed sheet: the sheet gripped on its clamp edges, strain offset "
                   f"{sheet.strain_offset:+.4f} identified in {display_calib} ({sheet.provenance.source}; "
                   "the planner's sheet entry)")
    else:
        log.append("pushed sheet: the sheet gripped on its clamp edges, strain offset 0 (no identified sheet "
                   "entry; `flexsheet calibrate sheet` writes one)")
    if ee.mode == "tracked":
        log.append(f"eye mode tracked: the pairs follow /eye/pose; V {np.round(ee.V * 1e3, 1).tolist()} mm "
                   "while the glasses are not tracked")
    return RenderGeometry(sc, sc.surface_mesh(), proj, np.asarray(pe.D, float).ravel().copy(),
                          np.asarray(ee.V, float).copy(), float(ee.ipd), nominal, log,
                          0.0 if sheet is None else float(sheet.strain_offset))
