"""Image-distortion correction for a moving, pushed rear-projection sheet (Furukawa et al., §III-C, eqs 1–6).

Notation follows the paper: eye V (``eye``, r_v), projector light source P (``projector``, r_p), imaginary
screen (r_o, n_o), actual screen (r_s, n_s), virtual-object vertex A (r_a). For each vertex:

1. C  = intersection of line V–A with the actual sheet             (eqs 1, 2; parameter s1)
2. C' = intersection of line C–P with the imaginary screen         (eqs 3, 4; parameter s2)
3. A' = intersection of line V–C' with the plane through A ∥ screen (eqs 5, 6; parameter s3)

so that the projector, which assumes the imaginary screen, sends the light for A' to C, where the user sees
A. Three sheet models give C:

* ``flat``:           one plane (r_s, n_s), the pose from the arms (paper §III-C-2);
* ``four_triangle``:  4 triangles (pushed point, corner i, corner i+1) (paper §III-C-3);
* ``fine``:           the pushed sheet's shape (beyond the paper; the renderer's is the gripped sheet's FEM
                      depth table of :mod:`flexsheet.model.sheet_model`), C found by Newton's method on the
                      line V–A.

Stability (each case is defined and tested, tests/unit/rendering/test_correction.py):

* grazing rays: when |(V − A)·n| < ``min_cos`` |V − A| (eq. 2's denominator) or |(C − P)·n_o| <
  ``min_cos`` |C − P| (eq. 4's), the vertex is left uncorrected (output = input) and flagged invalid;
  eq. 6's denominator is the eye's distance to the imaginary screen, checked once (``ValueError``);
* rays that miss the sheet (4-triangle / fine): the vertex is corrected with the extended surface (nearest
  triangle's plane / membrane clamped at the sheet border), continuous with its neighbours, and flagged
  off-sheet (``valid`` False);
* eye on the wrong side of the sheet (or projector on the user's side, so no rear projection): ``ValueError``;
* degenerate triangles (pushed point on a sheet edge, S → 0 makes no triangle degenerate: they only become
  coplanar and the result tends continuously to the flat correction): triangles of area below 1e-12 m² are
  skipped; all four degenerate → ``ValueError``;
* NaN/inf anywhere in the pose or vertices → ``ValueError`` naming the argument.

Every function is vectorised numpy over vertices of shape (N, 3), float64, m, display frame.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model.sheet import SheetSurface

__all__ = ["correct_vertices", "correct_vertices_pushed", "correct_vertices_fine",
           "project_vertices", "MODELS", "DEFAULT_MIN_COS", "choose_sheet_model", "predict_model_errors",
           "land_on_triangles", "land_on_surface", "land_projector_rays", "check_screen", "fan_triangles"]

#: correction models, cheapest first
MODELS = ("none", "flat", "four_triangle", "fine")
#: smallest |cos| between a ray and a surface normal that is still corrected (≈ 1.1° grazing)
DEFAULT_MIN_COS = 0.02
_NEWTON_ITERS = 4  # converges to 1e-9 m in 2 steps for S <= 50 mm (measured)


def _vec(name: str, v) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (3,) vector in m, got {v!r}")
    return a


def _unit(name: str, v) -> np.ndarray:
    a = _vec(name, v)
    n = float(np.linalg.norm(a))
    if n < 1e-12:
        raise ValueError(f"{name} must be non-zero, got {v!r}")
    return a / n


def _verts(vertices) -> np.ndarray:
    a = np.asarray(vertices, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("vertices must be finite, got NaN/inf")
    return a


def check_screen(eye, projector, screen_point, screen_normal):
    """Validate the fixed geometry: eye V (3,) m in front of the imaginary screen (r_o, n_o), projector P (3,)
    m behind it (rear projection). Returns (V, P, r_o, unit n_o) as float64 (3,) arrays. Raises ``ValueError``
    naming the argument for a bad shape, NaN/inf, a zero normal or a point on the wrong side."""
    v = _vec("eye", eye)
    p = _vec("projector", projector)
    ro = _vec("screen_point", screen_point)
    no = _unit("screen_normal", screen_normal)
    if (v - ro) @ no <= 1e-6:
        raise ValueError(f"eye {v.tolist()} must be in front of the imaginary screen (along screen_normal)")
    if (p - ro) @ no >= -1e-6:
        raise ValueError(f"projector {p.tolist()} must be behind the imaginary screen (rear projection)")
    return v, p, ro, no


def _through_screen(a, c, valid, v, p, ro, no, min_cos):
    """Eqs 3–6: from the landing points C (N, 3) to the shifted vertices A' (N, 3); updates ``valid``."""
    dcp = c - p
    den2 = dcp @ no                                                    # eq 4 denominator
    ok2 = np.abs(den2) >= min_cos * np.linalg.norm(dcp, axis=1)
    s2 = np.where(ok2, ((ro - p) @ no) / np.where(ok2, den2, 1.0), 0.0)
    ok2 &= s2 > 0.0                                                    # screen lies on the way P → C
    c_hat = s2[:, None] * c + (1.0 - s2[:, None]) * p                  # eq 4
    den3 = (v - c_hat) @ no  # eq 6 denominator = eye–screen distance
    s3 = ((a - c_hat) @ no) / den3                                     # from eq 5
    a_hat = s3[:, None] * v + (1.0 - s3[:, None]) * c_hat              # eq 6
    valid &= ok2
    return np.where(valid[:, None], a_hat, a), valid


