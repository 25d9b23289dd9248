"""Scenes drawn at random (pure: numpy, trimesh): objects a lab might bring, in any pose, stroked in any
direction, so the display is judged on shapes nobody tuned it to.

:func:`draw_scene` ``(seed)`` gives one scene as a YAML-ready dict and, for a mesh kind, its surface:

* **kind**, uniformly of :data:`KINDS`: ``ellipsoid`` (a convex mesh), ``superquadric`` (convex, box-like,
  exponent 2.5–4), ``capsule`` (a convex mesh), ``cylinder`` (the analytic kind), ``dented`` (an ellipsoid
  with a smooth inward dent somewhere on it: non-convex);
* **size**: semi-axes 20–45 mm (a cylinder: radius 20–40 mm, length 80–140 mm; a capsule: radius 18–30 mm,
  body 40–90 mm);
* **pose**: a uniformly random rotation; then translated so that the body's front (its support point along
  +x) lies on the home sheet (x = 0) and its centre at y = z = 0, as the paper's cylinder lies;
* **stroke**: an arc from the body's centre starting at a direction within 25° of +x (the face toward the
  user), turning toward a uniformly random direction around it (any stroke direction), over 30–60°;
* **material**: neo-Hookean, E log-uniform 3–30 kPa (soft tissue), ν 0.40–0.49; the finger sticks (8 mm).

Meshes are icospheres (level 4: 5120 triangles) scaled per axis (an ellipsoid stays a convex polyhedron), a
superquadric's radial map wrapped in its convex hull, in metres.
The same seed draws the same scene. :func:`write_scene` writes the YAML (and the mesh as OBJ beside it).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

__all__ = ["KINDS", "draw_scene", "write_scene", "rpy_from_rotation", "random_rotation"]

#: the kinds drawn, each equally likely
KINDS = ("ellipsoid", "superquadric", "capsule", "cylinder", "dented")
#: icosphere level of the drawn meshes (5120 triangles, as the organ's)
SUBDIVISIONS = 4


def rpy_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) degrees of rotation ``R`` (3, 3) with R = Rz(yaw)·Ry(pitch)·Rx(roll), the scene
    :class:`~flexsheet.model.scene_parts.Pose` convention
    (:func:`~flexsheet.model.scene_parts.rotation_rpy`)."""
    R = np.asarray(R, float)
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    if abs(R[2, 0]) < 1.0 - 1e-12:
        roll, yaw = math.atan2(R[2, 1], R[2, 2]), math.atan2(R[1, 0], R[0, 0])
    else:                                  # gimbal lock: yaw 0, roll takes the rest
        roll, yaw = math.atan2(-R[1, 2], R[1, 1]), 0.0
    return tuple(math.degrees(a) for a in (roll, pitch, yaw))  # type: ignore[return-value]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation (3, 3) (a unit quaternion from four normals)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _star_mesh(rng: np.random.Generator, kind: str):
    """(trimesh.Trimesh in the local frame, m; a description) of a star-shaped mesh kind."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=SUBDIVISIONS, radius=1.0)
    d = np.asarray(ico.vertices, float)
    a = rng.uniform(0.020, 0.045, size=3)
    if kind == "superquadric":
        p = float(rng.uniform(2.5, 4.0))
        r = np.sum(np.abs(d / a) ** p, axis=1) ** (-1.0 / p)
        what = f"superquadric, semi-axes {np.round(a * 1e3, 1).tolist()} mm, exponent {p:.2f}"
        return trimesh.Trimesh(d * r[:, None], ico.faces, process=False).convex_hull, what
    v = d * a                               # the icosphere scaled: an ellipsoid, still a convex polyhedron
    what = f"ellipsoid, semi-axes {np.round(a * 1e3, 1).tolist()} mm"
    if kind == "dented":
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        depth, width = float(rng.uniform(0.2, 0.35)), float(rng.uniform(0.35, 0.6))
        ang = np.arccos(np.clip(d @ c, -1.0, 1.0))
        v = v * (1.0 - depth * np.exp(-0.5 * (ang / width) ** 2))[:, None]
        what += f", dented {depth * 100:.0f} % over {math.degrees(width):.0f}° (non-convex)"
    return trimesh.Trimesh(v, ico.faces, process=False), what


def _capsule(rng: np.random.Generator):
    """(capsule trimesh along local +y, m; a description)."""
    import trimesh

    radius, body = float(rng.uniform(0.018, 0.030)), float(rng.uniform(0.040, 0.090))
    m = trimesh.creation.capsule(height=body, radius=radius, count=[32, 32])
    m.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0]))   # its +z → +y
    return m, f"capsule, radius {radius * 1e3:.1f} mm, body {body * 1e3:.0f} mm"


def draw_scene(seed: int) -> tuple[dict, object | None]:
    """(scene dict for :func:`flexsheet.model.scenes.parse_scene` / YAML, mesh or None) of draw ``seed``
    (module doc). A mesh kind's dict names ``object.file`` = ``"draw<seed>.obj"``, which :func:`write_scene`
    writes beside the YAML. Deterministic in ``seed`` (an int ≥ 0; ``ValueError`` otherwise)."""
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    rng = np.random.default_rng([0x5CE, int(seed)])
    kind = KINDS[int(rng.integers(len(KINDS)))]
    R = random_rotation(rng)
    mesh = None
    if kind == "cylinder":
        radius, length = float(rng.uniform(0.020, 0.040)), float(rng.uniform(0.080, 0.140))
        what = f"cylinder, radius {radius * 1e3:.1f} mm, length {length * 1e3:.0f} mm"
        ax = R[:, 1]                                       # the local +y axis in the display frame
        # the support along +x of a capped cylinder: the rim point farthest along +x
        ex = np.array([1.0, 0.0, 0.0])
        radial = ex - (ex @ ax) * ax
        rn = np.linalg.norm(radial)
        front = radius * rn + 0.5 * length * abs(ax[0])
        centre_x = -front
        obj = {"kind": "cylinder", "radius": radius, "length": length}
    else:
        mesh, what = _capsule(rng) if kind == "capsule" else _star_mesh(rng, kind)
        v = np.asarray(mesh.vertices) @ R.T
        centre_x = -float(v[:, 0].max())
        obj = {"kind": "mesh", "file": f"draw{seed}.obj"}
    obj["pose"] = {"position": [round(float(centre_x), 6), 0.0, 0.0],
                   "rpy_deg": [round(float(a), 6) for a in rpy_from_rotation(R)]}
    tilt, around = math.radians(float(rng.uniform(0.0, 25.0))), float(rng.uniform(0.0, 2 * math.pi))
    start = np.array([math.cos(tilt), math.sin(tilt) * math.cos(around), math.sin(tilt) * math.sin(around)])
    phi = float(rng.uniform(0.0, 2 * math.pi))
    e1 = np.cross(start, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(start, e1)
    toward = math.cos(phi) * e1 + math.sin(phi) * e2
    span = float(rng.uniform(30.0, 60.0))
    E, nu = float(np.exp(rng.uniform(math.log(3e3), math.log(30e3)))), float(rng.uniform(0.40, 0.49))
    scene = {
        "name": f"draw{seed}",
        "description": (f"drawn object {seed}: {what}; stroke {span:.0f}° toward "
                        f"{np.round(toward, 3).tolist()}"),
        "object": obj,
        "material": {"model": "neo_hookean", "E": round(E, 1), "nu": round(nu, 4)},
        "support": {"kind": "back_half"},
        "finger": {"radius": 0.008, "contact": "sticking",
                   "contact_source": "skin on soft tissue: no slip (as every shipped scene)"},
        "use": {"max_depth": 0.02, "stroke_depth": 0.005, "reason": "a drawn object: stroked and pressed"},
        "stroke": {"kind": "arc", "start": [round(float(x), 6) for x in start],
                   "toward": [round(float(x), 6) for x in toward], "start_deg": 0.0,
                   "end_deg": round(span, 3)},
        "inclusions": [],
    }
    return scene, mesh


def write_scene(seed: int, folder: str | Path) -> Path:
    """Write draw ``seed`` as ``folder/draw<seed>.yaml`` (and ``draw<seed>.obj`` for a mesh kind, 10 nm
    precision); returns the YAML's path. Creates ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    scene, mesh = draw_scene(seed)
    if mesh is not None:
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        lines = ([f"v {x:.8f} {y:.8f} {z:.8f}" for x, y, z in v]
                 + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f])
        (folder / scene["object"]["file"]).write_text("\n".join(lines) + "\n")
    path = folder / f"draw{seed}.yaml"
    path.write_text(f"# {scene['description']}\n# written by flexsheet.model.scene_draw (seed {seed})\n"
                    + yaml.safe_dump(scene, sort_keys=False))
    return path
