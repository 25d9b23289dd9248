"""``display.yaml``: the display's registration — where the camera, the projector, the arms and the eye are in the
``display`` frame, and how each was measured (pure: numpy + OpenCV FileStorage + PyYAML).

One file, written by ``flexsheet calibrate camera-pose | projector | arms | eye | display`` and named by a launch
file (``display_calib:``). Each entry is optional while the lab works through the procedures; a consumer asks
for the entries it needs with :meth:`DisplayCalib.require` (missing → ``ValueError`` naming the file and key)
and may refuse stale ones with :meth:`DisplayCalib.stale`.

Layout (OpenCV FileStorage YAML; matrices are ``!!opencv-matrix``, units m / rad / px)::

    format_version: 1
    camera:                       # the stereo camera (left optical frame: +z forward, +x right, +y down)
       T_display_camera: 4x4      # left camera pose in the display frame
       image_width, image_height, K1, D1, K2, D2, R, T   # stereo model refined by the camera-pose fit
       cov: 30x30                 # covariance of (stereo parameters, pose) — optional
       provenance: {method, measured_at, source, n_poses, residuals: {rms_px, residual_mm, ...}}
    projector:
       K: 3x3  D: 5x1  width, height
       T_display_projector: 4x4   # columns of R = projector x (image right), y (image down), z (optical axis);
                                  # translation = the projection centre P
       provenance: {...}
    arms:
       left:  {T_display_base: 4x4, marker_offset: 3x1 (clamp marker in the clamp frame), provenance}
       right: {...}
    eye:
       mode: fixed | tracked
       V: 3x1  ipd: m  glasses_eye_offset: 3x1 (cyclopean eye in the glasses marker frame, tracked mode)
       provenance: {...}

``provenance.measured_at`` is ISO 8601 UTC; ``source`` is ``lab``, ``twin seed N`` or ``nominal``.
The file is written with ``cv2.FileStorage`` (so OpenCV reads it back) and read with PyYAML's safe loader
(the ``!!opencv-matrix`` maps checked by :mod:`flexsheet.vision.stereo_calibration`), so a hostile file never reaches
OpenCV's parser. Frames: :mod:`flexsheet.model.geometry`.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field

import cv2
import numpy as np
import yaml

from flexsheet.model import geometry
from flexsheet.vision.stereo_calibration import MAX_CALIB_BYTES, _CvYamlLoader

__all__ = ["FORMAT_VERSION", "ENTRIES", "NOMINAL_CLAMP_MARKER", "NOMINAL_IPD", "Provenance", "CameraEntry",
           "ProjectorEntry", "ArmEntry", "EyeEntry", "DisplayCalib", "nominal_display_calib", "load_display_calib",
           "write_display_calib", "now_iso", "pose_from_rt", "xyzyaw_from_pose", "BOOTSTRAP_FILE", "STEREO_NAMES",
           "stereo_vector", "stereo_from_vector"]

FORMAT_VERSION = 1
#: entry names, as :meth:`DisplayCalib.require` and the error messages spell them
ENTRIES = ("camera", "projector", "arms.left", "arms.right", "eye")
#: nominal clamp marker (a 10 mm retro-reflective sphere) in the clamp (tool) frame, m: 10 mm toward the user
#: (normal) and 40 mm along axis_v from the middle of the clamped edge (design value; calibrated by ``arms``)
NOMINAL_CLAMP_MARKER = (0.010, 0.0, 0.040)
#: nominal interpupillary distance, m (adult median, Dodgson 2004: 63–64 mm)
NOMINAL_IPD = 0.064


#: bootstrap deviations of the shipped XIMEA stereo calibration (``python -m flexsheet.twin.truth --bootstrap``):
#: the uncertainty the stereo calibration leaves, used as the camera-pose prior and as the truth's spread
BOOTSTRAP_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "vision", "ximea_calib_bootstrap.json")

STEREO_NAMES = [f"{c}_{n}" for c in ("left", "right") for n in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2",
                                                                  "k3")] + ["rx", "ry", "rz", "tx", "ty", "tz"]


def stereo_vector(calib: dict) -> np.ndarray:
    """(24,) parameter vector of a stereo calibration dict: per camera (fx, fy, cx, cy, k1, k2, p1, p2, k3),
    then the left→right rotation as a Rodrigues vector (rad) and T (m)."""
    v = []
    for K, D in ((calib["K1"], calib["D1"]), (calib["K2"], calib["D2"])):
        d = np.zeros(5)
        dd = np.asarray(D, float).ravel()[:5]
        d[:dd.size] = dd
        v += [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d]
    v += list(cv2.Rodrigues(np.asarray(calib["R"], float))[0].ravel()) + list(np.asarray(calib["T"], float).ravel())
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
    T = _check_pose("T", T, "")
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(T[2, 2])))))
    if tilt > max_tilt_deg:
        raise ValueError(f"base is tilted {tilt:.3f} deg > {max_tilt_deg} deg from vertical; use the 4x4 pose")
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
    ``stereo``: the stereo model that pose was fitted with (dict with ``image_size`` (w, h), K1, D1, K2, D2, R,
    T — the format of :func:`flexsheet.vision.stereo_calibration.load_yaml`), or ``None`` to keep the stereo file's;
    ``cov`` (30, 30) or ``None``: covariance of (:func:`stereo_vector` of ``stereo``, the pose as the
    display→left-camera rotation vector and translation), rad/m/px units — the prior later steps refine under."""

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
        """The pinhole :class:`flexsheet.model.projector.Projector` of this entry (``D`` is not part of it)."""
        from flexsheet.model.projector import Projector

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
class DisplayCalib:
    """The whole ``display.yaml`` (module doc). Entries are ``None`` (``arms`` lacks the side) until measured."""

    camera: CameraEntry | None = None
    projector: ProjectorEntry | None = None
    arms: dict[str, ArmEntry] = field(default_factory=dict)
    eye: EyeEntry | None = None
    path: str = ""

    def _entry(self, name: str):
        if name.startswith("arms."):
            return self.arms.get(name.split(".", 1)[1])
        return getattr(self, name)

    def missing(self, names=ENTRIES) -> list[str]:
        """Names (of :data:`ENTRIES`) that have no entry."""
        return [n for n in names if self._entry(n) is None]

    def stale(self, max_age_s: float, names=ENTRIES, now: _dt.datetime | None = None) -> list[str]:
        """Names whose entry is older than ``max_age_s`` seconds (or was never measured: ``source: nominal``)."""
        out = []
        for n in names:
            e = self._entry(n)
            if e is not None and (e.provenance.source == "nominal" or e.provenance.age_s(now) > max_age_s):
                out.append(n)
        return out

    def require(self, *names: str, max_age_s: float | None = None) -> DisplayCalib:
        """Raise ``ValueError`` naming the file and the entries that are missing (or stale, when ``max_age_s``
        is given); returns ``self`` otherwise. ``names`` default to all :data:`ENTRIES`."""
        names = names or ENTRIES
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
                            other.eye or self.eye, other.path or self.path)