def correct_vertices(vertices, *, eye, projector, screen_point, screen_normal, sheet_point, sheet_normal,
                     min_cos: float = DEFAULT_MIN_COS, return_valid: bool = False):
    """Shift vertices so that their light lands, on a flat tilted sheet, where the eye expects them.

    Paper eqs (1)–(6). ``vertices`` (N, 3) m; ``eye`` V, ``projector`` P, ``screen_point`` r_o,
    ``screen_normal`` n_o (toward the user), ``sheet_point`` r_s, ``sheet_normal`` n_s (toward the user):
    (3,) each, m, display frame (normals need not be unit). Returns A' (N, 3) float64, and if
    ``return_valid`` also a bool (N,) mask (False: grazing ray, vertex returned uncorrected).
    Raises ``ValueError`` naming the argument for bad shapes, NaN/inf, zero normals, an eye that is not in
    front of the sheet and the screen, or a projector that is not behind them.
    """
    a = _verts(vertices)
    v, p, ro, no = check_screen(eye, projector, screen_point, screen_normal)
    rs = _vec("sheet_point", sheet_point)
    ns = _unit("sheet_normal", sheet_normal)
    if (v - rs) @ ns <= 1e-6:
        raise ValueError(f"eye {v.tolist()} is on the wrong side of the sheet (sheet_normal {ns.tolist()})")
    if (p - rs) @ ns >= -1e-6:
        raise ValueError(f"projector {p.tolist()} must be behind the sheet (sheet_normal {ns.tolist()})")
    dva = v - a
    den1 = dva @ ns                                                    # eq 2 into eq 1
    valid = np.abs(den1) >= min_cos * np.linalg.norm(dva, axis=1)
    s1 = np.where(valid, ((rs - a) @ ns) / np.where(valid, den1, 1.0), 0.0)
    c = s1[:, None] * v + (1.0 - s1[:, None]) * a                     # eq 2
    out, valid = _through_screen(a, c, valid, v, p, ro, no, min_cos)
    return (out, valid) if return_valid else out


def fan_triangles(pushed_point, corners, projector):
    """The 4-triangle fan of the pushed sheet (paper §III-C-3): triangle i = (pushed point, corner i, corner
    i+1).

    ``pushed_point`` (3,) m, ``corners`` (4, 3) m in order around it, ``projector`` (3,) m (orients the
    normals toward the user, away from the rear projector). Returns (q (3,), corners (4, 3), unit normals (4,
    3), usable (4,) bool: area above 1e-12 m², polygon normal (3,)); an unusable triangle gets the polygon
    normal. Raises ``ValueError`` for NaN/bad shapes, zero-area corners or all four triangles degenerate."""
    q = _vec("pushed_point", pushed_point)
    cs = np.asarray(corners, dtype=float)
    if cs.shape != (4, 3) or not np.all(np.isfinite(cs)):
        raise ValueError(f"corners must be a finite (4, 3) array in m, got {corners!r}")
    poly_n = np.cross(cs[2] - cs[0], cs[3] - cs[1])
    if np.linalg.norm(poly_n) < 1e-12:
        raise ValueError("corners are degenerate (zero area)")
    if (projector - cs.mean(axis=0)) @ poly_n > 0.0:    # toward the user = away from the rear projector
        poly_n = -poly_n
    poly_n /= np.linalg.norm(poly_n)
    c0, c1 = cs, np.roll(cs, -1, axis=0)
    nrm = np.cross(c0 - q, c1 - q)
    area2 = np.linalg.norm(nrm, axis=1)
    usable = area2 > 2e-12
    if not usable.any():
        raise ValueError("all four triangles are degenerate")
    nrm = np.where(usable[:, None], nrm / np.where(usable, area2, 1.0)[:, None], poly_n)
    nrm = np.where((nrm @ poly_n)[:, None] < 0.0, -nrm, nrm)          # orient toward the user
    return q, cs, nrm, usable, poly_n


