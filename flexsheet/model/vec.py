"""Tiny 3-vector and 3×3 rotation helpers on plain Python float tuples (pure, no numpy).

The planner's per-update path works on (3,) vectors; numpy costs ~1 µs per call on such small arrays,
plain float arithmetic costs ~0.05 µs, so the hot path uses these helpers (measured by
``flexsheet bench planner``). Vectors are ``tuple[float, float, float]``; rotations are row-major
``tuple`` of three row tuples. Frames and units are whatever the caller uses (display frame, m).
"""

from __future__ import annotations

import math

Vec = tuple[float, float, float]
Mat = tuple[Vec, Vec, Vec]

__all__ = ["Vec", "Mat", "add", "sub", "scale", "dot", "cross", "norm", "vnorm", "unit", "axpy", "finite",
           "perp_unit", "rodrigues", "matvec", "rot_from_cols", "cols", "mat_mul_t", "rot_log",
           "min_rotation"]


def add(a: Vec, b: Vec) -> Vec:
    """a + b."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a: Vec, b: Vec) -> Vec:
    """a − b."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(a: Vec, s: float) -> Vec:
    """s·a."""
    return (a[0] * s, a[1] * s, a[2] * s)


def axpy(s: float, x: Vec, y: Vec) -> Vec:
    """s·x + y."""
    return (s * x[0] + y[0], s * x[1] + y[1], s * x[2] + y[2])


def dot(a: Vec, b: Vec) -> float:
    """a · b."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec, b: Vec) -> Vec:
    """a × b."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def norm(a: Vec) -> float:
    """Euclidean length |a|."""
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def vnorm(a) -> float:
    """|a| of a 1-D float64 numpy array, computed as :func:`numpy.linalg.norm` computes it (the square root of
    a·a, the same float) without its dispatch: for small vectors on a hot path."""
    return math.sqrt(a.dot(a))


def unit(a: Vec, eps: float = 1e-12) -> Vec | None:
    """a/|a|, or ``None`` when |a| ≤ eps (direction undefined)."""
    n = norm(a)
    if n <= eps:
        return None
    return (a[0] / n, a[1] / n, a[2] / n)


def finite(a) -> bool:
    """True when every component of the sequence ``a`` is a finite float."""
    try:
        return all(math.isfinite(x) for x in a)
    except TypeError:
        return False


def perp_unit(n: Vec, hint: Vec) -> Vec:
    """Unit vector ⟂ n closest to ``hint`` (Gram–Schmidt); falls back to another axis if hint ∥ n."""
    h = axpy(-dot(hint, n), n, hint)
    u = unit(h, 1e-6)
    if u is not None:
        return u
    for ax in ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)):
        u = unit(axpy(-dot(ax, n), n, ax), 1e-3)
        if u is not None:
            return u
    raise ValueError(f"n must be a unit vector, got {n!r}")  # pragma: no cover - unreachable for unit n


def rodrigues(axis: Vec, angle: float, x: Vec) -> Vec:
    """Rotate x about unit ``axis`` by ``angle`` rad (Rodrigues' formula)."""
    c, s = math.cos(angle), math.sin(angle)
    k = axis
    kx = cross(k, x)
    kd = dot(k, x) * (1.0 - c)
    return (x[0] * c + kx[0] * s + k[0] * kd, x[1] * c + kx[1] * s + k[1] * kd,
            x[2] * c + kx[2] * s + k[2] * kd)


def matvec(R: Mat, x: Vec) -> Vec:
    """R x for a row-major 3×3 tuple."""
    return (dot(R[0], x), dot(R[1], x), dot(R[2], x))


def rot_from_cols(c0: Vec, c1: Vec, c2: Vec) -> Mat:
    """Row-major matrix whose columns are c0, c1, c2."""
    return ((c0[0], c1[0], c2[0]), (c0[1], c1[1], c2[1]), (c0[2], c1[2], c2[2]))


def cols(R: Mat) -> tuple[Vec, Vec, Vec]:
    """The three columns of a row-major 3×3 tuple."""
    return ((R[0][0], R[1][0], R[2][0]), (R[0][1], R[1][1], R[2][1]), (R[0][2], R[1][2], R[2][2]))


def mat_mul_t(A: Mat, B: Mat) -> Mat:
    """Aᵀ B."""
    ca, cb = cols(A), cols(B)
    return tuple(tuple(dot(ca[i], cb[j]) for j in range(3)) for i in range(3))  # type: ignore[return-value]


def rot_log(R: Mat) -> Vec:
    """Rotation vector (axis·angle, rad) of a rotation matrix R (SO(3) log); angle in [0, π]."""
    tr = R[0][0] + R[1][1] + R[2][2]
    c = max(-1.0, min(1.0, 0.5 * (tr - 1.0)))
    w = (R[2][1] - R[1][2], R[0][2] - R[2][0], R[1][0] - R[0][1])
    s = 0.5 * norm(w)
    ang = math.atan2(s, c)
    if ang < 1e-9:
        return (0.5 * w[0], 0.5 * w[1], 0.5 * w[2])
    if math.pi - ang < 1e-6:   # near π: axis from the symmetric part
        d = (R[0][0], R[1][1], R[2][2])
        i = max(range(3), key=lambda j: d[j])
        col = [0.5 * (R[i][j] + R[j][i]) for j in range(3)]
        col[i] = math.sqrt(max(0.0, 0.5 * (d[i] + 1.0)))
        a = unit(tuple(col))  # type: ignore[arg-type]
        return scale(a, ang) if a is not None else (0.0, 0.0, 0.0)
    k = ang / (2.0 * s)
    return (w[0] * k, w[1] * k, w[2] * k)


def min_rotation(a: Vec, b: Vec) -> tuple[Vec, float] | None:
    """Axis and angle of the smallest rotation taking unit ``a`` to unit ``b``; ``None`` if a ≈ b or a ≈
    −b."""
    ax = cross(a, b)
    s = norm(ax)
    c = dot(a, b)
    if s < 1e-12:
        return None
    return ((ax[0] / s, ax[1] / s, ax[2] / s), math.atan2(s, c))
