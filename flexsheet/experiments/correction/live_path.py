"""The live renderer's path, ray-traced: :class:`LivePath` (the renderer node's pushed-sheet correction
measured on the true sheet without GL) and :func:`live_path`, its rows for a truth."""

from __future__ import annotations

import logging

import numpy as np

from flexsheet.experiments.correction.poses import HOME_POSE
from flexsheet.experiments.correction.settings import PIXEL, STRETCH
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.experiments.measurement import trace_to_sheet
from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface, clamp_poses, frame_from_clamps
from flexsheet.model.sheet_model import SheetConfig, sheet_model_for
from flexsheet.rendering.correction import (
    correct_vertices,
    correct_vertices_fine,
    correct_vertices_pushed,
    project_vertices,
)
from flexsheet.rendering.state import ErrorTable, RendererState, pick_model, silhouette_probes
from flexsheet.rendering.stereo_renderer import cylinder_draw_mesh
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)


class LivePath:
    """The renderer node's pushed-sheet correction measured on the true sheet without GL (``live_path`` of the
    summary; ``tests/unit/experiments/test_correction.py``).

    Renderer side, as ``RendererNode.setup`` builds it: the sheet model of
    :func:`flexsheet.model.sheet_model.sheet_model_for` ``config`` (or ``sheet_model``), a
    :class:`flexsheet.rendering.state.RendererState` fed both clamp poses (the home pose at ``stretch``) and
    the fingertip, the :class:`flexsheet.rendering.state.ErrorTable` and ``auto``
    :func:`flexsheet.rendering.state.pick_model`, and the picked model's correction in numpy (the shader's
    twin, equal to 2e-6 m). Truth side: the twin's FEM sheet (:meth:`TwinWorld.table`, the truth's E,
    pre-strain and tension ratio) at the same clamps, lit along the projector's rays and traced by the
    measurement camera's bisection (:func:`trace_to_sheet` on a 241×241 grid), not the renderer's Newton
    solver. Eye V and projector P are the same on both sides, so the error is the sheet model's alone: per
    probe (the object's silhouette points), the distance on the imaginary screen seen from the eye between
    where the light for A' lands and where the eye expects A."""

    def __init__(self, stretch: float = STRETCH, config=None, sheet_model=None, eye=geometry.EYE,
                 projector=geometry.PROJECTOR) -> None:
        self.config = config or SheetConfig()
        self.eye, self.projector = np.asarray(eye, float), np.asarray(projector, float)
        self.stretch = float(stretch)
        model = sheet_model if sheet_model is not None else sheet_model_for(self.config)
        v, f = cylinder_draw_mesh()
        self.probes = silhouette_probes(v)
        self.clamps = clamp_poses(*HOME_POSE, self.stretch)
        self.table = ErrorTable.at_home(self.probes, eye=self.eye, projector=self.projector,
                                        stretch_node=self.stretch, config=self.config,
                                        sheet_model=sheet_model if sheet_model is not None
                                        else sheet_model_for(self.config))
        self.state = RendererState(self.eye, self.projector, self.config, mesh=(v, f), sheet_model=model)
        self.state.set_arm_pose("left", self.clamps[0])
        self.state.set_arm_pose("right", self.clamps[1])

    def sheet(self, finger) -> tuple[SheetSurface, str]:
        """(the renderer's sheet, the model ``auto`` picks) for the fingertip ``finger`` (3,) m."""
        self.state.set_fingertip(np.asarray(finger, float), 0.0)
        sheet, warn = self.state.sheet_for_frame()
        if warn:
            raise ValueError(warn)
        return sheet, pick_model("auto", sheet, self.table, PIXEL)

    def corrected(self, model: str, sheet: SheetSurface) -> np.ndarray:
        """A' (N, 3) m of the probes for ``model`` on ``sheet``."""
        c = dict(eye=self.eye, projector=self.projector, screen_point=geometry.SCREEN_POINT,
                 screen_normal=geometry.SCREEN_NORMAL)
        if model == "fine":
            return correct_vertices_fine(self.probes, sheet=sheet, **c)
        if model == "four_triangle":
            return correct_vertices_pushed(self.probes, pushed_point=sheet.pushed_point,
                                           corners=sheet.corners, **c)
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
        """Per probe, m: where the light for ``a_hat`` lands on ``true``, seen from the eye, against the
        probe."""
        scr = dict(eye=self.eye, screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL)
        b = project_vertices(a_hat, **scr)                            # where the projector aims (its pinhole)
        grid = true.membrane.grid(241) if true.membrane is not None else None
        c, hit = trace_to_sheet(self.projector, b - self.projector, true, grid)
        if not hit.all():
            raise ValueError(f"{int((~hit).sum())} projector rays miss the true sheet")
        return np.linalg.norm(project_vertices(c, **scr) - project_vertices(self.probes, **scr), axis=1)

    def measure(self, world: TwinWorld, depth: float) -> dict:
        """The live path at push ``depth`` m at the sheet centre: the picked model's max and mean landing
        error, and (for comparison only) the uncorrected image's and the old series model's, mm."""
        finger = HOME_POSE[0] - depth * HOME_POSE[1]
        sheet, model = self.sheet(finger)
        true = self.true_sheet(world, finger)
        err = self.landing_error(self.corrected(model, sheet), true)
        row = {"model": model, "max_mm": float(err.max() * 1e3), "mean_mm": float(err.mean() * 1e3),
               "depth_table": list(sheet.membrane.w.shape) if sheet.membrane is not None else None,
               "uncorrected_max_mm": float(self.landing_error(self.probes, true).max() * 1e3)}
        if depth > 0.0:
            old = SheetSurface.from_clamps(*self.clamps, half_width=self.config.half_width,
                                           pushed_point=finger,
                                           membrane_kwargs={"modes": 16})
            row["series_max_mm"] = float(self.landing_error(self.corrected("fine", old), true).max() * 1e3)
        return row


def live_path(truth: TwinTruth, depths_mm=(0, 10, 30, 50), strain_offset: float = 0.0) -> dict:
    """:class:`LivePath` rows for ``truth`` at each depth (mm), keyed by the depth; the renderer's sheet model
    with the identified ``strain_offset`` (``display.yaml``'s sheet entry)."""
    lp, world = LivePath(config=SheetConfig(strain_offset=float(strain_offset))), TwinWorld(truth)
    out = {}
    for d in depths_mm:
        out[f"{d:g}"] = r = lp.measure(world, d * 1e-3)
        log.info(f"[correction] live path {d:g} mm: {r['model']} max {r['max_mm']:.2f} mm, mean "
                 f"{r['mean_mm']:.2f} mm (uncorrected max {r['uncorrected_max_mm']:.2f} mm)")
    return out
