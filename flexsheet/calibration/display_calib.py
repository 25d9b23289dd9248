"""``display.yaml``: the display's registration — where the camera, the projector, the arms and the eye are in
the ``display`` frame, and how each was measured (pure: numpy + OpenCV FileStorage + PyYAML).

One file, written by ``flexsheet calibrate camera-pose | projector | arms | eye |
display`` and named by a launch file (``display_calib:``). Each entry is optional while the lab works through
the procedures; a consumer asks for the entries it needs with :meth:`DisplayCalib.require` (missing →
``ValueError`` naming the file and key) and may refuse stale ones with :meth:`DisplayCalib.stale`.

Layout (OpenCV FileStorage YAML; matrices are ``!!opencv-matrix``, units m / rad / px)::

    format_version: 1
    camera:                       # the stereo camera (left optical frame: +z forward, +x right, +y down)
       T_display_camera: 4x4      # left camera pose in the display frame
       image_width, image_height, K1, D1, K2, D2, R, T   # stereo model refined by the camera-pose fit
       cov: 30x30                 # covariance of (stereo parameters, pose) — optional
       provenance: {method, measured_at, source, n_poses, residuals: {rms_px, residual_mm, ...}} projector: K:
       3x3  D: 5x1  width, height T_display_projector: 4x4   # columns of R = projector x (image right), y
       (image down), z (optical axis);
                                  # translation = the projection centre P provenance: {...} arms: left:
    {T_display_base: 4x4, marker_offset: 3x1 (clamp marker in the clamp frame), provenance} right: {...} eye:
    mode: fixed | tracked V: 3x1  ipd: m  glasses_eye_offset: 3x1 (cyclopean eye in the glasses marker frame,
    tracked mode) provenance: {...} head_camera:                  # the camera facing the viewer (optional:
    without it the image is for V) K: 3x3  D: 5x1  width, height T_display_camera: 4x4      # its optical
    frame (+z forward, +x right, +y down) in the display frame provenance: {...} sheet:
    # the sheet's force under a fingertip, identified from pushes (optional) contact_width: m  contact_growth:
    1 own_stiffness: N  own_growth: N/m  stretching: N/m^3  strain_offset: 1 provenance: {...}          #
    residuals: median_pct, rms_pct (the model against the presses)

``provenance.measured_at`` is ISO 8601 UTC; ``source`` is ``lab``, ``twin seed N`` or ``nominal``. The file is
written with ``cv2.FileStorage`` (so OpenCV reads it back) and read with PyYAML's safe loader (the
``!!opencv-matrix`` maps checked by :mod:`flexsheet.vision.stereo_calibration`), so a hostile file never
reaches OpenCV's parser. Frames: :mod:`flexsheet.model.geometry`.
"""  # noqa: E501 - a table, template or command line kept whole

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field

import cv2
import numpy as np

from flexsheet.calibration.sheet import with_terms
from flexsheet.model import geometry
from flexsheet.model.checks import check_pose
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.projector import Projector
from flexsheet.vision.camera_model import DEFAULT_CAMERA_POSITION, camera_model, look_at

__all__ = ["FORMAT_VERSION", "ENTRIES", "NOMINAL_CLAMP_MARKER", "NOMINAL_IPD", "Provenance", "CameraEntry",
           "ProjectorEntry", "ArmEntry", "EyeEntry", "HeadCameraEntry", "SheetEntry", "DisplayCalib",
           "OPTIONAL", "nominal_display_calib",
           "now_iso", "pose_from_rt", "xyzyaw_from_pose", "BOOTSTRAP_FILE", "STEREO_NAMES",
           "stereo_vector", "stereo_from_vector"]

FORMAT_VERSION = 1
#: entry names, as :meth:`DisplayCalib.require` and the error messages spell them
ENTRIES = ("camera", "projector", "arms.left", "arms.right", "eye", "head_camera", "sheet")
#: entries a display runs without (the head camera: the image is for V; the sheet: the nominal string band)
OPTIONAL = ("head_camera", "sheet")
#: nominal clamp marker (a 10 mm retro-reflective sphere) in the clamp (tool) frame, m: 10 mm toward the user
#: (normal) and 40 mm along axis_v from the middle of the clamped edge (design value; calibrated by ``arms``)
NOMINAL_CLAMP_MARKER = (0.010, 0.0, 0.040)
#: nominal interpupillary distance, m (adult median, Dodgson 2004: 63–64 mm)
NOMINAL_IPD = 0.064


