"""Tetrahedral mesh of the paper's virtual cylinder (pure: gmsh builds it in memory, meshio writes it).

Geometry (display frame, m): cylinder of radius R = 0.025·√2 and length 0.12 with its axis along +y through
O = (−R, 0, 0), so its side surface touches the imaginary screen at x = z = 0 (Furukawa et al. §V, §VI-A;
:mod:`flexsheet.model.geometry`). The finger pushes from +x.

Support (our choice, stated in docs/fem.md): the object rests in a rigid cradle that holds its **back half**:
every boundary node with x ≤ −R (the half of the side surface and end faces away from the user) is fixed.

Refinement: an optional band of element size ``h_fine`` within ``refine_radius`` of the *working arc*, the
circle of the side surface at y = 0 from −``arc_deg`` to +``arc_deg`` around +x (the paper strokes the
cylinder in that plane, Fig. 7). gmsh ``Ball`` fields sampled along the arc are combined with a ``Min`` field
(gmsh reference manual, §"Specifying mesh element sizes").
"""

from __future__ import annotations

import hashlib
import math
import threading
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model.checks import check_positive
from flexsheet.model.geometry import CYLINDER_CENTER, CYLINDER_LENGTH, CYLINDER_RADIUS

__all__ = ["TetMesh", "MeshSpec", "cylinder_tet_mesh", "cylinder_part_mesh", "surface_faces", "write_mesh",
           "arc_points",
           "gmsh_tets", "finish_cylinder_mesh", "orient_tets"]

_GMSH_LOCK = threading.Lock()   # gmsh is a process-wide singleton


@dataclass(frozen=True)
class MeshSpec:
    """Mesh resolution: ``h`` global element size (m), ``h_fine`` size in the refined band (m, ≤ h),
    ``refine_radius`` band half-width around the working arc (m; 0 = no refinement), ``arc_deg`` half-angle of
    the working arc (deg, ≥ 0). Raises ``ValueError`` naming the field on non-positive or inconsistent
    values."""

    h: float = 0.008
    h_fine: float = 0.003
    refine_radius: float = 0.012
    arc_deg: float = 0.0

    def __post_init__(self):
        for name in ("h", "h_fine"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0005 <= v <= 0.05):
                raise ValueError(f"{name} must be in [0.0005, 0.05] m, got {v!r}")
        if self.h_fine > self.h:
            raise ValueError(f"h_fine must be <= h, got h_fine={self.h_fine!r} > h={self.h!r}")
        if not (math.isfinite(self.refine_radius) and 0.0 <= self.refine_radius <= 0.1):
            raise ValueError(f"refine_radius must be in [0, 0.1] m, got {self.refine_radius!r}")
        if not (math.isfinite(self.arc_deg) and 0.0 <= self.arc_deg <= 90.0):
            raise ValueError(f"arc_deg must be in [0, 90] deg, got {self.arc_deg!r}")

    def key(self) -> str:
        """Stable text key of the spec (used in cache keys)."""
        return f"h={self.h:.6g},hf={self.h_fine:.6g},rr={self.refine_radius:.6g},arc={self.arc_deg:.6g}"


@dataclass
class TetMesh:
    """A linear tetrahedral mesh in the display frame.

    ``points`` (N, 3) float64 m; ``tets`` (M, 4) int64 (positively oriented: det > 0); ``faces`` (F, 3) int64
    boundary triangles wound counter-clockwise seen from outside; ``fixed`` (N,) bool, nodes of the support;
    ``spec`` the :class:`MeshSpec` it came from (None for meshes built otherwise); ``radius``/``length``/
    ``center`` the cylinder geometry (m).
    """

    points: np.ndarray
    tets: np.ndarray
    faces: np.ndarray
    fixed: np.ndarray
    spec: MeshSpec | None = None
    radius: float = CYLINDER_RADIUS
    length: float = CYLINDER_LENGTH
    center: np.ndarray = field(default_factory=lambda: CYLINDER_CENTER.copy())

    @property
    def surface_nodes(self) -> np.ndarray:
        """Sorted unique node indices on the boundary, (S,) int64."""
        return np.unique(self.faces)

    def digest(self) -> str:
        """SHA-256 hex digest of points, tets and fixed mask (cache key part)."""
        h = hashlib.sha256()
        for a in (np.ascontiguousarray(self.points, np.float64), np.ascontiguousarray(self.tets, np.int64),
                  np.ascontiguousarray(self.fixed, np.bool_)):
            h.update(a.tobytes())
        return h.hexdigest()


