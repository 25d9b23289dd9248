"""The estimator side (no truth): :class:`DisplayEstimator`, the display's estimators for one
:class:`flexsheet.experiments.correction.calibrated_display.CalibratedDisplay`."""

from __future__ import annotations

import numpy as np

from flexsheet.arm.kinematics import ArmKinematics, clamp_joints
from flexsheet.experiments.correction.calibrated_display import CalibratedDisplay
from flexsheet.experiments.correction.settings import PIXEL, STRETCH
from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface, clamp_half_span, clamp_poses
from flexsheet.model.sheet_model import SheetConfig, sheet_model_for
from flexsheet.rendering.state import ErrorTable, RendererState, pick_model, silhouette_probes
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh


class DisplayEstimator:
    """The display's estimators for one :class:`CalibratedDisplay` (and nothing else — by construction it
    takes no truth): the bridges' kinematics at the calibrated bases, the renderer's sheet, model choice and
    drawing.

    ``config``: the renderer's :class:`flexsheet.model.sheet_model.SheetConfig`; ``sheet_model``: the
    renderer's pushed-sheet model (:class:`flexsheet.model.sheet_model.NominalSheetModel`; None: the node's
    own, :func:`flexsheet.model.sheet_model.sheet_model_for` ``config``), the ``fem_nominal`` column;
    ``samples``: MSAA samples; ``target`` m: the ``auto`` model choice's accuracy target. Raises ``TypeError``
    if ``cal`` is not a :class:`CalibratedDisplay`.
    """

    def __init__(self, cal: CalibratedDisplay, config=None, *, sheet_model=None, samples: int = 4,
                 target: float = PIXEL) -> None:
        if not isinstance(cal, CalibratedDisplay):
            raise TypeError(f"DisplayEstimator takes a CalibratedDisplay, got {type(cal).__name__}")
        self.cal = cal
        self.config = config or SheetConfig()
        self.sheet_model = sheet_model if sheet_model is not None else sheet_model_for(self.config)
        self.target = float(target)
        self.kin = {s: ArmKinematics(s, cal.bases[s]) for s in ("left", "right")}
        self.renderer = StereoRenderer(cal.projector, distortion=cal.distortion, eye=cal.eye, ipd=cal.ipd,
                                       samples=samples, shading=False)
        v, f = cylinder_draw_mesh()
        self.renderer.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], clamp_half_span(STRETCH))
        self.table = ErrorTable.build(silhouette_probes(v), eye=cal.eye, projector=cal.projector.position,
                                      screen_point=geometry.SCREEN_POINT,
                                      screen_normal=geometry.SCREEN_NORMAL, sheet=home,
                                      sheet_model=self.sheet_model)

    def joints(self, origin, normal, axis_u, stretch: float = STRETCH) -> dict[str, np.ndarray]:
        """The bridges' joint commands (side → (6,) rad) for the commanded sheet pose: IK of the clamp poses
        (:func:`flexsheet.model.sheet.clamp_poses`) at the calibrated bases. Raises ``ValueError`` if an arm
        cannot reach it."""
        return clamp_joints(self.kin, *clamp_poses(origin, normal, axis_u, stretch))

    def clamps(self, q: dict) -> tuple[np.ndarray, np.ndarray]:
        """The bridges' clamp poses (FK of the measured joints at the calibrated bases), (left, right) (4,
        4)."""
        return self.kin["left"].fk(q["left"]), self.kin["right"].fk(q["right"])

    def sheet(self, q: dict, finger=None, series: bool = False) -> SheetSurface:
        """The renderer's sheet (:meth:`flexsheet.rendering.state.RendererState.current_sheet`, the node's
        code path) from the bridges' clamp poses and the tracked fingertip ``finger`` (3,) m or None; when
        pushed, its membrane is the ``sheet_model``'s (``fem_nominal``). ``series``: instead the renderer's
        OLD pushed-sheet model, the 16-mode sine series (:class:`flexsheet.model.sheet.Membrane`, tension
        ratio 1), for the comparison column ``fine`` only; the renderer no longer uses it."""
        Tl, Tr = self.clamps(q)
        if series:
            flat = SheetSurface.from_clamps(Tl, Tr, half_width=self.config.half_width)
            if finger is None or -float((np.asarray(finger, float) - flat.origin) @ flat.normal) <= \
                    self.config.push_threshold:
                return flat
            return SheetSurface.from_clamps(Tl, Tr, half_width=self.config.half_width,
                                            pushed_point=np.asarray(finger, float),
                                            membrane_kwargs={"modes": 16})
        st = RendererState(self.cal.eye, self.cal.projector.position, self.config,
                           sheet_model=self.sheet_model)
        st.set_arm_pose("left", Tl)
        st.set_arm_pose("right", Tr)
        st.set_fingertip(None if finger is None else np.asarray(finger, float), 0.0)
        return st.current_sheet()

    def pick(self, sheet: SheetSurface) -> str:
        """The model the renderer's ``auto`` picks for ``sheet``
        (:func:`flexsheet.rendering.state.pick_model`)."""
        return pick_model("auto", sheet, self.table, self.target)

    def draw(self, model: str, sheet: SheetSurface) -> np.ndarray:
        """The projector image (H, W) float in [0, 1] drawn with ``model`` (one of
        :data:`flexsheet.rendering.correction.MODELS`; ``fine`` uses ``sheet``'s membrane) for the calibrated
        eye."""
        with self.renderer.ctx:           # another renderer's (standalone) context may be current
            self.renderer.set_model(model, None if model == "none" else sheet)
            return self.renderer.render_single(self.cal.eye)

    def release(self) -> None:
        self.renderer.release()
