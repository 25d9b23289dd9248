"""The viewer's eye for the image correction: the paper's fixed viewpoint V, or eyes that follow tracked
glasses.

* ``fixed`` (Furukawa et al. §IV): V from ``display.yaml`` (default 400 mm in front of the sheet centre); the
  left/right eyes sit ± IPD/2 along +y (:func:`flexsheet.model.projector.eye_positions`).
* ``tracked`` (beyond the paper): three or more markers on the stereo glasses, triangulated by the same stereo
  camera, give the glasses' pose (:func:`glasses_pose`, Kabsch/Umeyama least-squares rigid fit). The cyclopean
  eye sits at a fixed offset in the glasses frame (:func:`glasses_eye_offset`, measured once with the viewer
  in the reference position), and the eyes at ± IPD/2 along the glasses' x axis (from the right lens to the
  left lens): :func:`flexsheet.vision.glasses.tracked_eyes`. The correction then follows the viewer's head.

Frames: ``display`` (:mod:`flexsheet.model.geometry`); the glasses frame: x from the right to the left lens,
y up, z = x × y (toward the sheet when worn). Units m.
"""

from __future__ import annotations

import numpy as np

from flexsheet.calibration.display_calib import NOMINAL_IPD, EyeEntry, Provenance
from flexsheet.model import geometry

__all__ = ["fixed_eye", "glasses_pose", "glasses_eye_offset", "tracked_eye_entry"]


def _vec3(name: str, v) -> np.ndarray:
    a = np.asarray(v, float).ravel()
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers (m), got {v!r}")
    return a


def _ipd(ipd: float) -> float:
    if not (np.isfinite(ipd) and 0.0 <= ipd <= 0.1):
        raise ValueError(f"ipd must be in [0, 0.1] m, got {ipd!r}")
    return float(ipd)


def fixed_eye(V=geometry.EYE, ipd: float = NOMINAL_IPD, method: str = "fixed viewpoint (paper §IV)",
              source: str = "lab") -> EyeEntry:
    """``display.yaml`` eye entry for the fixed viewpoint ``V`` (3,) m with interpupillary distance ``ipd`` m.
    Raises ``ValueError`` on a bad V or ipd, or a V not in front of the sheet (x ≤ 0)."""
    v = _vec3("V", V)
    if v[0] <= 0.0:
        raise ValueError(f"V must be in front of the sheet (x > 0), got {v.tolist()}")
    return EyeEntry("fixed", v, _ipd(ipd), Provenance(method, source=source))


def glasses_pose(markers_display, model_points) -> np.ndarray:
    """Least-squares rigid pose T_display_glasses (4, 4) mapping the glasses' marker layout ``model_points``
    (K, 3) m (glasses frame) onto their triangulated positions ``markers_display`` (K, 3) m.

    Kabsch/Umeyama (Umeyama, IEEE PAMI 13(4), 1991) without scale. Raises ``ValueError`` with fewer than 3
    markers, mismatched shapes, non-finite values, or (nearly) collinear markers."""
    A = np.asarray(model_points, float)
    B = np.asarray(markers_display, float)
    if A.ndim != 2 or A.shape[1] != 3 or A.shape != B.shape or len(A) < 3:
        raise ValueError(f"need >= 3 matching (K, 3) marker arrays, got {A.shape} and {B.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise ValueError("marker positions must be finite")
    ca, cb = A.mean(0), B.mean(0)
    H = (A - ca).T @ (B - cb)
    U, S, Vt = np.linalg.svd(H)
    if S[1] < 1e-6 * max(S[0], 1e-12):
        raise ValueError("glasses markers are collinear: the pose is undetermined")
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = cb - R @ ca
    return T


def glasses_eye_offset(T_display_glasses: np.ndarray, V_reference=geometry.EYE) -> np.ndarray:
    """The cyclopean eye in the glasses frame (3,) m, from one capture with the viewer's eye at the reference
    ``V_reference`` (3,) m (e.g. the chin rest that defines the paper's V)."""
    T = np.asarray(T_display_glasses, float)
    return T[:3, :3].T @ (_vec3("V_reference", V_reference) - T[:3, 3])


def tracked_eye_entry(V_fallback, ipd: float, eye_offset, source: str = "lab") -> EyeEntry:
    """``display.yaml`` eye entry for ``eye: tracked`` (``V_fallback`` used while the glasses are not
    seen)."""
    e = fixed_eye(V_fallback, ipd, "tracked glasses (fallback V)", source)
    return EyeEntry("tracked", e.V, e.ipd, Provenance("tracked glasses markers (Kabsch), eye offset in the "
                                                      "glasses frame", source=source),
                    _vec3("eye_offset", eye_offset))