def arc_points(radius: float, center: np.ndarray, arc_deg: float, spacing: float) -> np.ndarray:
    """Points (K, 3) on the side surface at y = center_y along the arc φ ∈ [−arc_deg, arc_deg] around +x,
    where a point is ``center + radius·(cos φ, 0, sin φ)``; at most ``spacing`` m apart (K ≥ 1)."""
    half = math.radians(arc_deg)
    n = max(1, int(math.ceil(2.0 * half * radius / max(spacing, 1e-6))) + 1) if half > 0 else 1
    phis = np.linspace(-half, half, n) if n > 1 else np.zeros(1)
    c = np.asarray(center, float)
    return np.column_stack([c[0] + radius * np.cos(phis), np.full(n, c[1]), c[2] + radius * np.sin(phis)])


def _split_at_rim(gmsh, point, normal, size: float, h: float) -> list[int]:
    """Split the OpenCASCADE solid(s) by the plane through ``point`` (3,) m normal to ``normal`` (3,), so the
    surface is meshed with a line where the plane meets it (the support's rim: a held-to-free transition on a
    mesh line, not between nodes); returns a ``Threshold`` field: ``size`` m on those lines, graded to ``h``
    over 3·``size``. Pieces of the cutting disk outside the solid are removed."""
    occ = gmsh.model.occ
    occ.synchronize()
    vols = gmsh.model.getEntities(3)
    x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(-1, -1)
    big = 2.0 * max(x1 - x0, y1 - y0, z1 - z0) + 0.01
    p = np.asarray(point, float)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    disk = occ.addDisk(float(p[0]), float(p[1]), float(p[2]), big, big)      # in the plane z = p_z
    axis = np.cross([0.0, 0.0, 1.0], n)
    if np.linalg.norm(axis) > 1e-12:
        occ.rotate([(2, disk)], *map(float, p), *map(float, axis), math.acos(float(np.clip(n[2], -1.0, 1.0))))
    occ.fragment(vols, [(2, disk)])
    occ.synchronize()
    loose = [(2, t) for _, t in gmsh.model.getEntities(2) if len(gmsh.model.getAdjacencies(2, t)[0]) == 0]
    if loose:
        occ.remove(loose, recursive=True)
        occ.synchronize()
    rim = set()
    for _, t in gmsh.model.getEntities(2):
        if len(gmsh.model.getAdjacencies(2, t)[0]) != 1:  # the outer boundary's faces only
            continue
        for c in gmsh.model.getAdjacencies(2, t)[1]:
            lo, hi = gmsh.model.getParametrizationBounds(1, abs(int(c)))
            xyz = np.asarray(gmsh.model.getValue(1, abs(int(c)), list(np.linspace(lo[0], hi[0], 7))), float)
            if np.abs((xyz.reshape(-1, 3) - p) @ n).max() < 1e-7:              # a curve in the plane
                rim.add(abs(int(c)))
    if not rim:
        raise RuntimeError("the support's plane does not cut the solid: no rim to mesh")
    dist = gmsh.model.mesh.field.add("Distance")
    gmsh.model.mesh.field.setNumbers(dist, "CurvesList", sorted(rim))
    gmsh.model.mesh.field.setNumber(dist, "Sampling", 400)
    thr = gmsh.model.mesh.field.add("Threshold")
    gmsh.model.mesh.field.setNumber(thr, "InField", dist)
    for name, v in (("SizeMin", size), ("SizeMax", h), ("DistMin", 0.0), ("DistMax", 3.0 * size)):
        gmsh.model.mesh.field.setNumber(thr, name, v)
    return [thr]