#: bootstrap deviations of the shipped XIMEA stereo calibration
#: (``python -m flexsheet.twin.truth --bootstrap``): the uncertainty the stereo
#: calibration leaves, used as the camera-pose prior and as the truth's spread
BOOTSTRAP_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "vision",
                              "ximea_calib_bootstrap.json")

STEREO_NAMES = [f"{c}_{n}" for c in ("left", "right")
                for n in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2",
                                                                  "k3")] + ["rx", "ry", "rz", "tx", "ty",
                                                                            "tz"]


def stereo_vector(calib: dict) -> np.ndarray:
    """(24,) parameter vector of a stereo calibration dict: per camera (fx, fy, cx, cy, k1, k2, p1, p2, k3),
    then the left→right rotation as a Rodrigues vector (rad) and T (m)."""
    v = []
    for K, D in ((calib["K1"], calib["D1"]), (calib["K2"], calib["D2"])):
        d = np.zeros(5)
        dd = np.asarray(D, float).ravel()[:5]
        d[:dd.size] = dd
        v += [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d]
    v += list(cv2.Rodrigues(np.asarray(calib["R"], float))[0].ravel()) + list(np.asarray(calib["T"],
                                                                                         float).ravel())
    return np.array(v, float)


def stereo_from_vector(v: np.ndarray, image_size) -> dict:
    """Inverse of :func:`stereo_vector`: dict with ``image_size``, K1, D1, K2, D2, R, T (float64)."""
    v = np.asarray(v, float)
    out: dict = {"image_size": (int(image_size[0]), int(image_size[1]))}
    for i, s in enumerate(("1", "2")):
        a = v[9 * i:9 * i + 9]
        out["K" + s] = np.array([[a[0], 0.0, a[2]], [0.0, a[1], a[3]], [0.0, 0.0, 1.0]])
        out["D" + s] = a[4:9].copy()
    out["R"] = cv2.Rodrigues(v[18:21].copy())[0]
    out["T"] = v[21:24].copy()
    return out


def now_iso() -> str:
    """Current UTC time as ISO 8601 with seconds, e.g. ``2025-01-31T12:00:00Z``."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def pose_from_rt(R, t) -> np.ndarray:
    """(4, 4) homogeneous transform from a rotation (3, 3) and translation (3,) m."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, float)
    T[:3, 3] = np.asarray(t, float).ravel()
    return T


def xyzyaw_from_pose(T: np.ndarray, max_tilt_deg: float = 1.0) -> tuple[float, float, float, float]:
    """(x, y, z, yaw) (m, m, m, rad) of a base pose (4, 4) whose rotation is a yaw about +z up to a tilt of
    ``max_tilt_deg`` (the form ``ArmKinematics`` and the planner's ``left_base``/``right_base`` take).

    Raises ``ValueError`` if the base is tilted more than ``max_tilt_deg`` (use the full 4×4 then).
    """
    T = check_pose("T", T)
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(T[2, 2])))))
    if tilt > max_tilt_deg:
        raise ValueError(f"base is tilted {tilt:.3f} deg > {max_tilt_deg} deg from vertical; use the 4x4 "
                         "pose")
    yaw = math.atan2(float(T[1, 0]), float(T[0, 0]))
    return float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), yaw


@dataclass
class Provenance:
    """How and when an entry was measured.

    ``method``: one line naming the procedure and its inputs; ``measured_at``: ISO 8601 UTC;
    ``source``: ``lab``, ``twin seed N`` or ``nominal``; ``n_poses``: poses/views/configurations used;
    ``residuals``: named residuals (``*_mm`` in mm, ``*_px`` in pixels, ``*_deg`` in degrees).
    """

    method: str
    measured_at: str = field(default_factory=now_iso)
    source: str = "lab"
    n_poses: int = 0
    residuals: dict[str, float] = field(default_factory=dict)

    def age_s(self, now: _dt.datetime | None = None) -> float:
        """Seconds since ``measured_at`` (``math.inf`` if it does not parse)."""
        try:
            t = _dt.datetime.strptime(self.measured_at, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=_dt.UTC)
        except ValueError:
            return math.inf
        return ((now or _dt.datetime.now(_dt.UTC)) - t).total_seconds()


