"""The display calibration's file, ``display.yaml`` (format: :mod:`flexsheet.calibration.display_calib`):
written with ``cv2.FileStorage`` so OpenCV reads it back, read with PyYAML's safe loader
(:class:`flexsheet.vision.calib_yaml.CvYamlLoader`) so a hostile file never reaches OpenCV's parser, and every
entry checked (finite, rigid poses, the right shapes) with an error naming the file, key and value."""

from __future__ import annotations

import math
import os

import cv2
import numpy as np

from flexsheet.calibration.display_calib import (
    FORMAT_VERSION,
    ArmEntry,
    CameraEntry,
    DisplayCalib,
    EyeEntry,
    HeadCameraEntry,
    ProjectorEntry,
    Provenance,
    SheetEntry,
)
from flexsheet.calibration.sheet import OPTIONAL_TERMS, TERMS
from flexsheet.model.checks import check_pose
from flexsheet.vision.calib_yaml import read_cv_yaml

__all__ = ["write_display_calib", "load_display_calib"]


# ---------------------------------------------------------------------------------------------------- writing
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
        if calib.head_camera is not None:
            h = calib.head_camera
            fs.startWriteStruct("head_camera", cv2.FileNode_MAP)
            _mat(fs, "K", h.K)
            _mat(fs, "D", h.D)
            fs.write("width", int(h.width))
            fs.write("height", int(h.height))
            _mat(fs, "T_display_camera", h.T_display_camera)
            _write_prov(fs, h.provenance)
            fs.endWriteStruct()
        if calib.sheet is not None:
            fs.startWriteStruct("sheet", cv2.FileNode_MAP)
            for k in TERMS:
                fs.write(k, float(getattr(calib.sheet, k)))
            _write_prov(fs, calib.sheet.provenance)
            fs.endWriteStruct()
    finally:
        fs.release()


# ---------------------------------------------------------------------------------------------------- reading
def _checked_pose(key: str, T, path: str) -> np.ndarray:
    """:func:`flexsheet.model.checks.check_pose` naming the file and key."""
    return check_pose(f"{path}: {key}" if path else key, T)


def _vec(key: str, v, n: int, path: str) -> np.ndarray:
    a = np.asarray(v, float).ravel()
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: {key} must be {n} finite numbers, got shape {a.shape}")
    return a


def _check_intrinsics(name: str, e, path: str) -> None:
    """Entry ``name``'s ``K`` (finite 3x3, positive focal lengths), ``D`` (5) and positive
    ``width``/``height``."""
    K = np.asarray(e.K, float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{path}: {name}.K must be a finite 3x3 matrix with positive focal lengths")
    _vec(f"{name}.D", e.D, 5, path)
    if not (int(e.width) > 0 and int(e.height) > 0):
        raise ValueError(f"{path}: {name}.width/height must be positive, got {e.width}x{e.height}")


def _validate(c: DisplayCalib, path: str) -> None:
    if c.camera is not None:
        _checked_pose("camera.T_display_camera", c.camera.T_display_camera, path)
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
            if (C.shape != (30, 30) or not np.all(np.isfinite(C))
                or np.abs(C - C.T).max() > 1e-9 * max(1.0, np.abs(C).max())):
                raise ValueError(f"{path}: camera.cov must be a finite symmetric 30x30 matrix, got {C.shape}")
    if c.projector is not None:
        p = c.projector
        _checked_pose("projector.T_display_projector", p.T_display_projector, path)
        _check_intrinsics("projector", p, path)
    for side, a in c.arms.items():
        if side not in ("left", "right"):
            raise ValueError(f"{path}: arms.{side}: side must be 'left' or 'right'")
        _checked_pose(f"arms.{side}.T_display_base", a.T_display_base, path)
        _vec(f"arms.{side}.marker_offset", a.marker_offset, 3, path)
    if c.eye is not None:
        if c.eye.mode not in ("fixed", "tracked"):
            raise ValueError(f"{path}: eye.mode must be 'fixed' or 'tracked', got {c.eye.mode!r}")
        _vec("eye.V", c.eye.V, 3, path)
        _vec("eye.glasses_eye_offset", c.eye.glasses_eye_offset, 3, path)
        if not (math.isfinite(c.eye.ipd) and 0.0 <= c.eye.ipd <= 0.1):
            raise ValueError(f"{path}: eye.ipd must be in [0, 0.1] m, got {c.eye.ipd!r}")
    if c.head_camera is not None:
        _checked_pose("head_camera.T_display_camera", c.head_camera.T_display_camera, path)
        _check_intrinsics("head_camera", c.head_camera, path)
    if c.sheet is not None:
        try:
            c.sheet.material()                      # SheetMaterial checks each term and names it
        except ValueError as exc:
            raise ValueError(f"{path}: sheet: {exc}") from None


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
                      str(_get(p, "source", pre, path, str)), int(_get(p, "n_poses", pre, path, int)),
                      residuals)