def gmsh_tets(model: str, geometry, h: float, h_fine: float, refine_radius: float, centres, what: str,
              extra_balls: tuple = (), rim: tuple | None = None):
    """Run gmsh once: ``geometry(gmsh)`` adds the OpenCASCADE solid, element size ``h`` with ``h_fine`` within
    ``refine_radius`` of each point of ``centres`` (``Ball`` fields under a ``Min``), single-threaded
    Delaunay; ``extra_balls``: further (centres (K, 3) m, radius m, size m) groups of balls under the same
    ``Min``, each graded to ``h`` over its radius; ``rim`` (point (3,) m, normal (3,)): mesh the plane's cut
    of the surface as lines of size ``h_fine`` (:func:`_split_at_rim`, OpenCASCADE solids only). Returns
    (points (N, 3) m, tets (M, 4) int64 into ``points``, unoriented). Raises ``RuntimeError`` naming ``what``
    if gmsh fails or produces no tetrahedra."""
    import gmsh

    with _GMSH_LOCK:
        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.option.setNumber("General.NumThreads", 1)
            gmsh.option.setNumber("Mesh.Algorithm3D", 1)
            gmsh.model.add(model)
            geometry(gmsh)
            gmsh.model.occ.synchronize()
            gmsh.option.setNumber("Mesh.MeshSizeMax", h)
            gmsh.option.setNumber("Mesh.MeshSizeMin", min([h_fine, h] + [b[2] for b in extra_balls]))
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
            gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
            gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
            fields = [] if rim is None else _split_at_rim(gmsh, rim[0], rim[1], h_fine, h)
            for group, radius, size in ((centres, refine_radius, h_fine), *extra_balls):
                for p in group:
                    f = gmsh.model.mesh.field.add("Ball")
                    gmsh.model.mesh.field.setNumber(f, "Radius", radius)
                    gmsh.model.mesh.field.setNumber(f, "Thickness", radius)
                    gmsh.model.mesh.field.setNumber(f, "VIn", size)
                    gmsh.model.mesh.field.setNumber(f, "VOut", h)
                    for k, name in enumerate(("XCenter", "YCenter", "ZCenter")):
                        gmsh.model.mesh.field.setNumber(f, name, float(p[k]))
                    fields.append(f)
            if fields:
                fmin = gmsh.model.mesh.field.add("Min")
                gmsh.model.mesh.field.setNumbers(fmin, "FieldsList", fields)
                gmsh.model.mesh.field.setAsBackgroundMesh(fmin)
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            etypes, _, enodes = gmsh.model.mesh.getElements(3)
        except Exception as exc:  # gmsh raises plain Exception
            raise RuntimeError(f"gmsh failed to mesh {what}: {exc}") from exc
        finally:
            gmsh.finalize()
    if 4 not in list(etypes):
        raise RuntimeError(f"gmsh produced no tetrahedra for {what}")
    conn = np.asarray(enodes[list(etypes).index(4)], dtype=np.int64).reshape(-1, 4)
    pts_all = np.asarray(coords, float).reshape(-1, 3)
    tag_to_row = np.full(int(np.max(tags)) + 1, -1, dtype=np.int64)
    tag_to_row[np.asarray(tags, np.int64)] = np.arange(len(tags))
    used, inv = np.unique(tag_to_row[conn], return_inverse=True)
    return pts_all[used], inv.reshape(-1, 4)


