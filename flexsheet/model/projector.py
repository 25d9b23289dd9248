"""The projector model: a pinhole calibrated to the imaginary screen, and the viewer's eye positions.

Pure (numpy). Frames: ``display`` (see :mod:`flexsheet.model.geometry`). Source: Furukawa et al. §IV
(projector 1000 mm behind and 250 mm below the screen, 0.7 mm per pixel on the screen, §VI); pinhole model
after Hartley & Zisserman, *Multiple View Geometry*, §6.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.model import geometry

__all__ = ["Projector", "eye_positions"]


@dataclass(frozen=True)
class Projector:
    """Pinhole projector calibrated to the imaginary screen.

    ``K`` (3, 3) intrinsics, px; ``R`` (3, 3) columns = projector x (image right), y (image down), z (optical
    axis) in the display frame; ``position`` (3,) light source P, m; ``width``, ``height`` px.
    """

    K: np.ndarray
    R: np.ndarray
    position: np.ndarray
    width: int = 1024
    height: int = 768

    @classmethod
    def default(cls, width: int = 1024, height: int = 768, pixel: float = geometry.PIXEL_ON_SCREEN,
                position=geometry.PROJECTOR) -> Projector:
        """The paper's rear projector: at P, optical axis +x (perpendicular to the screen), lens shift so that
        the image centre lands on the screen origin, ``pixel`` m per pixel on the screen (0.7 mm, §VI)."""
        if width < 1 or height < 1:
            raise ValueError(f"width/height must be >= 1, got {width}x{height}")
        if not (pixel > 0.0 and math.isfinite(pixel)):
            raise ValueError(f"pixel must be > 0, got {pixel!r}")
        p = np.asarray(position, dtype=float)
        dist = -p[0]
        if dist <= 0.0:
            raise ValueError(f"projector position must be behind the screen (x < 0), got {p.tolist()}")
        f = dist / pixel
        # seen from behind, image right is -y (display), image down is -z
        R = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
        # image of the screen origin: x_c = R^T (0 - p)
        xc = R.T @ (-p)
        cx = (width - 1) / 2.0 - f * xc[0] / xc[2]
        cy = (height - 1) / 2.0 - f * xc[1] / xc[2]
        K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
        return cls(K, R, p, width, height)

    @classmethod
    def calibrated(cls, width: int = 1024, height: int = 768, pixel: float = geometry.PIXEL_ON_SCREEN,
                   position=geometry.PROJECTOR, K=None, R=None) -> Projector:
        """:meth:`default`, with the intrinsics ``K`` (3, 3) px and/or the axes ``R`` (3, 3) replaced by
        calibrated values where given (None keeps the default). Raises ``ValueError`` naming ``K``/``R`` for a
        wrong shape or non-finite entries, or ``R`` that is not a rotation (tolerance 1e-3)."""
        d = cls.default(width, height, pixel, position)
        if K is None and R is None:
            return d
        K = d.K if K is None else np.asarray(K, dtype=float)
        R = d.R if R is None else np.asarray(R, dtype=float)
        for name, a in (("K", K), ("R", R)):
            if a.shape != (3, 3) or not np.all(np.isfinite(a)):
                raise ValueError(f"projector {name} must be a finite 3x3 matrix, got shape {a.shape}")
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0:
            raise ValueError("projector R must be a rotation (columns = projector axes; a mirrored image is "
                             f"the renderer's mirror_x, not a reflection in R), got {R.round(4).tolist()}")
        return cls(K, R, d.position, width, height)


def eye_positions(eye, ipd: float) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) eye positions (3,) m: V ∓ ipd/2 along y. The user faces −x with +z up, so in the
    right-handed display frame the user's left is −y and the right eye sits at +y. Raises on ipd < 0."""
    if not (math.isfinite(ipd) and ipd >= 0.0):
        raise ValueError(f"ipd must be finite and >= 0, got {ipd!r}")
    v = np.asarray(eye, dtype=float)
    dy = np.array([0.0, ipd / 2.0, 0.0])
    return v - dy, v + dy