@dataclass
class CameraEntry:
    """Stereo camera registration: ``T_display_camera`` (4, 4) left optical frame in the display frame, m;
    ``stereo``: the stereo model that pose was fitted with (dict with ``image_size`` (w, h), K1, D1, K2, D2,
    R, T — the format of :func:`flexsheet.vision.calib_yaml.load_yaml`), or ``None`` to keep the stereo
    file's; ``cov`` (30, 30) or ``None``: covariance of (:func:`stereo_vector` of ``stereo``, the pose as the
    display→left-camera rotation vector and translation), rad/m/px units — the prior later steps refine
    under."""

    T_display_camera: np.ndarray
    provenance: Provenance
    stereo: dict | None = None
    cov: np.ndarray | None = None


@dataclass
class ProjectorEntry:
    """Projector registration: ``K`` (3, 3) px, ``D`` (5,) OpenCV distortion, ``T_display_projector`` (4, 4)
    (columns of R = projector x, y, z axes; translation = projection centre P, m), ``width``/``height`` px."""

    K: np.ndarray
    D: np.ndarray
    T_display_projector: np.ndarray
    width: int
    height: int
    provenance: Provenance

    @property
    def position(self) -> np.ndarray:
        """Projection centre P (3,), m, display frame."""
        return self.T_display_projector[:3, 3].copy()

    def projector(self):
        """The pinhole :class:`flexsheet.model.projector.Projector` of this entry (``D`` is not part of
        it)."""
        return Projector(self.K.copy(), self.T_display_projector[:3, :3].copy(), self.position, self.width,
                         self.height)


@dataclass
class ArmEntry:
    """One arm's registration: ``T_display_base`` (4, 4) the URDF ``base_link`` in the display frame, m;
    ``marker_offset`` (3,) m, the clamp marker in the clamp (tool) frame."""

    T_display_base: np.ndarray
    marker_offset: np.ndarray
    provenance: Provenance


@dataclass
class EyeEntry:
    """The viewer's eye. ``mode`` ``fixed`` (the paper's fixed viewpoint V) or ``tracked`` (V per frame from a
    marker on the stereo glasses; V here is the fallback); ``V`` (3,) m cyclopean eye; ``ipd`` m;
    ``glasses_eye_offset`` (3,) m: the cyclopean eye in the glasses marker frame (tracked mode)."""

    mode: str
    V: np.ndarray
    ipd: float
    provenance: Provenance
    glasses_eye_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class HeadCameraEntry:
    """The head camera (facing the viewer, for the glasses): ``K`` (3, 3) px, ``D`` (5,) OpenCV distortion,
    ``width``/``height`` px, ``T_display_camera`` (4, 4) its optical frame in the display frame, m."""

    K: np.ndarray
    D: np.ndarray
    width: int
    height: int
    T_display_camera: np.ndarray
    provenance: Provenance


@dataclass
class SheetEntry:
    """The sheet's force model identified from pushes (:mod:`flexsheet.calibration.sheet`): the terms of
    :class:`flexsheet.model.tension.SheetMaterial` ``contact_width`` (m), ``contact_growth``,
    ``own_stiffness`` (N), ``own_growth`` (N/m), ``stretching`` (N/m³), ``strain_offset``, ``position_u`` and
    ``position_v``."""

    contact_width: float
    contact_growth: float
    own_stiffness: float
    own_growth: float
    stretching: float
    strain_offset: float
    position_u: float
    position_v: float
    provenance: Provenance

    def material(self, base=None):
        """``base`` (a :class:`~flexsheet.model.tension.SheetMaterial`, default the nominal one) with these
        terms (:func:`flexsheet.calibration.sheet.with_terms`)."""
        return with_terms(self, base)