def cylinder_tet_mesh(spec: MeshSpec = MeshSpec(), radius: float = CYLINDER_RADIUS,
                      length: float = CYLINDER_LENGTH,
                      center: np.ndarray = CYLINDER_CENTER) -> TetMesh:
    """Mesh the cylinder (axis +y through ``center``) with gmsh's OpenCASCADE kernel, P1 tetrahedra.

    Returns a :class:`TetMesh` (tetrahedra, not the renderer's triangle surface) with the back-half support
    marked (boundary nodes with x ≤ center_x + 1e-9). Raises ``ValueError`` on bad geometry and
    ``RuntimeError`` if gmsh fails. Source: gmsh Python API (``occ.addCylinder``, ``Ball``/``Min`` size
    fields, ``generate(3)``). Deterministic for a given spec (single-threaded Delaunay with fixed options).
    """
    radius, length = check_positive("radius", radius), check_positive("length", length)
    c = np.asarray(center, float)

    def geometry(gmsh) -> None:
        gmsh.model.occ.addCylinder(c[0], c[1] - length / 2, c[2], 0.0, length, 0.0, radius)

    centres = (arc_points(radius, c, spec.arc_deg, spec.refine_radius / 2)
               if spec.refine_radius > 0 and spec.h_fine < spec.h else [])
    points, tets = gmsh_tets("cylinder", geometry, spec.h, spec.h_fine, spec.refine_radius, centres,
                             f"the cylinder with {spec.key()}")
    return finish_cylinder_mesh(points, tets, radius, length, c, spec)


def _part_geometry(c: np.ndarray, y0: float, radius: float, length: float, half_z: bool,
                   cut_deg: float | None):
    """:func:`cylinder_part_mesh`'s gmsh geometry: the cylinder from ``y0``, cut to z ≥ z_O (``half_z``),
    fragmented by the plane at azimuth ``cut_deg``."""

    def geometry(gmsh) -> None:
        cyl = gmsh.model.occ.addCylinder(c[0], y0, c[2], 0.0, c[1] + length / 2 - y0, 0.0, radius)
        if half_z:
            box = gmsh.model.occ.addBox(c[0] - 2 * radius, y0 - 0.01, c[2], 4 * radius, length + 0.02,
                                        2 * radius)
            gmsh.model.occ.intersect([(3, cyl)], [(3, box)])
        if cut_deg is not None:
            # the plane through the cylinder's axis and the push direction at azimuth cut_deg: fragmenting the
            # solid with it makes two volumes that gmsh meshes
            # conformally, so the mesh has nodes on that plane
            rect = gmsh.model.occ.addRectangle(c[0] - 2 * radius, y0 - 0.01, c[2], 4 * radius, length + 0.02)
            gmsh.model.occ.rotate([(2, rect)], c[0], c[1], c[2], 0.0, 1.0, 0.0, -math.radians(cut_deg))
            vols = gmsh.model.occ.getEntities(3)
            gmsh.model.occ.fragment(vols, [(2, rect)])

    return geometry


def _skin_balls(skin, h_fine: float, refine_deg, radius: float, c: np.ndarray, y0: float,
                half_z: bool) -> tuple:
    """The skin's size balls (centres, radius, size) of :func:`cylinder_part_mesh` (``ValueError`` on bad
    sizes)."""
    size, patch, depth = (float(v) for v in skin)
    if not (math.isfinite(size) and 0.0005 <= size <= h_fine):
        raise ValueError(f"skin size must be in [0.0005, h_fine={h_fine}] m, got {size!r}")
    if not (math.isfinite(patch) and 0 < patch <= radius * math.pi / 2):
        raise ValueError(f"skin patch radius must be in (0, {radius * math.pi / 2:.4g}] m, got {patch!r}")
    if not (math.isfinite(depth) and size <= depth <= radius / 2):
        raise ValueError(f"skin depth must be in [skin size {size:g}, {radius / 2:.4g}] m, got {depth!r}")
    step = depth / 2
    n = int(math.ceil(patch / step))
    if len(refine_deg) * (2 * n + 1) ** 2 > 40000:      # gmsh evaluates every ball at every mesh vertex
        raise ValueError(f"skin patch radius {patch:g} m / depth {depth:g} m needs > 40000 size balls; "
                         "use a thicker skin or a smaller patch")
    pts = []
    for d in refine_deg:
        for i in range(-n, n + 1):          # arc length along the azimuth
            for j in range(-n, n + 1):      # along the axis (y)
                if math.hypot(i, j) * step > patch:
                    continue
                phi = math.radians(d) + i * step / radius
                pts.append(c + np.array([radius * math.cos(phi), j * step, radius * math.sin(phi)]))
    keep = [p for p in pts if p[1] >= y0 - depth and (not half_z or p[2] >= c[2] - depth)]
    return (np.array(keep), depth, size)


