"""Triangle surfaces of a scene's object in the display frame: the cylinder's, the rounded box's, a mesh
file's (trimesh; meshio as a fallback reader), and their corner normals (pure, no I/O beyond reading a mesh
file)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["cylinder_surface", "rounded_box_surface", "corner_normals", "load_mesh_file", "object_surface",
           "MAX_MESH_BYTES"]


MAX_MESH_BYTES = 32 << 20


# ----------------------------------------------------------------------------------------------- meshes
def cylinder_surface(radius: float, length: float, n_around: int = 96, n_along: int = 48):
    """Closed cylinder in its local frame (axis +y, centred), fine along the axis (per-vertex image correction
    needs short edges): rings of ``n_around`` vertices at ``n_along`` + 1 heights, caps as fans around their
    centres. Returns (vertices (N, 3) float64 m, faces (M, 3) int64, outward winding)."""
    if n_around < 3 or n_along < 1 or not radius > 0 or not length > 0:
        raise ValueError(f"bad cylinder: radius={radius}, length={length}, n_around={n_around}, "
                         f"n_along={n_along}")
    th = np.linspace(0.0, 2 * math.pi, n_around, endpoint=False)
    ys = np.linspace(-length / 2, length / 2, n_along + 1)
    ring = np.stack([radius * np.cos(th), np.zeros_like(th), radius * np.sin(th)], axis=1)
    v = np.concatenate([ring + [0.0, y, 0.0] for y in ys])
    i = np.arange(n_around)
    j = np.arange(n_along)[:, None]
    a = j * n_around + i
    b = j * n_around + (i + 1) % n_around
    side = np.stack([np.stack([a, b, a + n_around], -1), np.stack([b, b + n_around, a + n_around], -1)], 2)
    base = len(v)
    top = n_along * n_around
    caps = np.stack([np.stack([np.full(n_around, base), (i + 1) % n_around, i], -1),
                     np.stack([np.full(n_around, base + 1), top + i, top + (i + 1) % n_around], -1)], 1)
    v = np.concatenate([v, [[0.0, -length / 2, 0.0], [0.0, length / 2, 0.0]]])
    f = np.concatenate([side.reshape(-1, 3), caps.reshape(-1, 3)])[:, ::-1]  # counter-clockwise from outside
    return v, np.ascontiguousarray(f, dtype=np.int64)


def rounded_box_surface(half_extents, radius: float, step: float = 0.003, n_round: int = 6):
    """Rounded box in its local frame: each face of the outer box gridded (≈ ``step`` m inside, ``n_round``
    steps of equal angle across each rounded strip), every grid point P moved to the rounded surface along
    P − clamp(P, inner box) (exact for the Minkowski sum of the inner box and a ball of ``radius``).
    Returns (vertices (N, 3) float64, faces (M, 3) int64)."""
    import trimesh

    e = np.asarray(half_extents, float)
    ei = e - radius

    def coords(k: int) -> np.ndarray:
        n = max(2, int(math.ceil(2 * ei[k] / step)))
        inner = np.linspace(-ei[k], ei[k], n + 1) if ei[k] > 0 else np.array([0.0])
        if radius <= 0:
            return inner
        t = ei[k] + radius * np.tan(np.linspace(0.0, math.pi / 4, n_round + 1)[1:])
        return np.concatenate([-t[::-1], inner, t])

    cs = [coords(k) for k in range(3)]
    verts, faces = [], []
    for ax in range(3):
        u, w = [k for k in range(3) if k != ax]
        for sign in (-1.0, 1.0):
            U, W = np.meshgrid(cs[u], cs[w], indexing="ij")
            P = np.zeros(U.shape + (3,))
            P[..., ax] = sign * e[ax]
            P[..., u], P[..., w] = U, W
            nu, nw = U.shape
            idx = np.arange(nu * nw).reshape(nu, nw) + sum(len(x) for x in verts)
            q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
            tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
            # outward winding: (u, w, ax) right-handed for +ax faces
            rh = np.cross(np.eye(3)[u], np.eye(3)[w])[ax] > 0
            if (sign > 0) != rh:
                tri = tri[:, ::-1]
            verts.append(P.reshape(-1, 3))
            faces.append(tri)
    P = np.concatenate(verts)
    if radius > 0:
        inner = np.clip(P, -ei, ei)
        d = P - inner
        P = inner + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    m = trimesh.Trimesh(P, np.concatenate(faces), process=False)
    m.merge_vertices(digits_vertex=10)
    m.remove_unreferenced_vertices()
    return np.asarray(m.vertices), np.asarray(m.faces)


def corner_normals(m, crease_deg: float = 30.0) -> np.ndarray:
    """Per-face corner normals (M, 3, 3) of a trimesh: at each corner the area-weighted mean of the normals
    of the faces around that vertex within ``crease_deg`` of this face's normal — smooth across a curved
    surface, the face normal across a sharp edge (a box)."""
    fn = np.asarray(m.face_normals, dtype=float)
    area_n = fn * np.asarray(m.area_faces, dtype=float)[:, None]
    vf = np.asarray(m.vertex_faces)                     # (N, k) incident faces, padded with -1
    cos_c = math.cos(math.radians(crease_deg))
    out = np.empty((len(m.faces), 3, 3))
    for c in range(3):
        nb = vf[m.faces[:, c]]                          # (M, k)
        ok = nb >= 0
        nbn = area_n[np.where(ok, nb, 0)]               # (M, k, 3)
        keep = ok & (np.einsum("mkj,mj->mk", fn[np.where(ok, nb, 0)], fn) >= cos_c)
        s = np.einsum("mk,mkj->mj", keep.astype(float), nbn)
        out[:, c] = s / np.linalg.norm(s, axis=1, keepdims=True)
    return out


def load_mesh_file(path: Path):
    """A closed ``trimesh.Trimesh`` from ``path`` (trimesh, else meshio's triangle cells). ``ValueError``."""
    import trimesh

    if not path.is_file():
        raise ValueError(f"mesh file not found: {str(path)!r}")
    if path.stat().st_size > MAX_MESH_BYTES:
        raise ValueError(f"mesh file {str(path)!r} is larger than {MAX_MESH_BYTES >> 20} MiB")
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # noqa: BLE001 - trimesh raises assorted errors; try meshio before giving up
        try:
            import meshio

            mm = meshio.read(str(path))
            tri = [c.data for c in mm.cells if c.type == "triangle"]
            if not tri:
                raise ValueError("no triangle cells") from None
            mesh = trimesh.Trimesh(mm.points[:, :3], np.concatenate(tri))
        except Exception as exc2:  # noqa: BLE001
            raise ValueError(f"cannot read mesh file {str(path)!r}: {exc}; meshio: {exc2}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"mesh file {str(path)!r} holds no triangles")
    if not mesh.is_watertight:
        raise ValueError(f"mesh file {str(path)!r} is not a closed (watertight) surface")
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def object_surface(o, mesh_path: Path | None):
    """The closed ``trimesh.Trimesh`` of a scene's object ``o`` (a cylinder, sphere, rounded box or mesh
    object of :mod:`flexsheet.model.scene_parts`) in the display frame, m; ``mesh_path``: a mesh object's
    file. Raises ``ValueError`` for a mesh file that is missing, too large, unreadable or not closed."""
    import trimesh

    if o.kind == "cylinder":
        v, f = cylinder_surface(o.radius, o.length)
    elif o.kind == "sphere":
        ico = trimesh.creation.icosphere(subdivisions=4, radius=o.radius)
        v, f = np.asarray(ico.vertices), np.asarray(ico.faces)
    elif o.kind == "rounded_box":
        v, f = rounded_box_surface(o.half_extents, o.radius)
    else:
        mesh = load_mesh_file(mesh_path)
        v, f = np.asarray(mesh.vertices) * o.scale, np.asarray(mesh.faces)
    return trimesh.Trimesh(o.pose.apply(v), f, process=False)