def load_display_calib(path: str, require: tuple[str, ...] = ()) -> DisplayCalib:
    """Read a ``display.yaml`` written by :func:`write_display_calib` (or by hand in the same layout).

    ``require``: entry names (:data:`ENTRIES`) that must be present. Returns a :class:`DisplayCalib` with
    ``path`` set. Raises ``ValueError`` naming the file and the key when the file is missing, too large, not
    YAML, of another ``format_version``, or an entry is malformed (wrong type, shape, non-finite, not a rigid
    transform) or a required entry is absent.
    """
    doc = read_cv_yaml(path, "display calibration")
    ver = doc.get("format_version")
    if ver != FORMAT_VERSION:
        raise ValueError(f"{path}: format_version must be {FORMAT_VERSION}, got {ver!r:.40}")
    out = DisplayCalib(path=path)

    def mat(d, key, prefix):
        v = _get(d, key, prefix, path, np.ndarray)
        return v

    if "camera" in doc:
        d = _get(doc, "camera", "", path, dict)
        T = _checked_pose("camera.T_display_camera", mat(d, "T_display_camera", "camera."), path)
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
            _checked_pose("projector.T_display_projector", mat(d, "T_display_projector", "projector."), path),
            int(_get(d, "width", "projector.", path, int)), int(_get(d, "height", "projector.", path, int)),
            _read_prov(d, "projector.", path))
    if "arms" in doc:
        arms = _get(doc, "arms", "", path, dict)
        for side in arms:
            if side not in ("left", "right"):
                raise ValueError(f"{path}: arms.{side}: side must be 'left' or 'right'")
            d = _get(arms, side, "arms.", path, dict)
            pre = f"arms.{side}."
            out.arms[side] = ArmEntry(_checked_pose(pre + "T_display_base", mat(d, "T_display_base", pre),
                                                    path),
                                      _vec(pre + "marker_offset", mat(d, "marker_offset", pre), 3, path),
                                      _read_prov(d, pre, path))
    if "eye" in doc:
        d = _get(doc, "eye", "", path, dict)
        off = d.get("glasses_eye_offset", np.zeros(3))
        out.eye = EyeEntry(str(_get(d, "mode", "eye.", path, str)),
                           _vec("eye.V", mat(d, "V", "eye."), 3, path),
                           float(_get(d, "ipd", "eye.", path, float)), _read_prov(d, "eye.", path),
                           _vec("eye.glasses_eye_offset", off, 3, path))
    if "head_camera" in doc:
        d = _get(doc, "head_camera", "", path, dict)
        pre = "head_camera."
        out.head_camera = HeadCameraEntry(
            mat(d, "K", pre), _vec(pre + "D", mat(d, "D", pre), 5, path),
            int(_get(d, "width", pre, path, int)),
            int(_get(d, "height", pre, path, int)),
            _checked_pose(pre + "T_display_camera", mat(d, "T_display_camera", pre), path),
            _read_prov(d, pre, path))
    if "sheet" in doc:
        d = _get(doc, "sheet", "", path, dict)
        out.sheet = SheetEntry(*(float(_get(d, k, "sheet.", path, float)) if k in d or k not in OPTIONAL_TERMS
                                 else 0.0 for k in TERMS), _read_prov(d, "sheet.", path))
    _validate(out, path)
    if require:
        out.require(*require)
    return out