def _tip_balls(tip, h_fine: float, refine_deg, radius: float, c: np.ndarray) -> tuple:
    """The tip's size balls (centres, radius, size) of :func:`cylinder_part_mesh` (``ValueError`` on bad
    sizes)."""
    size, rad = (float(v) for v in tip)
    if not (math.isfinite(size) and 0.0005 <= size <= h_fine):
        raise ValueError(f"tip size must be in [0.0005, h_fine={h_fine}] m, got {size!r}")
    if not (math.isfinite(rad) and size <= rad <= radius / 2):
        raise ValueError(f"tip radius must be in [tip size {size:g}, {radius / 2:.4g}] m, got {rad!r}")
    apex = [c + radius * np.array([math.cos(math.radians(d)), 0.0, math.sin(math.radians(d))])
            for d in refine_deg]
    return (np.array(apex), rad, size)


def cylinder_part_mesh(h: float, h_fine: float, refine_radius: float, refine_deg: tuple[float, ...] = (0.0,),
                       half_y: bool = True, half_z: bool = False, radius: float = CYLINDER_RADIUS,
                       length: float = CYLINDER_LENGTH, center: np.ndarray = CYLINDER_CENTER,
                       path_depth: float = 0.0, skin: tuple[float, float, float] | None = None,
                       cut_deg: float | None = None, tip: tuple[float, float] | None = None,
                       rim: bool = False) -> TetMesh:
    """Mesh a symmetric part of the cylinder for the nonlinear reference (P1 tetrahedra, gmsh OpenCASCADE).

    ``half_y``: keep y ≥ y_O only (the push at y = y_O is mirror-symmetric in y); ``half_z``: also keep z ≥
    z_O (a push at azimuth 0 is mirror-symmetric in z too). Element size ``h`` (m), ``h_fine`` (m) within
    ``refine_radius`` (m) of the side-surface points at azimuths ``refine_deg`` (deg, around +x toward +z, at
    y = y_O), gmsh ``Ball`` + ``Min`` fields; with ``path_depth`` (m) > 0 the refined region is the whole
    *push path* instead: balls every ``refine_radius``/3 from each of those surface points down to
    ``path_depth`` along the inward normal (the tube the fingertip travels through and the ring of material
    that wraps it). Each ball grades from ``h_fine`` to ``h`` over a further ``refine_radius``. ``skin``
    (size, patch radius, depth) m: also size ``size`` in the skin around each push point — the surface layer
    ``depth`` thick within ``patch radius`` (along the surface) of it, whose material wraps around the
    fingertip and lines the crater (balls of radius ``depth`` every ``depth``/2 on the surface). ``tip``
    (size, radius) m: also size ``size`` within ``radius`` of each push point itself, graded to ``h`` over a
    further ``radius`` (the material that ends up over the fingertip). ``cut_deg`` (deg, without ``half_z``):
    the mesh conforms to the plane through the axis and the push direction at that azimuth (the solid is
    fragmented by it, so the two volumes share their nodes there). ``rim``: the support's plane x = x_O cuts
    the surface along mesh lines of size ``h_fine`` (:func:`_split_at_rim`). ``fixed`` marks nothing here: the
    caller knows which faces are symmetry planes. Raises ``ValueError`` on bad sizes or a ``cut_deg`` that is
    not finite or comes with ``half_z``, and ``RuntimeError`` if gmsh fails.
    """
    for name, v in (("h", h), ("h_fine", h_fine)):
        if not (math.isfinite(v) and 0.0005 <= v <= 0.05):
            raise ValueError(f"{name} must be in [0.0005, 0.05] m, got {v!r}")
    if h_fine > h:
        raise ValueError(f"h_fine must be <= h, got h_fine={h_fine!r} > h={h!r}")
    if not (math.isfinite(refine_radius) and 0.0 <= refine_radius <= 0.1):
        raise ValueError(f"refine_radius must be in [0, 0.1] m, got {refine_radius!r}")
    c = np.asarray(center, float)
    y0 = c[1] if half_y else c[1] - length / 2
    geometry = _part_geometry(c, y0, radius, length, half_z, cut_deg)
    if cut_deg is not None and (half_z or not math.isfinite(cut_deg)):
        raise ValueError("cut_deg must be a finite azimuth (deg) on a part without the z mirror (half_z), "
                         f"got {cut_deg!r} with half_z={half_z}")
    if not (math.isfinite(path_depth) and 0.0 <= path_depth <= 2 * radius):
        raise ValueError(f"path_depth must be in [0, {2 * radius:.4g}] m, got {path_depth!r}")
    centres = []
    if refine_radius > 0 and h_fine < h:
        for d in refine_deg:
            out = np.array([math.cos(math.radians(d)), 0.0, math.sin(math.radians(d))])
            n = int(math.ceil(path_depth / (refine_radius / 3))) if path_depth > 0 else 0
            centres += [c + (radius - s) * out for s in np.linspace(0.0, path_depth, n + 1)]
    extra = ()
    if skin is not None:
        extra = (_skin_balls(skin, h_fine, refine_deg, radius, c, y0, half_z),)
    if tip is not None:
        extra = extra + (_tip_balls(tip, h_fine, refine_deg, radius, c),)
    points, tets = gmsh_tets("cylinder_part", geometry, h, h_fine, refine_radius, centres,
                             f"the cylinder part (h={h}, h_fine={h_fine}, skin={skin}, tip={tip})", extra,
                             rim=(c, np.array([1.0, 0.0, 0.0])) if rim else None)
    tets = orient_tets(points, tets)
    faces = surface_faces(points, tets)
    return TetMesh(points, tets, faces, np.zeros(len(points), bool), None, radius, length, c.copy())


