"""Scene files: the virtual object the display presents — its shape and pose, material, support, the finger
and the stroke path (pure: numpy, pydantic, PyYAML, trimesh).

A scene is a YAML file beside the launch files (``launch/scenes/*.yaml``; docs/scenes.md)::

    name: cylinder
    description: the paper's cylinder (§VI-A)
    object:                       # kind: cylinder | sphere | rounded_box | mesh kind: cylinder radius:
      0.035355339059327376 length: 0.12 pose: {position: [-0.035355339059327376, 0.0, 0.0], rpy_deg: [0, 0,
      0]} material: {model: gent, E: 10000.0, nu: 0.45, Jm: 97.2}   # or {model: neo_hookean, E: ..., nu: ...}
      support: {kind: back_half}    # or {kind: half_space, point: [...], normal: [...]} finger: {radius:
      0.008} stroke: {kind: arc, start: [1, 0, 0], toward: [0, 0, 1], start_deg: 0, end_deg: 60} inclusions:
      []                # stiffer spheres inside: [{name, center, radius, E, nu}]

Frames and units: every position is in the ``display`` frame (:mod:`flexsheet.model.geometry`), m; moduli Pa;
angles in degrees where the key says ``_deg``. An object's local frame is placed by ``pose``: display point
= R·local + position with R = Rz(yaw)·Ry(pitch)·Rx(roll) from ``rpy_deg`` (the convention of
:class:`flexsheet.model.shapes.RoundedBox`). Local frames: cylinder axis +y, centred; sphere centred; rounded
box centred, axis-aligned; a mesh file's own coordinates (× ``scale``, to m). The pose position is the
object's *centre*: it must lie inside the body (the back-half support and arc strokes are defined from it).

What each consumer calls:

* renderer / viz: :meth:`Scene.surface_mesh` → (vertices (N, 3) float32 m, faces (M, 3) int32), closed,
outward-wound;
* planner: :meth:`Scene.shape` → the :class:`flexsheet.model.shape_base.Shape` (analytic where it can be);
* FEM: :meth:`Scene.write_surface` (a surface file gmsh can mesh), :meth:`Scene.fixed_mask` (support),
  :meth:`Scene.material_at` (E, ν per point: the inclusions), ``scene.material.model``, :meth:`Scene.key`
  (cache key); ``scene.finger.radius``;
* world / experiments: :meth:`Scene.stroke_at` (points and normals at fractions of the path's arc length),
  :meth:`Scene.stroke_points` (n evenly spaced), :meth:`Scene.stroke_length`.

Errors: :class:`SceneError` (a ``ValueError``) naming the file, the key and the value.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    Field,
    PrivateAttr,
    ValidationError,
)

from flexsheet.dirs import launch_dir
from flexsheet.model import geometry as paper
from flexsheet.model import shapes
from flexsheet.model.scene_parts import (
    GENT_JM_RUBBER,
    MAX_EXTENT,
    SCENE_CONFIG,
    ArcStroke,
    CylinderObject,
    Finger,
    Inclusion,
    MaterialSpec,
    MeshObject,
    PolylineStroke,
    Pose,
    RoundedBoxObject,
    SceneError,
    SphereObject,
    Support,
    Use,
)
from flexsheet.model.scene_surface import corner_normals, object_surface
from flexsheet.yamlio import UniqueKeyLoader

__all__ = ["Scene", "load_scene", "parse_scene", "paper_scene", "is_paper_cylinder", "load_scene_or_paper",
           "SCENES_DIR", "DEFAULT_SCENE_FILE", "MAX_SCENE_BYTES"]

#: the shipped scenes (``launch/scenes/`` of :func:`flexsheet.dirs.launch_dir`, resolved at import)
SCENES_DIR = launch_dir() / "scenes"
#: the default scene: the paper's cylinder
DEFAULT_SCENE_FILE = SCENES_DIR / "cylinder.yaml"
MAX_SCENE_BYTES = 1 << 20


ObjectSpec = Annotated[CylinderObject | SphereObject | RoundedBoxObject | MeshObject,
                       Field(discriminator="kind")]


StrokeSpec = Annotated[ArcStroke | PolylineStroke, Field(discriminator="kind")]


# ----------------------------------------------------------------------------------------------- the scene
class Scene(BaseModel):
    """One scene (module doc). Build with :func:`load_scene`, :func:`parse_scene` or :func:`paper_scene`;
    the geometry (mesh, shape, stroke) is computed on first use and cached."""

    model_config = SCENE_CONFIG
    name: str = Field(min_length=1, max_length=64)
    description: str = ""
    object: ObjectSpec
    material: MaterialSpec = MaterialSpec()
    support: Support = Support()
    finger: Finger = Finger()
    stroke: StrokeSpec = ArcStroke(kind="arc")
    inclusions: list[Inclusion] = Field(default_factory=list, max_length=16)
    use: Use = Use()

    _source: str = PrivateAttr("<scene>")
    _base_dir: Path = PrivateAttr(Path("."))
    _mesh: Any = PrivateAttr(None)
    _shape: Any = PrivateAttr(None)
    _table: Any = PrivateAttr(None)
    _cnormals: Any = PrivateAttr(None)

    # ------------------------------------------------------------------ identity
    @property
    def source(self) -> str:
        """The file the scene was read from (or ``<paper>`` / ``<dict>``)."""
        return self._source

    @property
    def center(self) -> np.ndarray:
        """The object's centre (3,) m, display frame (the pose position)."""
        return np.asarray(self.object.pose.position, dtype=float)

    @property
    def mesh_path(self) -> Path | None:
        """Absolute path of a mesh object's file (None for analytic kinds)."""
        if self.object.kind != "mesh":
            return None
        p = Path(os.path.expanduser(self.object.file))
        return p if p.is_absolute() else (self._base_dir / p).resolve()

    def key(self) -> str:
        """SHA-256 hex of the scene's values and its mesh file's bytes: a cache key for precomputed FEM
        data."""
        # the default contact law is left out, so every key made before the field existed still holds (the
        # shipped tables' keys; tests/unit/model/test_scenes.py); so are what does not change the model: the
        # depths the scene is used at and the contact law's source
        finger = {"contact",
                  "contact_source"} if self.finger.contact == "frictionless" else {"contact_source"}
        h = hashlib.sha256(self.model_dump_json(exclude={"finger": finger, "use": True}).encode())
        if self.mesh_path is not None:
            h.update(self.mesh_path.read_bytes())
        return h.hexdigest()

    def describe(self) -> str:
        """One line for logs: name, kind, size, material, inclusions, source file."""
        o = self.object
        size = {"cylinder": lambda: f"R {o.radius * 1e3:.1f} mm x {o.length * 1e3:.0f} mm",
                "sphere": lambda: f"R {o.radius * 1e3:.1f} mm",
                "rounded_box": lambda: "half extents " + "x".join(f"{e * 1e3:.0f}" for e in o.half_extents)
                                       + f" mm, edge {o.radius * 1e3:.0f} mm",
                "mesh": lambda: f"{Path(o.file).name} x{o.scale:g}"}[o.kind]()
        m = self.material
        inc = f", {len(self.inclusions)} inclusion(s)" if self.inclusions else ""
        return (f"scene {self.name!r} ({self._source}): {o.kind} {size}, {m.model} E {m.E / 1e3:g} kPa "
                f"nu {m.nu:g}{inc}")

    # ------------------------------------------------------------------ geometry
    def trimesh(self):
        """The surface as a ``trimesh.Trimesh`` in the display frame, m (closed, outward normals; cached)."""
        if self._mesh is None:
            self._mesh = object_surface(self.object, self.mesh_path)
        return self._mesh

    def surface_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The object's closed surface for the renderer and the viewer: (vertices (N, 3) float32 m, display
        frame; faces (M, 3) int32, counter-clockwise seen from outside). Tessellation: cylinder 96 × 48
        (the renderer's historical mesh), sphere icosphere level 4, rounded box ≈ 3 mm faces with 6 steps
        per rounded edge, mesh files as given."""
        m = self.trimesh()
        return np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, dtype=np.int32)

    def write_surface(self, path: str | os.PathLike) -> str:
        """Write :meth:`surface_mesh` to ``path`` (format from the suffix: .stl, .obj, .ply; trimesh), for
        gmsh (``gmsh.merge`` + ``classifySurfaces`` + ``createGeometry``). Returns the path as a string."""
        path = str(path)
        self.trimesh().export(path)
        return path

    def shape(self):
        """The planner's :class:`flexsheet.model.shape_base.Shape` (analytic for cylinder/sphere/rounded box,
        :class:`~flexsheet.model.shapes.MeshShape` for a mesh; cached)."""
        if self._shape is None:
            o = self.object
            R = o.pose.R
            if o.kind == "cylinder":
                self._shape = shapes.Cylinder(tuple(self.center), tuple(R[:, 1]), o.radius, o.length)
            elif o.kind == "sphere":
                self._shape = shapes.Sphere(tuple(self.center), o.radius)
            elif o.kind == "rounded_box":
                self._shape = shapes.RoundedBox(tuple(self.center), o.half_extents, o.radius,
                                                tuple(math.radians(a) for a in o.pose.rpy_deg))
            else:
                self._shape = shapes.MeshShape(self.trimesh())
        return self._shape

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance (N,) m of points (N, 3) m to the surface, < 0 inside (the analytic shape's, or the
        mesh's through trimesh)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        if self.object.kind == "mesh":
            import trimesh

            return -trimesh.proximity.signed_distance(self.trimesh(), p)    # trimesh: > 0 inside
        s = self.shape()
        return np.array([s.signed_distance(tuple(q)) for q in p])

    def contains(self, points) -> np.ndarray:
        """(N,) bool: points (N, 3) m strictly inside the body."""
        return self.signed_distance(points) < 0.0

    def surface_point(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points (N, 3) m and outward unit normals (N, 3) of points (N, 3) m (mesh: normals
        interpolated from the vertex normals, so they vary smoothly along a path)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        if self.object.kind == "mesh":
            return self._mesh_closest(p)
        s = self.shape()
        q, n = [], []
        for x in p:
            qi, ni, _ = s.closest(tuple(x))
            q.append(qi)
            n.append(ni)
        return np.asarray(q, dtype=float), np.asarray(n, dtype=float)

    def mesh_corner_normals(self) -> np.ndarray:
        """Per-face corner normals (M, 3, 3) of a mesh scene's :meth:`trimesh`, computed once
        (:func:`flexsheet.model.scene_surface.corner_normals`): what :meth:`surface_point` interpolates."""
        if self._cnormals is None:
            self._cnormals = corner_normals(self.trimesh())
        return self._cnormals

    def _mesh_closest(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        import trimesh

        m = self.trimesh()
        q, _, tri = trimesh.proximity.closest_point(m, p)
        bary = trimesh.triangles.points_to_barycentric(m.triangles[tri], q)
        n = np.einsum("ij,ijk->ik", bary, self.mesh_corner_normals()[tri])
        return q, n / np.linalg.norm(n, axis=1, keepdims=True)

    # ------------------------------------------------------------------ FEM helpers
    def fixed_mask(self, points) -> np.ndarray:
        """(N,) bool: which of the points (N, 3) m (boundary nodes) the support holds (:class:`Support`)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        s = self.support
        point = self.center if s.kind == "back_half" else np.asarray(s.point, float)
        n = np.asarray(s.normal, float) / np.linalg.norm(s.normal)
        return (p - point) @ n <= s.tolerance

    def material_at(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(E (N,) Pa, nu (N,)) at points (N, 3) m (e.g. element centroids): the body's material, replaced by
        an inclusion's inside it (later inclusions win where they overlap)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        E = np.full(len(p), self.material.E)
        nu = np.full(len(p), self.material.nu)
        for inc in self.inclusions:
            inside = np.linalg.norm(p - np.asarray(inc.center, float), axis=1) <= inc.radius
            E[inside] = inc.E
            nu[inside] = self.material.nu if inc.nu is None else inc.nu
        return E, nu

    # ------------------------------------------------------------------ stroke
    def _stroke_raw(self, s: np.ndarray) -> np.ndarray:
        """Surface points (N, 3) at the stroke's own parameter ``s`` ∈ [0, 1] (not arc length)."""
        st = self.stroke
        if st.kind == "arc":
            c = self.center if st.center is None else np.asarray(st.center, float)
            e0, e1 = st.basis()
            ang = np.radians(st.start_deg + s * (st.end_deg - st.start_deg))
            w = np.cos(ang)[:, None] * e0 + np.sin(ang)[:, None] * e1
            return self._ray_exits(c, w)
        pts = np.asarray(st.points, float)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        t = np.clip(s, 0.0, 1.0) * cum[-1]
        x = np.column_stack([np.interp(t, cum, pts[:, k]) for k in range(3)])
        return self.surface_point(x)[0]

    def _ray_exits(self, c: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Where rays from ``c`` (inside) along unit ``w`` (N, 3) first leave the body, (N, 3) m."""
        if self.object.kind == "mesh":
            m = self.trimesh()
            loc, ray, _ = m.ray.intersects_location(np.repeat(c[None], len(w), 0), w, multiple_hits=True)
            out = np.full((len(w), 3), np.nan)
            d = np.einsum("ij,ij->i", loc - c, w[ray])
            for i in range(len(w)):
                k = np.flatnonzero((ray == i) & (d > 0))
                if len(k):
                    out[i] = loc[k[np.argmin(d[k])]]
            if np.isnan(out).any():
                raise ValueError(f"a stroke ray from {c.round(4).tolist()} does not leave the mesh")
            return out
        shape = self.shape()
        hi0 = float(np.max(np.linalg.norm(self.trimesh().vertices - c, axis=1))) * 1.1 + 1e-3
        out = np.empty((len(w), 3))
        for i, d in enumerate(w):
            lo, hi = 0.0, hi0
            for _ in range(48):  # bisection on the signed distance: hi0 / 2^48 < 1e-15 m
                mid = 0.5 * (lo + hi)
                if shape.signed_distance(tuple(c + mid * d)) < 0.0:
                    lo = mid
                else:
                    hi = mid
            out[i] = c + 0.5 * (lo + hi) * d
        return out

    def _stroke_table(self) -> tuple[np.ndarray, np.ndarray]:
        if self._table is None:
            s = np.linspace(0.0, 1.0, 513)
            q = self._stroke_raw(s)
            L = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
            self._table = (s, L)
        return self._table

    def stroke_length(self) -> float:
        """Length of the stroke path on the surface, m (512 chords)."""
        return float(self._stroke_table()[1][-1])

    def stroke_at(self, fraction) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 3) m on the surface and outward unit normals (N, 3) at ``fraction`` (N,) ∈ [0, 1] of the
        stroke's arc length (0: start, 1: end). Raises ``ValueError`` for values outside [0, 1] or NaN."""
        f = np.atleast_1d(np.asarray(fraction, dtype=float))
        if not np.all(np.isfinite(f)) or f.min(initial=0.0) < 0.0 or f.max(initial=0.0) > 1.0:
            raise ValueError(f"fraction must be in [0, 1], got {np.round(f, 6).tolist()[:8]}")
        s_tab, L = self._stroke_table()
        s = np.interp(f * L[-1], L, s_tab)
        return self.surface_point(self._stroke_raw(s))

    def stroke_points(self, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
        """``n`` ≥ 2 points (n, 3) m evenly spaced by arc length along the stroke, on the surface, with their
        outward unit normals (n, 3); display frame."""
        if int(n) < 2:
            raise ValueError(f"n must be >= 2, got {n!r}")
        return self.stroke_at(np.linspace(0.0, 1.0, int(n)))

    # ------------------------------------------------------------------ checks
    def check_geometry(self) -> Scene:
        """Check what the schema cannot: the mesh loads and is closed, the object lies within
        :data:`MAX_EXTENT` of the display origin, the centre is inside the body, every inclusion lies inside
        it, the stroke can be traced. Raises :class:`SceneError` naming the file and the key; returns self."""
        src = self._source
        try:
            m = self.trimesh()
        except (ValueError, OSError) as exc:
            raise SceneError(f"{src}: key 'object.file': {exc}") from None
        far = float(np.max(np.linalg.norm(m.vertices, axis=1)))
        if far > MAX_EXTENT:
            raise SceneError(f"{src}: key 'object.pose': position {list(self.object.pose.position)} puts the "
                             f"object {far * 1e3:.0f} mm from the display origin; the display presents "
                             f"objects within {MAX_EXTENT * 1e3:.0f} mm")
        if not self.contains(self.center[None])[0]:
            raise SceneError(f"{src}: key 'object.pose.position': the object's centre "
                             f"{np.round(self.center, 5).tolist()} is not inside the body")
        for i, inc in enumerate(self.inclusions):
            d = float(self.signed_distance(np.asarray(inc.center, float)[None])[0])
            if d > -inc.radius:
                raise SceneError(f"{src}: key 'inclusions.{i}.center': inclusion {inc.name!r} (radius "
                                 f"{inc.radius * 1e3:.1f} mm) is not inside the body: its centre "
                                 f"{list(inc.center)} is {-d * 1e3:.1f} mm deep")
        st = self.stroke
        if (st.kind == "arc" and st.center is not None
            and not self.contains(np.asarray(st.center, float)[None])[0]):
            raise SceneError(f"{src}: key 'stroke.center': {list(st.center)} is not inside the body")
        if st.kind == "polyline":
            bad = np.flatnonzero(self.contains(np.asarray(st.points, float)))
            if len(bad):
                i = int(bad[0])
                raise SceneError(f"{src}: key 'stroke.points.{i}': {list(st.points[i])} is inside the body; "
                                 "give points in front of the surface (they are projected onto it)")
        try:
            self._stroke_table()
        except ValueError as exc:
            raise SceneError(f"{src}: key 'stroke': {exc}") from None
        return self


# ----------------------------------------------------------------------------------------------- loading
_KINDS = {"cylinder", "sphere", "rounded_box", "mesh", "arc", "polyline"}


def _short(v) -> str:
    s = repr(v)
    return s if len(s) <= 80 else s[:77] + "..."


def parse_scene(data, source: str = "<dict>", base_dir: str | os.PathLike = ".", check: bool = True) -> Scene:
    """A :class:`Scene` from a mapping (the YAML's content); ``source`` names it in errors; ``base_dir``
    resolves a relative mesh ``file``; ``check`` runs :meth:`Scene.check_geometry`. Raises
    :class:`SceneError` ``"<source>: key 'object.radius': <why> (value -0.01)"``."""
    if not isinstance(data, dict):
        raise SceneError(f"{source}: a scene must be a mapping with 'name' and 'object', got "
                         f"{type(data).__name__}")
    try:
        sc = Scene.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            loc = [str(p) for p in err["loc"]]
            loc = [p for i, p in enumerate(loc) if not (i > 0 and p in _KINDS)]   # drop the union's tag
            value = err.get("input")
            if err["type"] == "union_tag_invalid":
                loc.append("kind")
                value = err["ctx"]["tag"]
            elif err["type"] == "union_tag_not_found":
                loc.append("kind")
                value = None
            msg = err["msg"].removeprefix("Value error, ")
            lines.append(f"{source}: key '{'.'.join(loc)}': {msg:.300} (value {_short(value)})")
        raise SceneError("\n".join(lines)) from None
    sc._source = source
    sc._base_dir = Path(base_dir).resolve()
    return sc.check_geometry() if check else sc


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a scene file (module doc). Relative mesh paths are resolved against the scene file's
    folder. Raises :class:`SceneError` naming the file, the key and the value: file missing, too large, not
    YAML, duplicate key, unknown key, wrong type or range, mesh unreadable or not closed, object too far from
    the display, centre or an inclusion not inside the body, stroke that cannot be traced."""
    p = Path(os.path.expanduser(str(path)))
    try:
        with open(p, "rb") as fh:
            raw = fh.read(MAX_SCENE_BYTES + 1)
    except FileNotFoundError:
        raise SceneError(f"{p}: scene file not found") from None
    except OSError as exc:
        raise SceneError(f"{p}: cannot read scene file: {exc.strerror or exc}") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(f"{p}: scene file larger than {MAX_SCENE_BYTES} bytes")
    try:
        data = yaml.load(raw.decode("utf-8"), Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except UnicodeDecodeError as exc:
        raise SceneError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except yaml.YAMLError as exc:
        raise SceneError(f"{p}: not valid YAML: {' '.join(str(exc).split())[:300]}") from None
    except RecursionError:
        raise SceneError(f"{p}: not valid YAML: nested too deeply") from None
    return parse_scene(data, str(p), p.parent)


#: why every shipped scene's finger sticks (docs/scenes.md "Contact law")
STICKING_SOURCE = ("µ of moist skin and rubber-like materials typically > 1 (Derler & Gerhardt, Tribol. "
                   "Lett. 45:1-27, 2012): no slip")


def paper_scene() -> Scene:
    """The paper's cylinder (§VI-A) from :mod:`flexsheet.model.geometry`'s constants — what
    ``launch/scenes/cylinder.yaml`` holds; the default wherever no scene is named. Its material is a Gent
    solid (E 10 kPa, ν 0.45, Jm :data:`GENT_JM_RUBBER`): the neo-Hookean body the paper's 50 mm push was first
    modelled with has no mesh-converged solution there (docs/fem.md, the material study). Its finger sticks
    (the one contact law, :data:`STICKING_SOURCE`)."""
    R = paper.CYLINDER_RADIUS
    if not np.allclose(paper.CYLINDER_AXIS, [0.0, 1.0, 0.0]):      # pragma: no cover - a constant
        raise ValueError("paper_scene assumes the cylinder axis +y (the local axis, no rotation)")
    sc = Scene(name="cylinder", description="the paper's cylinder (§VI-A), stroked from 0° to 60° toward +z",
               object=CylinderObject(kind="cylinder", radius=R, length=paper.CYLINDER_LENGTH,
                                     pose=Pose(position=tuple(float(x) for x in paper.CYLINDER_CENTER))),
               material=MaterialSpec(model="gent", E=10e3, nu=0.45, Jm=GENT_JM_RUBBER),
               stroke=ArcStroke(kind="arc", start=(1.0, 0.0, 0.0), toward=(0.0, 0.0, 1.0), start_deg=0.0,
                                end_deg=60.0),
               use=Use(max_depth=0.05, stroke_depth=0.010, reason="the paper pushes its cylinder to 50 mm "
                                                                  "(Fig. 13)"),
               finger=Finger(radius=0.008, contact="sticking", contact_source=STICKING_SOURCE))
    sc._source = "<paper>"
    return sc


def is_paper_cylinder(sc: Scene) -> bool:
    """Whether ``sc``'s object is the paper's cylinder (same radius, length and pose to 1 nm / 1e-9 deg) — the
    object the cylinder-specific FEM models and nonlinear snapshots were built for (material and stroke may
    differ)."""
    o, p = sc.object, paper_scene().object
    return (o.kind == "cylinder"
            and np.allclose([o.radius, o.length], [p.radius, p.length], rtol=0, atol=1e-9)
            and np.allclose(o.pose.position, p.pose.position, rtol=0, atol=1e-9)
            and np.allclose(o.pose.rpy_deg, p.pose.rpy_deg, rtol=0, atol=1e-9))


def load_scene_or_paper(path: str | os.PathLike | None) -> Scene:
    """A node's ``scene`` param: :func:`load_scene` of ``path``, or :func:`paper_scene` for None/empty. Raises
    ``ValueError`` ("scene: <file>: <what is wrong>") on a missing or invalid file."""
    if not path:
        return paper_scene()
    try:
        return load_scene(path)
    except SceneError as exc:
        raise ValueError(f"scene: {exc}") from None