def land_on_triangles(a, v, q, cs, nrm, usable, min_cos):
    """Where the line V–A first meets the 4-triangle fan. Returns (C (N,3), ok (N,) not grazing, on (N,))."""
    c0, c1 = cs, np.roll(cs, -1, axis=0)
    dva = v - a                                                        # (N, 3)
    den = dva @ nrm.T                                                  # (N, 4)
    nd = np.linalg.norm(dva, axis=1)[:, None]
    ok = (np.abs(den) >= min_cos * nd) & usable[None, :]
    s1 = np.where(ok, ((q - a) @ nrm.T) / np.where(ok, den, 1.0), 0.0)  # (N, 4)
    x = a[:, None, :] + s1[..., None] * dva[:, None, :]                # (N, 4, 3)
    # barycentric coordinates of x in triangle (q, c0_i, c1_i)
    e1, e2 = c0 - q, c1 - q                                            # (4, 3)
    d = x - q                                                          # (N, 4, 3)
    d11 = (e1 * e1).sum(1)
    d12 = (e1 * e2).sum(1)
    d22 = (e2 * e2).sum(1)
    dd1 = (d * e1).sum(2)
    dd2 = (d * e2).sum(2)
    det = np.where(usable, d11 * d22 - d12 * d12, 1.0)
    b1 = (d22 * dd1 - d12 * dd2) / det
    b2 = (d11 * dd2 - d12 * dd1) / det
    bmin = np.minimum(np.minimum(b1, b2), 1.0 - b1 - b2)
    bmin = np.where(ok, bmin, -np.inf)
    inside = bmin >= -1e-9
    # first hit from the eye = largest s1 among the triangles
    # the line passes inside; else the least-outside one
    score = np.where(inside, 1e6 + s1, bmin)
    k = np.argmax(score, axis=1)
    rows = np.arange(a.shape[0])
    c = x[rows, k]
    good = ok[rows, k]
    return c, good, inside[rows, k]


def correct_vertices_pushed(vertices, *, eye, projector, screen_point, screen_normal, pushed_point, corners,
                            min_cos: float = DEFAULT_MIN_COS, return_valid: bool = False):
    """Correction for the pushed sheet approximated by 4 flat triangles (paper §III-C-3).

    ``pushed_point`` (3,) m: the common vertex (fingertip on the sheet); ``corners`` (4, 3) m: the sheet's
    corners in order around it (from the arms' clamp poses). Triangle i = (pushed_point, corners[i],
    corners[i+1]); each vertex is corrected with eqs (1)–(6) using the triangle that the line eye→vertex
    meets first (seen from the eye). Other arguments and the return value as :func:`correct_vertices`;
    ``valid`` is also False for vertices whose ray misses all four triangles (corrected with the extended
    plane of the nearest triangle). Raises ``ValueError`` for NaN/bad shapes, degenerate corners, all four
    triangles degenerate, or the eye/projector on the wrong side of the corners' plane.
    """
    a = _verts(vertices)
    v, p, ro, no = check_screen(eye, projector, screen_point, screen_normal)
    q, cs, nrm, usable, poly_n = fan_triangles(pushed_point, corners, p)
    if (v - cs.mean(axis=0)) @ poly_n <= 1e-6 or (v - q) @ poly_n <= 1e-6:
        raise ValueError(f"eye {v.tolist()} is on the wrong side of the sheet")
    if (p - cs.mean(axis=0)) @ poly_n >= -1e-6:
        raise ValueError(f"projector {p.tolist()} must be behind the sheet")
    c, ok, on = land_on_triangles(a, v, q, cs, nrm, usable, min_cos)
    out, valid = _through_screen(a, c, ok.copy(), v, p, ro, no, min_cos)
    valid &= on
    return (out, valid) if return_valid else out