def finish_cylinder_mesh(points: np.ndarray, tets: np.ndarray, radius: float, length: float,
                         center: np.ndarray,
                         spec: MeshSpec | None) -> TetMesh:
    tets = orient_tets(points, tets)
    faces = surface_faces(points, tets)
    fixed = np.zeros(len(points), bool)
    fixed[np.unique(faces)] = points[np.unique(faces), 0] <= center[0] + 1e-9
    return TetMesh(points, tets, faces, fixed, spec, radius, length, np.asarray(center, float).copy())


def orient_tets(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Return ``tets`` (M, 4) with the last two vertices swapped where the signed volume is negative."""
    tets = np.array(tets, dtype=np.int64, copy=True)
    p = points[tets]
    vol = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    neg = vol < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    return tets


def surface_faces(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Boundary triangles (F, 3) int64 of a tet mesh, wound counter-clockwise seen from outside.

    A face is on the boundary when exactly one tetrahedron has it. ``points`` (N, 3), ``tets`` (M, 4)."""
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    opp = np.array([0, 1, 2, 3])
    f = tets[:, local].reshape(-1, 3)
    o = np.repeat(tets[:, opp][:, :, None], 1, axis=2).reshape(-1)
    key = np.sort(f, axis=1)
    _, idx, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    b = idx[counts == 1]
    faces, other = f[b], o[b]
    p0, p1, p2 = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    nrm = np.cross(p1 - p0, p2 - p0)
    inward = np.einsum("ij,ij->i", nrm, points[other] - p0) > 0
    faces[inward, 1], faces[inward, 2] = faces[inward, 2].copy(), faces[inward, 1].copy()
    return faces


def write_mesh(mesh: TetMesh, path: str) -> None:
    """Write the mesh (tets + boundary triangles, point data ``fixed``) with meshio; format from the
    suffix."""
    import meshio

    meshio.write(path, meshio.Mesh(mesh.points, [("tetra", mesh.tets), ("triangle", mesh.faces)],
                                   point_data={"fixed": mesh.fixed.astype(np.int32)}))
