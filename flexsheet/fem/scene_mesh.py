"""Tetrahedral mesh of any scene's object: sphere, rounded box, cylinder, surface mesh (pure: gmsh
builds it in memory).

Geometry (display frame, m), from :class:`flexsheet.model.scenes.Scene`:

* analytic kinds through gmsh's OpenCASCADE kernel — ``occ.addSphere``; ``occ.addCylinder`` along the pose's
  local +y; ``occ.addBox`` with every edge rounded by ``occ.fillet`` (the scene's edge radius), rotated
  Rx(roll), Ry(pitch), Rz(yaw) about the origin and moved to the pose position (the convention of
  :func:`flexsheet.model.scene_parts.rotation_rpy`);
* a surface mesh (``kind: mesh``, e.g. the organ's ``kidney.obj``) — and any analytic kind OpenCASCADE fails
  on — through :meth:`Scene.write_surface` → STL → ``gmsh.merge`` + ``mesh.classifySurfaces`` +
  ``mesh.createGeometry`` (the surface is re-parametrised and remeshed at the requested sizes) + a volume on
  its surface loop (gmsh tutorial t13, "remeshing an STL file without an underlying CAD model").

Sizes: ``h`` everywhere, ``h_fine`` within ``refine_radius`` of the scene's stroke path
(:meth:`Scene.stroke_points`, where the finger goes) and of every inclusion's centre (``Ball`` fields under
a ``Min``; :func:`flexsheet.fem.mesh.gmsh_tets`).

Support: boundary nodes where :meth:`Scene.fixed_mask` holds. Material: per-element (E, ν) from
:meth:`Scene.material_at` at the element centroids (the inclusions, piecewise constant on the tets whose
centroid lies inside).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.mesh import MeshSpec, TetMesh, gmsh_tets, orient_tets, surface_faces
from flexsheet.model.scenes import Scene

__all__ = ["SceneMesh", "scene_mesh", "refine_centres", "support_plane", "DEFAULT_SCENE_SPEC"]

#: the cylinder's chosen real-time mesh sizes (flexsheet/fem/accuracy_table.json:
#: P2 h 12 mm, h_fine 4 mm, band 12 mm) applied along any scene's stroke path
DEFAULT_SCENE_SPEC = MeshSpec(0.012, 0.004, 0.012)


@dataclass
class SceneMesh:
    """A scene's tetrahedral mesh with its material.

    ``mesh`` :class:`TetMesh` (``fixed`` from the scene's support on boundary nodes, ``center`` = the scene's
    centre (3,) m); ``E`` (M,) Pa and ``nu`` (M,) per tetrahedron; ``how`` "occ" (OpenCASCADE solid) or
    "stl" (remeshed surface); ``volume`` m³ of the tets."""

    mesh: TetMesh
    E: np.ndarray
    nu: np.ndarray
    how: str

    @property
    def volume(self) -> float:
        """Total tetrahedron volume, m³."""
        p = self.mesh.points[self.mesh.tets]
        return float(np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]),
                               p[:, 3] - p[:, 0]).sum()
                     / 6.0)


def refine_centres(scene, spec: MeshSpec) -> np.ndarray:
    """Centres (K, 3) m of the refinement balls: the stroke path at ≤ refine_radius/2 spacing, then each
    inclusion's centre. Empty (0, 3) when ``spec`` asks for no refinement."""
    if not (spec.refine_radius > 0 and spec.h_fine < spec.h):
        return np.zeros((0, 3))
    n = max(2, int(math.ceil(scene.stroke_length() / (spec.refine_radius / 2))) + 1)
    pts, _ = scene.stroke_points(n)
    inc = [np.asarray(i.center, float) for i in scene.inclusions]
    return np.vstack([pts] + ([np.array(inc)] if inc else []))


def support_plane(scene) -> tuple[np.ndarray, np.ndarray]:
    """(point (3,) m, unit normal (3,)): the plane bounding the scene's held region
    (:class:`flexsheet.model.scene_parts.Support`: (p − point)·n ≤ tolerance), 1 pm inside it so the nodes a
    mesh puts on the plane are held whatever their rounding."""
    s = scene.support
    point = np.asarray(scene.center if s.kind == "back_half" else s.point, float)
    n = np.asarray(s.normal, float) / np.linalg.norm(s.normal)
    return point + (s.tolerance - 1e-12) * n, n


