"""Nonlinear snapshots along a scene's stroke path: the real-time model for scenes with no symmetry
that carries one push onto another (the rounded box, the organ), after Peterlík et al. 2010's precomputed
snapshots: solved states, blended as the cylinder's and the sphere's tables blend theirs.

The cylinder's and the sphere's tables (:mod:`flexsheet.fem.snapshots`, :mod:`flexsheet.fem.sphere_snapshots`)
move a snapshot from one push to the next by the object's symmetry. A general body has none, so this table
holds pushes at stations along the stroke and moves each with the contact:

* **Offline** (:mod:`flexsheet.fem.reference.path_table`): at K **stations** along the stroke (fractions f_0 <
  … < f_K-1 of its arc length; the stroke's start and end included) the scene's hyperelastic body is pushed
  along the inward surface normal 0 → ``depths[-1]`` (the nonlinear reference,
  :func:`flexsheet.fem.reference.scene_reference.scene_reference`), and at every depth d_j the same push is
  solved by the real-time linear model (:class:`flexsheet.fem.scene_model.SceneModel`, its own mesh). The
  table holds, on the real-time model's rendered surface vertices (S, 3):

  - ``correction`` (K, D, S, 3) m: reference displacement − linear displacement (the table is keyed to the
    real-time model it was taken against; attaching it adds that model's station solves back,
    :class:`PathSnapshotModel`'s ``linear``, so the served states are the reference's);
  - ``force_ratio`` / ``stiffness_ratio`` (K, D): the reference's force F and dF/dd (central differences in d)
    over the linear model's at the same push (at d = 0 the first depth's ratio);
  - ``inverted`` (K, D) and ``max_strain`` (K, D): the reference's inverted elements and largest principal
  Green–Lagrange strain.
* **Run time** (:meth:`PathSnapshotModel.lookup`): the finger's contact point is located on the stroke
  (projected onto the segments of a dense path polyline beside its nearest sample: fraction f and lateral
  distance ℓ); inside the table (f within the stations, ℓ ≤ ``reach``, 0 < d ≤ ``depths[-1]``) the served
  surface is **the stations' solved states (the reference's surface displacement) blended in (f, d)** from the
  four neighbouring samples, each station's first moved with the contact; the force and stiffness are the
  linear model's solve of this very push times the bilinearly blended ratios, so the force keeps the linear
  model's spatial detail (an inclusion's stiffness peak between stations). At a station the served surface is
  the reference's (up to float32). The node then puts every vertex left inside the fingertip sphere on it
  (:meth:`flexsheet.fem.scene_model.SceneModel._update_path`). On the stroke the surface never comes from the
  linear solve: its bonded contact set changes a surface node at a time as the finger moves, and the drawn
  surface jumped with it (the rounded box: 6.1 px p99 a frame).
* **A state follows the contact.** A station's state is a dent centred on *its* contact point. Blending two of
  them at fixed vertices puts two half dents either side of a push midway between stations. So each station's
  state is first **moved along the surface with the contact**: at fraction f, vertex v takes R times station
  s's displacement at the rest-surface point nearest to P(f_s) + Rᵀ(v − P(f)) (P: the path polyline; R: the
  least rotation from the station's normal to the path's at f; barycentric on the rendered triangles), then
  the two moved states are blended with weights 1 − a, a. The moves are precomputed when the table is attached
  (``trimesh.proximity.closest_point``), at sub-fractions no more than :data:`SHIFT_STEP` of path apart, as
  one sparse (S, 2S) matrix each, and blended linearly between sub-fractions at run time (one or two sparse
  products: no search per update). At a station the move is the identity. The move turns each station's state
  by the least rotation from its normal to the path's normal there; it follows the contact *along* the path
  only, so the node fades from the states to the linear solve of the push as the contact's lateral offset goes
  from ``reach``/2 to ``reach`` (no jump at the table's side).

Frames and units: display frame, m, N, N/m. Errors: ``ValueError`` naming the field.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.fem.cache import cache_key
from flexsheet.fem.reference.versions import SOLVER_VERSION

__all__ = ["PATH_TABLE_VERSION", "GRID", "REACH", "SHIFT_STEP", "PathSnapshotModel", "least_rotation",
           "path_table_key", "check_path_table", "stiffness_from_force",
           "TABLE_FIELDS"]

PATH_TABLE_VERSION = "path-snap-1"
#: the arrays a path table holds (module doc)
TABLE_FIELDS = ("fractions", "depths", "points", "normals", "rest_vertices", "correction", "force_ratio",
                "stiffness_ratio", "inverted", "max_strain", "reach")


#: the stations' reference: load step and deepest depth (m), mesh sizes (m): h, h_fine along the push path
#: (radius refine_radius, down to path_depth), as the scene FULL run's first level
#: (:mod:`flexsheet.fem.reference.path_table` solves them)
GRID = {"step": 0.0025, "depth_max": 0.05, "h": 0.012, "h_fine": 0.006, "refine_radius": 0.015,
        "path_depth": 0.05}
#: how far off the stroke (m) a contact point may lie and still be served from the table
REACH = 0.004
#: the largest path length (m) between two sub-fractions whose contact-following moves are precomputed
#: (module doc); between them the moved states are blended linearly
SHIFT_STEP = 0.001


def least_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(…, 3, 3) the least rotations taking unit vectors ``a`` (…, 3) to unit vectors ``b`` (…, 3) (broadcast;
    Rodrigues about a × b). Opposite vectors have no least rotation: ``ValueError``."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    v, c = np.cross(a, b), np.einsum("...i,...i->...", a, b)
    if np.any(c <= -1.0 + 1e-9):
        raise ValueError("least_rotation: opposite vectors have no least rotation")
    vx = np.zeros(a.shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2], vx[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    vx[..., 1, 0], vx[..., 2, 0], vx[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return np.eye(3) + vx + (vx @ vx) / (1.0 + c)[..., None, None]


def path_table_key(scene_key: str, realtime_key: str) -> str:
    """The cache/shipped-store key (kind "pathsnap") of a scene's path table: the scene (``Scene.key()``), the
    real-time model it corrects (:attr:`flexsheet.fem.scene_model.SceneModel.cache_key`: mesh, gmsh version,
    reach, finger), the reference solver's version, :data:`GRID` and :data:`REACH` (the stations are in the
    table)."""
    import json

    return cache_key(PATH_TABLE_VERSION, scene_key, realtime_key, SOLVER_VERSION,
                     json.dumps(GRID, sort_keys=True),
                     f"reach={REACH:.9g}")


def stiffness_from_force(force: np.ndarray, depths: np.ndarray) -> np.ndarray:
    """dF/dd (…, D) N/m of ``force`` (…, D) N sampled at ``depths`` (D,) m ascending: second-order central
    differences inside, one-sided at the ends (``numpy.gradient``). Raises ``ValueError`` for fewer than 2
    depths or non-ascending depths."""
    d = np.asarray(depths, float)
    if d.ndim != 1 or len(d) < 2 or np.any(np.diff(d) <= 0):
        raise ValueError(f"depths must be >= 2 ascending values in m, got {np.round(d, 6).tolist()[:8]}")
    return np.gradient(np.asarray(force, float), d, axis=-1, edge_order=2 if len(d) > 2 else 1)


def check_path_table(t: dict) -> None:
    """Raise ``ValueError`` naming the field when the table ``t`` (module doc) is missing an array, has
    inconsistent shapes, non-ascending fractions/depths, depths not starting at 0, or non-finite values."""
    for k in TABLE_FIELDS:
        if k not in t:
            raise ValueError(f"path table: field {k!r} missing")
    fr, d = np.asarray(t["fractions"], float), np.asarray(t["depths"], float)
    if fr.ndim != 1 or len(fr) < 2 or np.any(np.diff(fr) <= 0) or fr[0] < 0 or fr[-1] > 1:
        raise ValueError("path table: fractions must be >= 2 ascending values in [0, 1], got "
                         f"{fr.tolist()[:8]}")
    if d.ndim != 1 or len(d) < 2 or abs(d[0]) > 1e-12 or np.any(np.diff(d) <= 0):
        raise ValueError(f"path table: depths must ascend from 0 m, got {np.round(d, 6).tolist()[:8]}")
    K, D = len(fr), len(d)
    S = np.asarray(t["rest_vertices"]).shape[0]
    shapes = {"points": (K, 3), "normals": (K, 3), "rest_vertices": (S, 3), "correction": (K, D, S, 3),
              "force_ratio": (K, D), "stiffness_ratio": (K, D), "inverted": (K, D), "max_strain": (K, D)}
    for k, sh in shapes.items():
        a = np.asarray(t[k])
        if a.shape != sh:
            raise ValueError(f"path table: {k} has shape {a.shape}, expected {sh}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"path table: {k} holds non-finite values")
    r = float(np.asarray(t["reach"]))
    if not (math.isfinite(r) and 0 < r <= 0.05):
        raise ValueError(f"path table: reach must be in (0, 0.05] m, got {r!r}")


class PathSnapshotModel:
    """Look-ups into a path table (module doc).

    ``table``: the arrays of :data:`TABLE_FIELDS` (checked by :func:`check_path_table`); ``rest_vertices`` (S,
    3) m the real-time model's rendered vertices, which must be the table's (within 1 µm: the table corrects
    that very mesh), and ``faces`` (F, 3) int its rendered triangles (the states move over them); ``path`` (M,
    3) m dense samples of the stroke on the surface and ``path_normals`` (M, 3) its outward unit normals
    there, at ``path_fractions`` (M,) ascending (``Scene.stroke_at``). Raises ``ValueError`` when the table is
    inconsistent, was built on another mesh, or the path samples or faces are bad. Attaching costs one
    ``closest_point`` query per vertex, sub-fraction and
    station (module doc): about 1 s for either shipped table here. ``linear`` (K, D, S, 3) m: the real-time
    model's surface displacement at each station's push and table depth (the solves the table's
    ``correction`` was taken against); the served states are ``linear + correction``."""

    def __init__(self, table: dict, rest_vertices: np.ndarray, faces: np.ndarray, path: np.ndarray,
                 path_normals: np.ndarray, path_fractions: np.ndarray, linear: np.ndarray):
        check_path_table(table)
        rv = np.asarray(rest_vertices, float)
        tv = np.asarray(table["rest_vertices"], float)
        if rv.shape != tv.shape or float(np.abs(rv - tv).max(initial=0.0)) > 1e-6:
            raise ValueError(f"path table: built on another real-time mesh ({tv.shape[0]} rendered vertices) "
                             f"than this model's ({rv.shape[0]}), or they moved by more than 1 um")
        p, pf = np.asarray(path, float), np.asarray(path_fractions, float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or pf.shape != (len(p),) or np.any(np.diff(pf) <= 0):
            raise ValueError(f"path must be (M >= 2, 3) with ascending fractions (M,), got {p.shape} / "
                             f"{pf.shape}")
        pn = np.asarray(path_normals, float)
        if pn.shape != p.shape or not np.all(np.abs(np.linalg.norm(pn, axis=1) - 1.0) < 1e-6):
            raise ValueError(f"path_normals must be unit vectors shaped as path {p.shape}, got {pn.shape}")
        self.fractions = np.asarray(table["fractions"], float)
        self.depths = np.asarray(table["depths"], float)
        self.depth_max = float(self.depths[-1])
        self.reach = float(np.asarray(table["reach"]))
        lin = np.asarray(linear)
        if lin.shape != np.shape(table["correction"]) or not np.all(np.isfinite(lin)):
            raise ValueError(f"linear must be finite, shaped as the table's correction "
                             f"{np.shape(table['correction'])}, got {lin.shape}")
        self.state = np.ascontiguousarray(np.asarray(table["correction"], np.float64) + lin, dtype=np.float32)
        self.force_ratio = np.asarray(table["force_ratio"], float)
        self.stiffness_ratio = np.asarray(table["stiffness_ratio"], float)
        self.inverted = np.asarray(table["inverted"], float)
        self.max_strain = np.asarray(table["max_strain"], float)
        self._path, self._path_n, self._path_f = p, pn, pf
        fc = np.asarray(faces)
        if fc.ndim != 2 or fc.shape[1] != 3 or len(fc) == 0 or fc.min() < 0 or fc.max() >= len(rv):
            raise ValueError(f"faces must be (F >= 1, 3) indices into the {len(rv)} rendered vertices, got "
                             f"shape {fc.shape}")
        self._sub, self._moves, self._turns = self._contact_moves(rv, fc.astype(np.int64))

    def _along(self, samples: np.ndarray, fraction) -> np.ndarray:
        """(…, 3): ``samples`` (M, 3) of the path interpolated linearly at ``fraction`` (…,)."""
        f = np.asarray(fraction, float)
        return np.stack([np.interp(f, self._path_f, samples[:, k]) for k in range(3)], axis=-1)

    def path_point(self, fraction) -> np.ndarray:
        """The path polyline's point(s) (…, 3) m at ``fraction`` (…,) of the stroke (linear between
        samples)."""
        return self._along(self._path, fraction)

    def path_normal(self, fraction) -> np.ndarray:
        """The path's outward unit normal(s) (…, 3) at ``fraction`` (…,) (linear between samples,
        normalised)."""
        n = self._along(self._path_n, fraction)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def _move_targets(self, rv: np.ndarray, g: np.ndarray, f0: float, f1: float) -> tuple[np.ndarray,
                                                                                          np.ndarray]:
        """For each sub-fraction in ``g`` and each of the interval's two stations f0, f1: the turn R (n+1, 2,
        3, 3) that takes the station's normal to the path's normal at g (the least rotation), and the point
        (n+1, 2, S, 3) m whose nearest rest-surface point gives vertex v its moved state, P(f_s) + Rᵀ(v −
        P(g)): the contact's travel along the path and its turn (module doc)."""
        pg, ps = self.path_point(g), self.path_point(np.array([f0, f1]))
        R = least_rotation(self.path_normal(np.array([f0, f1]))[None, :], self.path_normal(g)[:, None])
        x = np.einsum("gsji,gvj->gsvi", R, rv[None] - pg[:, None])          # Rᵀ (v − P(g))
        return R, x + ps[None, :, None]

    def _contact_moves(self, rv: np.ndarray, faces: np.ndarray):
        """Per interval i between stations: its sub-fractions (n_i + 1,), per sub-fraction g one sparse matrix
        (S, 2S) float32 (CSR, 6 entries a row) that maps the two stations' stacked, turned states (2S, 3) to
        their moved sum: row v holds the barycentric weights of the rest-surface point nearest its
        :meth:`_move_targets` point on its triangle's vertices, station s's columns offset by s·S; and the
        turns (n_i + 1, 2, 3, 3) float32 to apply to each station's state first (module doc)."""
        import scipy.sparse as sparse
        import trimesh

        S = len(rv)
        seg = np.linalg.norm(np.diff(self._path, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])          # path length at each path sample
        mesh = trimesh.Trimesh(rv, faces, process=False)
        subs, ys, turns = [], [], []
        for i in range(len(self.fractions) - 1):
            f0, f1 = self.fractions[i], self.fractions[i + 1]
            length = float(np.interp(f1, self._path_f, arc) - np.interp(f0, self._path_f, arc))
            g = np.linspace(f0, f1, max(1, int(math.ceil(length / SHIFT_STEP - 1e-9))) + 1)
            subs.append(g)
            R, y = self._move_targets(rv, g, f0, f1)
            ys.append(y)
            turns.append(R.astype(np.float32))
        flat = np.concatenate([y.reshape(-1, 3) for y in ys])
        cp, _, tri = trimesh.proximity.closest_point(mesh, flat)
        bc = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], cp)
        bc = np.clip(np.nan_to_num(bc, nan=1.0 / 3.0), 0.0, 1.0)
        bc /= bc.sum(axis=1, keepdims=True)
        cols_all, w_all, k, mats = faces[tri], bc.astype(np.float32), 0, []
        indptr = np.arange(0, 6 * S + 1, 6)
        for y in ys:
            n_sub = y.shape[0]
            cols = (cols_all[k:k + n_sub * 2 * S].reshape(n_sub, 2, S, 3)
                    + (np.arange(2) * S)[None, :, None, None])
            w = w_all[k:k + n_sub * 2 * S].reshape(n_sub, 2, S, 3)
            k += n_sub * 2 * S
            mats.append(
                [sparse.csr_matrix((w[g].transpose(1, 0, 2).reshape(-1),
                                    cols[g].transpose(1, 0, 2).reshape(-1),
                                    indptr), shape=(S, 2 * S)) for g in range(n_sub)])
        return subs, mats, turns

    def locate(self, point) -> tuple[float, float]:
        """(fraction along the stroke, lateral distance m) of a contact point (3,) m: its projection onto the
        path polyline's segments beside the nearest sample (continuous in the point)."""
        x = np.asarray(point, float)
        d2 = ((self._path - x) ** 2).sum(axis=1)
        i = int(np.argmin(d2))
        best_f, best = float(self._path_f[i]), float(d2[i])
        for a in (i - 1, i):
            if a < 0 or a + 1 >= len(self._path):
                continue
            seg = self._path[a + 1] - self._path[a]
            t = float(np.clip((x - self._path[a]) @ seg / max(float(seg @ seg), 1e-30), 0.0, 1.0))
            e = x - (self._path[a] + t * seg)
            if float(e @ e) < best:
                best = float(e @ e)
                best_f = float(self._path_f[a] + t * (self._path_f[a + 1] - self._path_f[a]))
        return best_f, math.sqrt(best)

    def covers(self, fraction: float, lateral: float, depth: float) -> bool:
        """Whether a push at ``fraction`` of the stroke, ``lateral`` m off it, ``depth`` m deep lies inside
        the table (between its first and last station, within ``reach``, 0 < depth ≤ the table's deepest)."""
        return bool(self.fractions[0] - 1e-9 <= fraction <= self.fractions[-1] + 1e-9
                    and lateral <= self.reach
                    and 0.0 < depth <= self.depth_max + 1e-9)

    def _cell(self, x: float, grid: np.ndarray) -> tuple[int, float]:
        i = min(max(int(np.searchsorted(grid, x, side="right")) - 1, 0), len(grid) - 2)
        w = (x - float(grid[i])) / float(grid[i + 1] - grid[i])
        return i, min(max(w, 0.0), 1.0)

    def lookup(self, fraction: float, depth: float) -> tuple[np.ndarray, float, float, float, int]:
        """(surface displacement (S, 3) float32 m, force ratio, stiffness ratio, the reference's largest
        strain, its inverted element count) at (``fraction``, ``depth`` m) (clamped to the table): each of the
        two bracketing stations' states, linear in depth, moved with the contact to ``fraction`` (module doc),
        blended with weights 1 − a, a; the ratios, strain and count bilinear between the four samples around
        it. Raises ``ValueError`` for a non-finite argument."""
        if not (math.isfinite(fraction) and math.isfinite(depth)):
            raise ValueError(f"fraction and depth must be finite, got {fraction!r}, {depth!r}")
        i, a = self._cell(fraction, self.fractions)
        j, b = self._cell(depth, self.depths)
        c = self.state
        k, w = self._cell(fraction, self._sub[i])
        s0 = np.float32((1 - a) * (1 - b)) * c[i, j] + np.float32((1 - a) * b) * c[i, j + 1]
        s1 = np.float32(a * (1 - b)) * c[i + 1, j] + np.float32(a * b) * c[i + 1, j + 1]
        mv, tn = self._moves[i], self._turns[i]

        def moved(g: int) -> np.ndarray:
            return mv[g] @ np.concatenate([s0 @ tn[g, 0].T, s1 @ tn[g, 1].T])

        u = moved(k) if w == 0.0 else np.float32(1 - w) * moved(k) + np.float32(w) * moved(k + 1)

        def bl(t):
            return float((1 - a) * ((1 - b) * t[i, j] + b * t[i, j + 1])
                         + a * ((1 - b) * t[i + 1, j] + b * t[i + 1, j + 1]))

        inv = int(round(max(self.inverted[i, j], self.inverted[i, j + 1], self.inverted[i + 1, j],
                            self.inverted[i + 1, j + 1]))) if (a > 0 or b > 0) else int(self.inverted[i, j])
        return (u.astype(np.float32, copy=False), bl(self.force_ratio), bl(self.stiffness_ratio),
                bl(self.max_strain), inv)