def land_on_surface(a, v, sheet: SheetSurface, iters: int = _NEWTON_ITERS):
    """Intersection C of the lines V–A (A: (N, 3)) with the (membrane) sheet surface, by Newton's method.

    Starts from the flat-plane intersection; ``iters`` fixed Newton steps on h(t) = depth(t) − w(u(t), v(t))
    along the unit ray from V. Returns (C (N, 3), converged (N,) |h| < 1e-7 m, on (N,) inside the sheet,
    cosines (N,) of the ray with the plane normal)."""
    n, eu, ev, o = sheet.normal, sheet.axis_u, sheet.axis_v, sheet.origin
    d = a - v
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    dn = -(d @ n)                                                      # > 0 for rays toward the sheet
    cos = np.abs(dn)
    safe = np.where(cos > 1e-9, dn, 1.0)
    t = ((v - o) @ n) / safe                                           # flat-plane intersection
    du, dv = d @ eu, d @ ev
    pu0, pv0 = (v - o) @ eu, (v - o) @ ev
    m = sheet.membrane
    h = np.zeros_like(t)
    if m is not None:
        for _ in range(iters):
            w, wu, wv = m.deflection_grad(pu0 + t * du, pv0 + t * dv)
            h = (-(v - o) @ n + t * dn) - w
            dh = dn - wu * du - wv * dv
            dh = np.where(np.abs(dh) > 1e-9, dh, 1e-9)
            t = t - np.clip(h / dh, -0.1, 0.1)
        w = m.deflection(pu0 + t * du, pv0 + t * dv)
        h = (-(v - o) @ n + t * dn) - w
    c = v + t[:, None] * d
    uu, vv = pu0 + t * du, pv0 + t * dv
    on = (np.abs(uu) <= sheet.half_span) & (np.abs(vv) <= sheet.half_width)
    return c, np.abs(h) < 1e-7, on, cos


def correct_vertices_fine(vertices, *, eye, projector, screen_point, screen_normal, sheet: SheetSurface,
                          min_cos: float = DEFAULT_MIN_COS, return_valid: bool = False):
    """Correction with the fine membrane model of the pushed sheet (beyond the paper).

    C is the first intersection of line V–A with ``sheet`` (a :class:`SheetSurface` whose ``membrane`` gives
    the deflection; None → flat, identical to :func:`correct_vertices`), found by Newton's method; then
    eqs (3)–(6). Returns as :func:`correct_vertices`; ``valid`` is False for grazing rays, rays off the sheet,
    or Newton not converged (|residual| ≥ 1e-7 m: vertex returned uncorrected). Raises ``ValueError`` for bad
    input or an eye/projector on the wrong side of the sheet plane.
    """
    a = _verts(vertices)
    v, p, ro, no = check_screen(eye, projector, screen_point, screen_normal)
    if not isinstance(sheet, SheetSurface):
        raise ValueError(f"sheet must be a SheetSurface, got {type(sheet).__name__}")
    if (v - sheet.origin) @ sheet.normal <= 1e-6:
        raise ValueError(f"eye {v.tolist()} is on the wrong side of the sheet")
    if (p - sheet.origin) @ sheet.normal >= -1e-6:
        raise ValueError(f"projector {p.tolist()} must be behind the sheet")
    c, conv, on, cos = land_on_surface(a, v, sheet)
    ok = conv & (cos >= min_cos)
    c = np.where(ok[:, None], c, a)
    out, valid = _through_screen(a, c, ok.copy(), v, p, ro, no, min_cos)
    valid &= on
    return (out, valid) if return_valid else out


def project_vertices(vertices, *, eye, screen_point, screen_normal) -> np.ndarray:
    """Central projection of vertices (N, 3) from ``eye`` onto the imaginary screen (paper's point B), (N, 3)
    m.

    Raises ``ValueError`` if a vertex lies in the plane through the eye parallel to the screen."""
    a = _verts(vertices)
    v = _vec("eye", eye)
    ro = _vec("screen_point", screen_point)
    no = _unit("screen_normal", screen_normal)
    den = (a - v) @ no
    if np.any(np.abs(den) < 1e-12):
        raise ValueError("a vertex lies in the eye's plane parallel to the screen")
    s = ((ro - v) @ no) / den
    return v + s[:, None] * (a - v)