def nominal_display_calib() -> DisplayCalib:
    """The display as the code's constants describe it (nothing measured; every provenance ``source: nominal``).

    Camera: the shipped XIMEA stereo calibration mounted at :func:`flexsheet.vision.camera_model.look_at`
    (``DEFAULT_CAMERA_POSITION``); projector: :meth:`flexsheet.model.projector.Projector.default`; arms:
    :data:`flexsheet.arm.kinematics.LEFT_BASE`/``RIGHT_BASE`` with :data:`NOMINAL_CLAMP_MARKER`; eye: the
    paper's fixed V (:data:`flexsheet.model.geometry.EYE`). Estimators start from these; the twin's truth is drawn
    around them (:mod:`flexsheet.twin.truth`).
    """
    from flexsheet.arm.kinematics import LEFT_BASE, RIGHT_BASE
    from flexsheet.model.projector import Projector
    from flexsheet.vision.camera_model import DEFAULT_CAMERA_POSITION, camera_model, look_at

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


# ----------------------------------------------------------------------------------------------------- writing
def _write_prov(fs: cv2.FileStorage, p: Provenance) -> None:
    fs.startWriteStruct("provenance", cv2.FileNode_MAP)
    fs.write("method", str(p.method))
    fs.write("measured_at", str(p.measured_at))
    fs.write("source", str(p.source))
    fs.write("n_poses", int(p.n_poses))
    fs.startWriteStruct("residuals", cv2.FileNode_MAP)
    for k, v in p.residuals.items():
        fs.write(str(k), float(v))
    fs.endWriteStruct()
    fs.endWriteStruct()


