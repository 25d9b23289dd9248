"""World-twin messages: ground truth of the simulated finger and sheet (simulation only)."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["FingerTruth", "HeadTruth", "SheetState"]


class FingerTruth(Message):
    """True position of the simulated fingertip marker (drives the camera twin; never used by the planner).
    ``position`` (3,) m and ``velocity`` (3,) m/s in the display frame. The script segment being played, as
    typed fields: ``segment`` (its index in the world's script, 0-based), ``mode`` ("stroke", "push",
    "stroke_push"), ``moving_time`` (s, the segment's time for the mark's travel; Table I's row key) and
    ``phase`` (where in the segment: "approach", "idle", or the mode while the mark moves; "paused" while a
    tool has paused the script, the finger away from the display). ``target_angle``: angle of the target mark
    around the cylinder axis, rad (0 = facing the user). ``visible``: False when the script occludes the
    marker.
    """

    SCHEMA = "flexsheet/FingerTruth"
    VERSION = 2

    position: ndarray("float64", (3,), "marker position, m, display frame")
    velocity: ndarray("float64", (3,), "marker velocity, m/s, display frame")
    segment: int = Field(default=0, ge=0, description="index of the script segment being played")
    mode: str = Field(default="stroke", pattern="^(stroke|push|stroke_push)$",
                      description="segment mode: stroke | push | stroke_push")
    moving_time: float = Field(default=0.0, ge=0.0, description="segment moving time (mark's travel), s")
    phase: str = Field(default="idle", pattern="^(approach|idle|stroke|push|stroke_push|paused)$",
                       description="script phase: approach | idle | the mode while the mark moves | paused")
    target_angle: float = Field(default=0.0, description="target mark angle around the cylinder axis, rad")
    visible: bool = Field(default=True, description="marker visible to the camera")


class SheetState(Message):
    """Actual (true) sheet state in the simulated world: the clamp poses come from the hidden truth's
    kinematics (true bases, link lengths, joint zero offsets; :class:`flexsheet.twin.truth.TwinTruth`) of the
    arms' measured joints, and ``membrane`` from the independent nonlinear sheet FEM
    (:mod:`flexsheet.model.sheet_fem`). Estimators never read it; the report and the measurement camera do.
    ``origin`` (3,) m: sheet centre; ``normal`` (3,), ``axis_u`` (3,): unit vectors (display frame).
    ``corners`` (4, 3) m: sheet corners in order around the sheet. ``pushed_point`` (3,) m: the deepest
    point of the finger's depression (equals ``origin`` projection when not pushed). ``depth`` m:
    depression along −normal. ``stretch``: engineering strain between the true clamps, signed (negative when
    they are closer than the sheet's side: slack). ``membrane`` (G, G) m:
    out-of-plane deflection of the membrane sampled on a G×G grid over the sheet (u, v ∈ [−a, a]), positive
    along −normal. The finger's force on it is on ``/world/contact`` (:class:`ContactTruth`).
    """

    SCHEMA = "flexsheet/SheetState"
    VERSION = 3    # v3: ``stretch`` signed (negative: the clamps closer than the sheet's side, slack)

    origin: ndarray("float64", (3,), "sheet centre, m, display frame")
    normal: ndarray("float64", (3,), "unit sheet normal")
    axis_u: ndarray("float64", (3,), "unit in-plane axis, right->left clamp (+y at home)")
    corners: ndarray("float64", (4, 3), "sheet corners, m, display frame")
    pushed_point: ndarray("float64", (3,), "deepest point of the depression, m")
    depth: float = Field(ge=0.0, description="depression depth, m")
    stretch: float = Field(gt=-1.0, description="engineering strain between clamps, signed (negative: slack)")
    membrane: ndarray("float64", (None, None), "deflection grid, m, along -normal")


class ContactTruth(Message):
    """The finger's true contact with the true sheet in the simulated world: what the finger feels. From the
    twin's sheet FEM (:mod:`flexsheet.model.sheet_fem`, its table at the true clamp strain); the report
    compares it with the force the object asks. Estimators never read it; a lab measures it with a load cell.
    ``touching``: the finger is behind the sheet's plane within the clamps. ``depth`` m: the indentation along
    the sheet's normal. ``force`` N: the normal contact force (0 while no table is ready). ``point`` (3,) m:
    the bottom of the dent (the finger's apex on the pushed sheet; not the contact on the object's surface),
    display frame. ``stiffness`` N/m: the sheet's incremental stiffness dF/d(depth) there (0 while no table is
    ready).
    """

    SCHEMA = "flexsheet/ContactTruth"
    VERSION = 1

    touching: bool = Field(default=False, description="finger behind the sheet's plane, within the clamps")
    depth: float = Field(ge=0.0, description="indentation along the sheet normal, m")
    force: float = Field(ge=0.0, description="normal contact force, N")
    point: ndarray("float64", (3,), "bottom of the dent (the finger's apex on the pushed sheet), m, display "
                                    "frame")
    stiffness: float = Field(ge=0.0, description="incremental stiffness dF/d(depth), N/m")


class HeadTruth(Message):
    """True pose of the simulated viewer's head (drives the head camera twin and the report; never used by an
    estimator).
    ``position`` (3,) m: the glasses frame's origin (the bridge of the stereo glasses), display frame;
    ``rotation`` (3, 3): the glasses frame's axes as columns (x from the right lens to the left lens, y up,
    z toward the sheet when worn; :mod:`flexsheet.calibration.eye`). ``left``/``right``/``eye`` (3,) m: the
    viewer's true eyes and their midpoint (the cyclopean eye). ``velocity`` (3,) m/s of the cyclopean eye.
    ``visible``: False while the script occludes the glasses' markers.
    """

    SCHEMA = "flexsheet/HeadTruth"
    VERSION = 1

    position: ndarray("float64", (3,), "glasses origin, m, display frame")
    rotation: ndarray("float64", (3, 3), "glasses axes as columns, display frame")
    left: ndarray("float64", (3,), "true left eye, m, display frame")
    right: ndarray("float64", (3,), "true right eye, m, display frame")
    eye: ndarray("float64", (3,), "true cyclopean eye, m, display frame")
    velocity: ndarray("float64", (3,), "cyclopean eye velocity, m/s, display frame")
    visible: bool = Field(default=True, description="glasses markers visible to the head camera")