def predict_model_errors(depth: float, *, eye, projector, screen_point, screen_normal, probes,
                         sheet: SheetSurface, reference, min_cos: float = DEFAULT_MIN_COS) -> dict[str,
                                                                                                   float]:
    """Predicted image error (m, max over ``probes``) of each model against the renderer's pushed-sheet model.

    ``probes`` (N, 3) m are object points to check (e.g. the silhouette); ``sheet`` is the unpushed sheet pose
    and ``depth`` (m, ≥ 0) the push at its centre. The error of a model is the largest distance, on the
    imaginary screen as seen from the eye, between where its shifted vertex's light lands on the reference
    shape and where the eye expects the vertex. The reference (and the ``fine`` model's shape) is
    ``reference(sheet, depth)`` → a membrane-like shape pushed at the centre (the renderer's:
    :meth:`flexsheet.model.sheet_model.NominalSheetModel.shape`); at depth 0 the flat sheet. Used by
    :func:`choose_sheet_model`. Raises ``ValueError`` on bad input.
    """
    if not (math.isfinite(depth) and depth >= 0.0):
        raise ValueError(f"depth must be finite and >= 0, got {depth!r}")
    v, p, ro, no = check_screen(eye, projector, screen_point, screen_normal)
    probes = _verts(probes)
    mem = reference(sheet, depth) if depth > 0.0 else None
    true = SheetSurface(sheet.origin, sheet.normal, sheet.axis_u, sheet.half_span, sheet.half_width, mem)
    want = project_vertices(probes, eye=v, screen_point=ro, screen_normal=no)
    common = dict(eye=v, projector=p, screen_point=ro, screen_normal=no, min_cos=min_cos)
    shifted = {
        "none": probes,
        "flat": correct_vertices(probes, sheet_point=sheet.origin, sheet_normal=sheet.normal, **common),
        "four_triangle": correct_vertices_pushed(probes, pushed_point=true.pushed_point,
                                                 corners=sheet.corners,
                                                 **common),
        "fine": correct_vertices_fine(probes, sheet=true, **common),
    }
    out = {}
    for name, ah in shifted.items():
        b = project_vertices(ah, eye=v, screen_point=ro, screen_normal=no)      # where the projector aims
        c = land_projector_rays(b, p, true)                                      # where the light lands
        seen = project_vertices(c, eye=v, screen_point=ro, screen_normal=no)
        out[name] = float(np.max(np.linalg.norm(seen - want, axis=1)))
    return out


def land_projector_rays(targets, projector, sheet: SheetSurface) -> np.ndarray:
    """Where the projector's rays P→target (targets (N, 3) on the imaginary screen) land on ``sheet``, (N, 3).

    Newton on the membrane from the flat-plane hit (same solver as the fine correction; the measurement
    camera uses an independent grid/bisection tracer instead)."""
    c, _, _, _ = land_on_surface(np.asarray(targets, dtype=float), np.asarray(projector, dtype=float), sheet)
    return c


def choose_sheet_model(depth: float, table: dict[str, list[tuple[float, float]]],
                 target: float = 0.0007, models: tuple[str, ...] = MODELS) -> str:
    """Cheapest correction model whose predicted error at push ``depth`` (m) is ≤ ``target`` (m).

    ``table`` maps model name → sorted [(depth m, predicted error m), ...] (from :func:`predict_model_errors`
    over a range of depths); errors are interpolated linearly in depth. Models are tried cheapest first
    (``MODELS`` order, restricted to ``models``); if none meets the target, the one with the smallest
    predicted error is returned. Raises ``ValueError`` for a non-finite/negative depth or target, or an empty
    table.
    """
    if not (math.isfinite(depth) and depth >= 0.0):
        raise ValueError(f"depth must be finite and >= 0, got {depth!r}")
    if not (math.isfinite(target) and target > 0.0):
        raise ValueError(f"target must be finite and > 0, got {target!r}")
    if not table:
        raise ValueError("table must not be empty")
    best, best_err = None, math.inf
    for name in MODELS:
        if name not in table or name not in models:
            continue
        pts = np.asarray(table[name], dtype=float)
        err = float(np.interp(depth, pts[:, 0], pts[:, 1]))
        if err <= target:
            return name
        if err < best_err:
            best, best_err = name, err
    return best