def _mat(fs: cv2.FileStorage, name: str, a) -> None:
    arr = np.asarray(a, np.float64)
    fs.write(name, arr.reshape(-1, 1) if arr.ndim == 1 else arr)


def write_display_calib(path: str, calib: DisplayCalib) -> None:
    """Write ``calib`` as an OpenCV FileStorage YAML at ``path`` (layout in the module doc; absent entries are
    left out). Validates every entry first and raises ``ValueError`` naming it."""
    _validate(calib, path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise ValueError(f"cannot write display calibration {path!r}")
    try:
        fs.write("format_version", FORMAT_VERSION)
        if calib.camera is not None:
            c = calib.camera
            fs.startWriteStruct("camera", cv2.FileNode_MAP)
            _mat(fs, "T_display_camera", c.T_display_camera)
            if c.stereo is not None:
                fs.write("image_width", int(c.stereo["image_size"][0]))
                fs.write("image_height", int(c.stereo["image_size"][1]))
                for k in ("K1", "D1", "K2", "D2", "R", "T"):
                    _mat(fs, k, c.stereo[k])
            if c.cov is not None:
                _mat(fs, "cov", c.cov)
            _write_prov(fs, c.provenance)
            fs.endWriteStruct()
        if calib.projector is not None:
            p = calib.projector
            fs.startWriteStruct("projector", cv2.FileNode_MAP)
            _mat(fs, "K", p.K)
            _mat(fs, "D", p.D)
            _mat(fs, "T_display_projector", p.T_display_projector)
            fs.write("width", int(p.width))
            fs.write("height", int(p.height))
            _write_prov(fs, p.provenance)
            fs.endWriteStruct()
        if calib.arms:
            fs.startWriteStruct("arms", cv2.FileNode_MAP)
            for side in ("left", "right"):
                if side in calib.arms:
                    a = calib.arms[side]
                    fs.startWriteStruct(side, cv2.FileNode_MAP)
                    _mat(fs, "T_display_base", a.T_display_base)
                    _mat(fs, "marker_offset", a.marker_offset)
                    _write_prov(fs, a.provenance)
                    fs.endWriteStruct()
            fs.endWriteStruct()
        if calib.eye is not None:
            e = calib.eye
            fs.startWriteStruct("eye", cv2.FileNode_MAP)
            fs.write("mode", e.mode)
            _mat(fs, "V", e.V)
            fs.write("ipd", float(e.ipd))
            _mat(fs, "glasses_eye_offset", e.glasses_eye_offset)
            _write_prov(fs, e.provenance)
            fs.endWriteStruct()
    finally:
        fs.release()


# ----------------------------------------------------------------------------------------------------- reading
def _check_pose(key: str, T, path: str) -> np.ndarray:
    A = np.asarray(T, float)
    where = f"{path}: {key}" if path else key
    if A.shape != (4, 4) or not np.all(np.isfinite(A)):
        raise ValueError(f"{where} must be a finite 4x4 transform, got shape {A.shape}")
    if np.abs(A[3] - (0, 0, 0, 1)).max() > 1e-9:
        raise ValueError(f"{where}: last row must be (0, 0, 0, 1), got {A[3].tolist()}")
    R = A[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise ValueError(f"{where}: rotation block is not a proper rotation (orthonormal, det +1)")
    return A


def _vec(key: str, v, n: int, path: str) -> np.ndarray:
    a = np.asarray(v, float).ravel()
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: {key} must be {n} finite numbers, got shape {a.shape}")
    return a


def _validate(c: DisplayCalib, path: str) -> None:
    if c.camera is not None:
        _check_pose("camera.T_display_camera", c.camera.T_display_camera, path)
        if c.camera.stereo is not None:
            s = c.camera.stereo
            for k, shape in (("K1", (3, 3)), ("K2", (3, 3)), ("R", (3, 3))):
                a = np.asarray(s.get(k, np.nan), float)
                if a.shape != shape or not np.all(np.isfinite(a)):
                    raise ValueError(f"{path}: camera.{k} must be a finite {shape} matrix")
            for k, n in (("D1", 5), ("D2", 5), ("T", 3)):
                _vec(f"camera.{k}", s.get(k, np.nan), n, path)
        if c.camera.cov is not None:
            C = np.asarray(c.camera.cov, float)
            if C.shape != (30, 30) or not np.all(np.isfinite(C)) or np.abs(C - C.T).max() > 1e-9 * max(1.0, np.abs(C).max()):
                raise ValueError(f"{path}: camera.cov must be a finite symmetric 30x30 matrix, got {C.shape}")
    if c.projector is not None:
        p = c.projector
        _check_pose("projector.T_display_projector", p.T_display_projector, path)
        K = np.asarray(p.K, float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"{path}: projector.K must be a finite 3x3 matrix with positive focal lengths")
        _vec("projector.D", p.D, 5, path)
        if not (int(p.width) > 0 and int(p.height) > 0):
            raise ValueError(f"{path}: projector.width/height must be positive, got {p.width}x{p.height}")
    for side, a in c.arms.items():
        if side not in ("left", "right"):
            raise ValueError(f"{path}: arms.{side}: side must be 'left' or 'right'")
        _check_pose(f"arms.{side}.T_display_base", a.T_display_base, path)
        _vec(f"arms.{side}.marker_offset", a.marker_offset, 3, path)
    if c.eye is not None:
        if c.eye.mode not in ("fixed", "tracked"):
            raise ValueError(f"{path}: eye.mode must be 'fixed' or 'tracked', got {c.eye.mode!r}")
        _vec("eye.V", c.eye.V, 3, path)
        _vec("eye.glasses_eye_offset", c.eye.glasses_eye_offset, 3, path)
        if not (math.isfinite(c.eye.ipd) and 0.0 <= c.eye.ipd <= 0.1):
            raise ValueError(f"{path}: eye.ipd must be in [0, 0.1] m, got {c.eye.ipd!r}")


def _get(d: dict, key: str, prefix: str, path: str, kind: type | tuple):
    if not isinstance(d, dict) or key not in d:
        raise ValueError(f"{path}: missing key {prefix}{key}")
    v = d[key]
    if kind is float and type(v) is int:
        v = float(v)
    if not isinstance(v, kind) or isinstance(v, bool):
        raise ValueError(f"{path}: {prefix}{key} has the wrong type ({type(v).__name__})")
    return v


def _read_prov(d: dict, prefix: str, path: str) -> Provenance:
    p = _get(d, "provenance", prefix, path, dict)
    pre = prefix + "provenance."
    res = p.get("residuals", {}) or {}
    if not isinstance(res, dict):
        raise ValueError(f"{path}: {pre}residuals must be a map of numbers")
    residuals = {}
    for k, v in res.items():
        if type(v) not in (int, float) or not math.isfinite(v):
            raise ValueError(f"{path}: {pre}residuals.{k} must be a finite number, got {v!r:.40}")
        residuals[str(k)] = float(v)
    return Provenance(str(_get(p, "method", pre, path, str)), str(_get(p, "measured_at", pre, path, str)),
                      str(_get(p, "source", pre, path, str)), int(_get(p, "n_poses", pre, path, int)), residuals)


def load_display_calib(path: str, require: tuple[str, ...] = ()) -> DisplayCalib:
    """Read a ``display.yaml`` written by :func:`write_display_calib` (or by hand in the same layout).

    ``require``: entry names (:data:`ENTRIES`) that must be present. Returns a :class:`DisplayCalib` with
    ``path`` set. Raises ``ValueError`` naming the file and the key when the file is missing, too large, not
    YAML, of another ``format_version``, or an entry is malformed (wrong type, shape, non-finite, not a rigid
    transform) or a required entry is absent.
    """
    if not os.path.isfile(path):
        raise ValueError(f"display calibration file not found: {path!r}")
    if os.path.getsize(path) > MAX_CALIB_BYTES:
        raise ValueError(f"{path}: display calibration larger than {MAX_CALIB_BYTES} bytes")
    try:
        with open(path, "rb") as fh:
            text = fh.read().decode("utf-8")
        if text.startswith("%YAML"):
            text = text.split("\n", 1)[1] if "\n" in text else ""
        doc = yaml.load(text, Loader=_CvYamlLoader)  # noqa: S506 - a SafeLoader subclass
    except (UnicodeDecodeError, yaml.YAMLError, ValueError, RecursionError) as exc:
        raise ValueError(f"{path}: not a display calibration YAML ({' '.join(str(exc).split())[:200]})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a display calibration YAML (top level is {type(doc).__name__})")
    ver = doc.get("format_version")
    if ver != FORMAT_VERSION:
        raise ValueError(f"{path}: format_version must be {FORMAT_VERSION}, got {ver!r:.40}")
    out = DisplayCalib(path=path)

    def mat(d, key, prefix):
        v = _get(d, key, prefix, path, np.ndarray)
        return v

    if "camera" in doc:
        d = _get(doc, "camera", "", path, dict)
        T = _check_pose("camera.T_display_camera", mat(d, "T_display_camera", "camera."), path)
        stereo = None
        if "K1" in d:
            stereo = {"image_size": (int(_get(d, "image_width", "camera.", path, int)),
                                     int(_get(d, "image_height", "camera.", path, int)))}
            for k in ("K1", "K2", "R"):
                stereo[k] = mat(d, k, "camera.")
            for k, n in (("D1", 5), ("D2", 5), ("T", 3)):
                stereo[k] = _vec(f"camera.{k}", mat(d, k, "camera."), n, path)
        cov = mat(d, "cov", "camera.") if "cov" in d else None
        out.camera = CameraEntry(T, _read_prov(d, "camera.", path), stereo, cov)
    if "projector" in doc:
        d = _get(doc, "projector", "", path, dict)
        out.projector = ProjectorEntry(
            mat(d, "K", "projector."), _vec("projector.D", mat(d, "D", "projector."), 5, path),
            _check_pose("projector.T_display_projector", mat(d, "T_display_projector", "projector."), path),
            int(_get(d, "width", "projector.", path, int)), int(_get(d, "height", "projector.", path, int)),
            _read_prov(d, "projector.", path))
    if "arms" in doc:
        arms = _get(doc, "arms", "", path, dict)
        for side in arms:
            if side not in ("left", "right"):
                raise ValueError(f"{path}: arms.{side}: side must be 'left' or 'right'")
            d = _get(arms, side, "arms.", path, dict)
            pre = f"arms.{side}."
            out.arms[side] = ArmEntry(_check_pose(pre + "T_display_base", mat(d, "T_display_base", pre), path),
                                      _vec(pre + "marker_offset", mat(d, "marker_offset", pre), 3, path),
                                      _read_prov(d, pre, path))
    if "eye" in doc:
        d = _get(doc, "eye", "", path, dict)
        off = d.get("glasses_eye_offset", np.zeros(3))
        out.eye = EyeEntry(str(_get(d, "mode", "eye.", path, str)), _vec("eye.V", mat(d, "V", "eye."), 3, path),
                           float(_get(d, "ipd", "eye.", path, float)), _read_prov(d, "eye.", path),
                           _vec("eye.glasses_eye_offset", off, 3, path))
    _validate(out, path)
    if require:
        out.require(*require)
    return out
