"""The stereo calibration's file: OpenCV ``FileStorage`` YAML written with ``cv2.FileStorage`` (so OpenCV
reads it back) and read with PyYAML's safe loader (:class:`CvYamlLoader`: the ``!!opencv-matrix`` maps become
checked numpy arrays), so a hostile file never reaches OpenCV's parser. Units: px (intrinsics), m (T)."""

from __future__ import annotations

import os

import cv2
import numpy as np
import yaml

__all__ = ["write_yaml", "load_yaml", "read_cv_yaml", "CvYamlLoader", "MAX_CALIB_BYTES"]


_MATS = ("K1", "D1", "K2", "D2", "R", "T", "E", "F", "R1", "R2", "P1", "P2", "Q", "per_pair_rms_px",
         "T_display_camera")


_SCALARS = ("rms_left_px", "rms_right_px", "rms_px")


def write_yaml(path: str, calib: dict) -> None:
    """Write a calibration dict (see module doc; e.g. :meth:`StereoCalibrationResult.as_dict`) as an OpenCV
    FileStorage YAML at ``path``. Matrices are written as ``!!opencv-matrix``; ``T``, ``D1``, ``D2`` as column
    vectors. Raises ``ValueError`` if a required key (``image_size``, K1, D1, K2, D2, R, T) is missing."""
    for key in ("image_size", "K1", "D1", "K2", "D2", "R", "T"):
        if key not in calib:
            raise ValueError(f"calibration dict lacks required key {key!r}")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    try:
        fs.write("image_width", int(calib["image_size"][0]))
        fs.write("image_height", int(calib["image_size"][1]))
        for key in _MATS:
            if key in calib and calib[key] is not None:
                arr = np.asarray(calib[key], np.float64)
                fs.write(key, arr.reshape(-1, 1) if arr.ndim == 1 else arr)
        for key in _SCALARS:
            if key in calib:
                fs.write(key, float(calib[key]))
        for key in ("used", "skipped"):
            if calib.get(key):
                fs.write(key, ",".join(calib[key]))
    finally:
        fs.release()


class CvYamlLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """PyYAML loader for OpenCV FileStorage YAML: ``!!opencv-matrix`` maps become checked numpy arrays. The
    safe loader's rules, parsed by libyaml where PyYAML was built with it (a calibration with its
    per-pixel tables is ~10× faster to read), else by PyYAML's own parser."""


def _cv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> np.ndarray:
    m = loader.construct_mapping(node, deep=True)
    rows, cols, data = m.get("rows"), m.get("cols"), m.get("data")
    if not (type(rows) is int and type(cols) is int and 0 < rows <= 64 and 0 < cols <= 64):
        raise ValueError(f"opencv-matrix rows/cols must be ints in 1..64, got rows={rows!r:.40} "
                         f"cols={cols!r:.40}")
    if m.get("dt") not in ("d", "f"):
        raise ValueError(f"opencv-matrix dt must be 'd' or 'f', got {m.get('dt')!r:.40}")
    if not (isinstance(data, list) and len(data) == rows * cols
            and all(type(v) in (int, float) for v in data)):
        raise ValueError(f"opencv-matrix data must be {rows * cols} numbers")
    a = np.array(data, dtype=np.float64).reshape(rows, cols)
    if not np.all(np.isfinite(a)):
        raise ValueError("opencv-matrix data must be finite")
    return a


CvYamlLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", _cv_matrix)


MAX_CALIB_BYTES = 1 << 20