@dataclass
class DisplayCalib:
    """The whole ``display.yaml`` (module doc). Entries are ``None`` (``arms`` lacks the side) until
    measured."""

    camera: CameraEntry | None = None
    projector: ProjectorEntry | None = None
    arms: dict[str, ArmEntry] = field(default_factory=dict)
    eye: EyeEntry | None = None
    path: str = ""
    head_camera: HeadCameraEntry | None = None
    sheet: SheetEntry | None = None

    def _entry(self, name: str):
        if name.startswith("arms."):
            return self.arms.get(name.split(".", 1)[1])
        return getattr(self, name)

    def missing(self, names=ENTRIES) -> list[str]:
        """Names (of :data:`ENTRIES`) that have no entry."""
        return [n for n in names if self._entry(n) is None]

    def stale(self, max_age_s: float, names=ENTRIES, now: _dt.datetime | None = None) -> list[str]:
        """Names whose entry is older than ``max_age_s`` seconds (or was never measured: ``source:
        nominal``)."""
        out = []
        for n in names:
            e = self._entry(n)
            if e is not None and (e.provenance.source == "nominal" or e.provenance.age_s(now) > max_age_s):
                out.append(n)
        return out

    def require(self, *names: str, max_age_s: float | None = None) -> DisplayCalib:
        """Raise ``ValueError`` naming the file and the entries that are missing (or stale, when ``max_age_s``
        is given); returns ``self`` otherwise. ``names`` default to every entry but the :data:`OPTIONAL`
        ones."""
        names = names or tuple(n for n in ENTRIES if n not in OPTIONAL)
        bad = [n for n in names if n not in ENTRIES]
        if bad:
            raise ValueError(f"unknown display calibration entries {bad}; known: {list(ENTRIES)}")
        miss = self.missing(names)
        if miss:
            raise ValueError(f"{self.path or 'display calibration'}: missing entries {miss} "
                             f"(run `flexsheet calibrate ...` for them, see docs/calibration.md)")
        if max_age_s is not None:
            old = self.stale(max_age_s, names)
            if old:
                raise ValueError(f"{self.path or 'display calibration'}: stale entries {old} "
                                 f"(older than {max_age_s:.0f} s or nominal); re-run their calibration")
        return self

    def merged(self, other: DisplayCalib) -> DisplayCalib:
        """A copy with every entry that ``other`` has replacing this one's."""
        arms = dict(self.arms)
        arms.update(other.arms)
        return DisplayCalib(other.camera or self.camera, other.projector or self.projector, arms,
                            other.eye or self.eye, other.path or self.path,
                            other.head_camera or self.head_camera,
                            other.sheet or self.sheet)


def nominal_display_calib() -> DisplayCalib:
    """The display as the code's constants describe it (nothing measured; every provenance ``source:
    nominal``).

    Camera: the shipped XIMEA stereo calibration mounted at :func:`flexsheet.vision.camera_model.look_at`
    (``DEFAULT_CAMERA_POSITION``); projector: :meth:`flexsheet.model.projector.Projector.default`; arms:
    :data:`flexsheet.model.geometry.LEFT_BASE`/``RIGHT_BASE`` with :data:`NOMINAL_CLAMP_MARKER`; eye: the
    paper's fixed V (:data:`flexsheet.model.geometry.EYE`). Estimators start from these; the twin's truth is
    drawn around them (:mod:`flexsheet.twin.truth`).
    """
    nominal = Provenance("nominal (code constants)", source="nominal")
    cal = camera_model("ximea")
    stereo = {k: (np.array(cal[k], float) if k != "image_size" else tuple(cal[k]))
              for k in ("image_size", "K1", "D1", "K2", "D2", "R", "T")}
    cam = CameraEntry(look_at(DEFAULT_CAMERA_POSITION), nominal, stereo)
    p = Projector.default()
    proj = ProjectorEntry(p.K.copy(), np.zeros(5), pose_from_rt(p.R, p.position), p.width, p.height, nominal)
    arms = {side: ArmEntry(geometry.pose_matrix(*b), np.array(NOMINAL_CLAMP_MARKER, float), nominal)
            for side, b in (("left", LEFT_BASE), ("right", RIGHT_BASE))}
    eye = EyeEntry("fixed", geometry.EYE.copy(), NOMINAL_IPD, nominal)
    return DisplayCalib(cam, proj, arms, eye)