def _occ_geometry(scene):
    """``geometry(gmsh)`` adding the scene's analytic solid to the OCC model, or None for a mesh object."""
    o = scene.object
    c = scene.center
    R = o.pose.R
    if o.kind == "sphere":
        return lambda gmsh: gmsh.model.occ.addSphere(c[0], c[1], c[2], o.radius)
    if o.kind == "cylinder":
        ax = R[:, 1]
        b = c - 0.5 * o.length * ax
        return lambda gmsh: gmsh.model.occ.addCylinder(b[0], b[1], b[2], *(o.length * ax), o.radius)
    if o.kind == "rounded_box":
        e = np.asarray(o.half_extents, float)
        roll, pitch, yaw = (math.radians(a) for a in o.pose.rpy_deg)

        def geometry(gmsh) -> None:
            occ = gmsh.model.occ
            v = occ.addBox(-e[0], -e[1], -e[2], 2 * e[0], 2 * e[1], 2 * e[2])
            if o.radius > 0:
                occ.synchronize()
                curves = [t for _, t in gmsh.model.getBoundary([(3, v)], combined=False, oriented=False,
                                                               recursive=False)]
                edges = sorted({abs(t) for s in curves for _,
                                t in gmsh.model.getBoundary([(2, s)], oriented=False)})
                out = occ.fillet([v], edges, [o.radius], removeVolume=True)
                v = [t for d, t in out if d == 3][0]
            for angle, axis in ((roll, (1, 0, 0)), (pitch, (0, 1, 0)), (yaw, (0, 0, 1))):
                if angle:
                    occ.rotate([(3, v)], 0, 0, 0, *axis, angle)
            occ.translate([(3, v)], *c)
        return geometry
    return None


def _stl_geometry(path: str):
    def geometry(gmsh) -> None:
        gmsh.merge(path)
        # angle 40°: a face pair bending more is an edge (none
        # on a smooth organ); curveAngle 180: no curve split
        gmsh.model.mesh.classifySurfaces(math.radians(40.0), True, True, math.pi)
        gmsh.model.mesh.createGeometry()
        surfaces = [t for _, t in gmsh.model.getEntities(2)]
        loop = gmsh.model.geo.addSurfaceLoop(surfaces)
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()
    return geometry


def scene_mesh(scene, spec: MeshSpec = DEFAULT_SCENE_SPEC, force_stl: bool = False,
               refine_at: np.ndarray | None = None, rim: bool = False) -> SceneMesh:
    """Mesh ``scene`` (a :class:`flexsheet.model.scenes.Scene`) with P1 tetrahedra refined along its stroke.

    ``spec``: sizes (``arc_deg`` is ignored: the refined band follows the scene's stroke path); ``force_stl``:
    mesh an analytic object through its STL surface too (tests compare both routes); ``refine_at`` optional
    (K, 3) m: refine around these points (and the inclusions) instead of the stroke (a reference mesh around
    one push point); ``rim``: the support's plane cuts the surface along a mesh line refined to ``h_fine`` (a
    conforming support rim for the references; OpenCASCADE solids only, a remeshed STL keeps the rim its nodes
    give). Returns a :class:`SceneMesh`. Raises ``ValueError`` when ``scene`` is not a Scene or its support
    holds no boundary node, ``RuntimeError`` when gmsh fails (naming the scene). Deterministic for a given
    scene and spec (single-threaded Delaunay)."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a flexsheet.model.scenes.Scene, got {type(scene).__name__}")
    if not isinstance(spec, MeshSpec):
        raise ValueError(f"spec must be a MeshSpec, got {type(spec).__name__}")
    centres = refine_centres(scene, spec)
    if refine_at is not None:
        pts = np.asarray(refine_at, float).reshape(-1, 3)
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"refine_at must be finite (K, 3) points in m, got {pts.tolist()[:3]}")
        inc = [np.asarray(i.center, float) for i in scene.inclusions]
        centres = np.vstack([pts] + ([np.array(inc)] if inc else [])) if spec.refine_radius > 0 else centres
    what = f"scene {scene.name!r} ({scene.source}) with {spec.key()}"
    geometry = None if force_stl else _occ_geometry(scene)
    how = "occ"
    points = tets = None
    if geometry is not None:
        try:
            points, tets = gmsh_tets(f"scene_{scene.name}", geometry, spec.h, spec.h_fine, spec.refine_radius,
                                     centres, what, rim=support_plane(scene) if rim else None)
        except RuntimeError:
            points = None  # e.g. a fillet OpenCASCADE cannot build: mesh the surface instead
    if points is None:
        how = "stl"
        with tempfile.TemporaryDirectory(prefix="flexsheet_scene_") as d:
            path = scene.write_surface(os.path.join(d, "surface.stl"))
            points, tets = gmsh_tets(f"scene_{scene.name}", _stl_geometry(path), spec.h, spec.h_fine,
                                     spec.refine_radius, centres, what)
    tets = orient_tets(points, tets)
    p = points[tets]
    vol = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0
    if not np.all(vol > 0):
        raise RuntimeError(f"gmsh produced {int(np.sum(vol <= 0))} degenerate tetrahedra for {what}")
    faces = surface_faces(points, tets)
    surf = np.unique(faces)
    fixed = np.zeros(len(points), bool)
    fixed[surf] = scene.fixed_mask(points[surf])
    if not fixed.any():
        raise ValueError(f"{scene.source}: key 'support': holds none of the {len(surf)} boundary nodes of "
                         "the mesh: the object would float")
    E, nu = scene.material_at(p.mean(axis=1))
    mesh = TetMesh(points, tets, faces, fixed, spec, center=np.asarray(scene.center, float).copy())
    return SceneMesh(mesh, np.asarray(E, float), np.asarray(nu, float), how)