def read_cv_yaml(path: str, what: str) -> dict:
    """The top-level mapping of the OpenCV FileStorage YAML at ``path`` (``what`` names the file's kind in the
    errors), read with :class:`CvYamlLoader`. Raises ``ValueError`` naming the file when it is missing, larger
    than :data:`MAX_CALIB_BYTES`, not UTF-8, not YAML or not a mapping."""
    if not os.path.isfile(path):
        raise ValueError(f"{what} file not found: {path!r}")
    if os.path.getsize(path) > MAX_CALIB_BYTES:
        raise ValueError(f"{path}: {what} file larger than {MAX_CALIB_BYTES} bytes")
    try:
        with open(path, "rb") as fh:
            text = fh.read().decode("utf-8")
        if text.startswith("%YAML"):  # OpenCV writes "%YAML:1.0" or "%YAML 1.2"; PyYAML wants neither
            text = text.split("\n", 1)[1] if "\n" in text else ""
        doc = yaml.load(text, Loader=CvYamlLoader)  # noqa: S506 - a SafeLoader subclass
    except (UnicodeDecodeError, yaml.YAMLError, ValueError, RecursionError) as exc:
        raise ValueError(f"{path}: not a {what} YAML ({' '.join(str(exc).split())[:200]})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a {what} YAML (top level is {type(doc).__name__})")
    return doc


def load_yaml(path: str) -> dict:
    """Read a calibration YAML written by :func:`write_yaml` (OpenCV FileStorage YAML with the same keys).

    Parsed with PyYAML (``!!opencv-matrix`` checked: int rows/cols in 1..64, ``dt`` d|f, exactly
    rows×cols finite numbers), never handed raw to ``cv2.FileStorage``, so a hostile file cannot reach
    OpenCV's parser. Returns a dict: ``image_size`` (w, h) ints, float64 arrays K1, K2, R (3, 3), D1, D2
    (5,), T (3,) m, and E, F, R1, R2, P1, P2, Q, T_display_camera, per_pair_rms_px when present (missing
    rectification is recomputed with ``cv2.stereoRectify``), plus rms floats. Raises ``ValueError`` naming
    the file and key when the file is missing, too large, not such a YAML, or a key is absent, malformed,
    non-finite or of the wrong shape.
    """
    doc = read_cv_yaml(path, "calibration")
    out: dict = {}
    w, h = doc.get("image_width"), doc.get("image_height")
    if not (type(w) is int and type(h) is int and 0 < w <= 100_000 and 0 < h <= 100_000):
        raise ValueError(f"{path}: image_width/image_height must be positive ints, got {w!r:.40}, {h!r:.40}")
    out["image_size"] = (w, h)
    for key in _MATS:
        if key in doc:
            if not isinstance(doc[key], np.ndarray):
                raise ValueError(f"{path}: {key} must be an opencv-matrix, got {type(doc[key]).__name__}")
            out[key] = doc[key]
    for key in _SCALARS:
        v = doc.get(key, 0.0)
        if type(v) not in (int, float) or not np.isfinite(v):
            raise ValueError(f"{path}: {key} must be a finite number, got {v!r:.40}")
        out[key] = float(v)
    for key in ("used", "skipped"):
        v = doc.get(key, "")
        out[key] = v.split(",") if isinstance(v, str) and v else []
    shapes = {"K1": (3, 3), "K2": (3, 3), "R": (3, 3), "T": (3,), "D1": None, "D2": None}
    for key, shape in shapes.items():
        if key not in out:
            raise ValueError(f"{path}: calibration lacks required key {key!r}")
        if shape == (3,) or shape is None:
            out[key] = out[key].ravel()
        if shape is not None and out[key].shape != shape:
            raise ValueError(f"{path}: {key} must have shape {shape}, got {out[key].shape}")
    for key in ("D1", "D2"):
        d = np.zeros(5)
        d[:min(5, out[key].size)] = out[key][:5]
        out[key] = d
    if "R1" not in out:
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(out["K1"], out["D1"], out["K2"], out["D2"],
                                                    out["image_size"],
                                                    out["R"], out["T"].reshape(3, 1), alpha=0)
        out.update(R1=R1, R2=R2, P1=P1, P2=P2, Q=Q)
    if "E" not in out:
        tx = np.array([[0, -out["T"][2], out["T"][1]], [out["T"][2], 0, -out["T"][0]],
                       [-out["T"][1], out["T"][0], 0]])
        out["E"] = tx @ out["R"]
        out["F"] = np.linalg.inv(out["K2"]).T @ out["E"] @ np.linalg.inv(out["K1"])
    return out
