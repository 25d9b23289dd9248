"""The planner's shape: every shape kind gives smooth normals by every path (closest point, support point,
centre-ray exit), a convex mesh's against its analytic surface (flexsheet/planning/shape.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from flexsheet.model.scenes import load_scene, parse_scene
from flexsheet.planning.shape import planner_shape

#: an ellipsoid's semi-axes, m (the convex mesh)
AXES = np.array([0.030, 0.045, 0.036])
#: the path's step, m, and the largest turn of the normal between two steps that a smooth surface allows here:
#: a step of 0.1 mm over a radius of curvature >= 10 mm turns the normal by <= 0.6 deg (a facet edge of the
#: 5120-triangle mesh turns it by 3-5 deg)
STEP, MAX_TURN_DEG = 1e-4, 0.6


def _deg(a, b) -> float:
    return math.degrees(math.acos(min(1.0, float(np.dot(a, b)))))


def _ellipsoid_scene(tmp_path, dent: bool = False):
    ico = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    d = np.asarray(ico.vertices)
    v = d * AXES
    if dent:                                # a smooth inward dent on the upper front: non-convex
        c = np.array([0.6, 0.0, 0.8])
        v = v * (1.0 - 0.3 * np.exp(-0.5 * (np.arccos(np.clip(d @ c, -1, 1)) / 0.4) ** 2))[:, None]
    trimesh.Trimesh(v, ico.faces, process=False).export(tmp_path / "body.obj")
    data = {"name": "ellipsoid", "object": {"kind": "mesh", "file": "body.obj",
                                            "pose": {"position": [-AXES[0], 0.0, 0.0],
                                                     "rpy_deg": [20.0, -15.0, 30.0]}}}
    return parse_scene(data, base_dir=tmp_path)


def _true_normal(sc, q) -> np.ndarray:
    R, c = sc.object.pose.R, np.asarray(sc.object.pose.position)
    n = R @ (((np.asarray(q) - c) @ R) / AXES ** 2)
    return n / np.linalg.norm(n)


def _path(n: int = 300) -> list[tuple[float, float, float]]:
    """Fingertips 5 mm in front of the home sheet, sweeping 30 mm across (steps of :data:`STEP`)."""
    return [(0.005, -0.015 + STEP * i, 0.4 * (-0.015 + STEP * i)) for i in range(n)]


def _turns(normals) -> float:
    return max(_deg(a, b) for a, b in zip(normals, normals[1:], strict=False))


def _paths(shape):
    """The normals along the path by each query path: closest point, centre ray (project), support."""
    out = {"closest": [np.asarray(shape.closest(p)[1]) for p in _path()],
           "project": [np.asarray(shape.project(p).normal) for p in _path()]}
    # support: the plane normals turning across the front, each found near the last point
    sup, near = [], (0.0, 0.0, 0.0)
    for th in np.linspace(-0.3, 0.3, 200):
        nn = (math.cos(th), math.sin(th), 0.2 * math.sin(th))
        near = shape.support(nn, near)
        sup.append(np.asarray(shape.closest(near)[1]))
    out["support"] = sup
    return out


def test_a_convex_mesh_has_its_analytic_normal_by_every_path_faceted_normals_fail_it(tmp_path):
    sc = _ellipsoid_scene(tmp_path)
    shape = planner_shape(sc)
    assert shape.convex                    # the centre ray applies: project goes through the ray exit
    for p in _path()[::30]:
        pr = shape.project(p)
        assert _deg(pr.normal, _true_normal(sc, pr.point)) < 0.5
        q, n, _ = shape.closest(p)
        assert _deg(n, _true_normal(sc, q)) < 0.5
    for name, normals in _paths(shape).items():
        assert _turns(normals) < MAX_TURN_DEG, name
    # the same mesh with its face normals (what the planner used before on the centre ray) fails this check
    faceted = sc.shape()
    turns = [np.asarray(faceted.project(p).normal) for p in _path()]
    assert _turns(turns) > 2.0


@pytest.mark.parametrize("scene", ["cylinder", "sphere", "rounded_box", "organ", "dented"])
def test_every_shape_kind_turns_its_normal_smoothly_by_every_path(scene, tmp_path):
    if scene == "dented":
        sc = _ellipsoid_scene(tmp_path, dent=True)
    else:
        from flexsheet.dirs import launch_dir
        sc = load_scene(launch_dir() / "scenes" / f"{scene}.yaml")
    shape = planner_shape(sc)
    limit = MAX_TURN_DEG * (4.0 if scene == "rounded_box" else 1.0)   # its 8 mm edge radius
    for name, normals in _paths(shape).items():
        assert _turns(normals) < limit, (scene, name)
