"""The real-time model the FEM node serves for a scene, built as the node builds it (:func:`served_model`), so
that an experiment judges what the user sees: the paper's cylinder's :class:`~flexsheet.fem.realtime.RealtimeModel`
(mesh and model kind from :func:`choose_cylinder_model`, the one choice the node makes too; the shipped nonlinear
snapshots where it picks them), any other scene's :class:`~flexsheet.fem.scene_model.SceneModel` with its stored
sphere or path table."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.choose import choose, choose_fem_model, load_model_table, load_table
from flexsheet.fem.config import FemConfig
from flexsheet.fem.contact import finger_at
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC
from flexsheet.fem.scene_model import SceneModel, attach_scene_table, finger_on_scene
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, load_snapshot_table
from flexsheet.model.scenes import Scene, is_paper_cylinder

__all__ = ["fem_models_as_cylinder", "served_model", "served_finger", "scene_update_ms", "CylinderChoice",
           "choose_cylinder_model"]


def fem_models_as_cylinder(sc: Scene) -> bool:
    """Whether the cylinder FEM path models ``sc``: the paper's cylinder
    (:func:`flexsheet.model.scenes.is_paper_cylinder`) with the back-half support and no inclusions (its
    material may differ: E, ν are taken from the scene)."""
    return is_paper_cylinder(sc) and sc.support.kind == "back_half" and not sc.inclusions


@dataclass(frozen=True)
class CylinderChoice:
    """The cylinder's real-time model as :func:`choose_cylinder_model` picks it: the mesh ``spec`` and element
    ``order`` and why (``mesh_reason``, one log line), the model ``kind`` ("linear" or "snapshots"; "corotational"
    where the model table picks it) and why (``kind_reason``)."""

    spec: MeshSpec
    order: int
    mesh_reason: str
    kind: str
    kind_reason: str


def choose_cylinder_model(cfg: FemConfig) -> CylinderChoice:
    """The model the FEM node serves for the paper's cylinder with the settings ``cfg``. Mesh: the one
    ``mesh_h``/``mesh_h_fine``/``refine_radius``/``order`` set when h and h_fine are > 0, else the cheapest the
    accuracy table (:func:`flexsheet.fem.choose.choose`) finds within ``accuracy_target`` over
    [``depth_min``, ``depth_max``] for ``nu`` and ``finger_radius``; the working arc ``arc_deg`` either way.
    Kind: ``model`` when "linear" or "snapshots", else ("auto") the model table's pick over ``depth_max``
    (:func:`flexsheet.fem.choose.choose_fem_model`). Raises ``ValueError`` on a non-positive target or depth."""
    if cfg.mesh_h > 0 and cfg.mesh_h_fine > 0:
        spec, order = MeshSpec(cfg.mesh_h, cfg.mesh_h_fine, cfg.refine_radius, cfg.arc_deg), cfg.order
        mesh_reason = f"mesh set by params: P{order} {spec.key()}"
    else:
        ch = choose(load_table(), cfg.accuracy_target, cfg.depth_min, cfg.depth_max, cfg.nu, cfg.finger_radius)
        spec, order = MeshSpec(ch.spec.h, ch.spec.h_fine, ch.spec.refine_radius, cfg.arc_deg), ch.order
        mesh_reason = f"model choice: {ch.reason}"
    kind, why = ("linear", "model=linear") if cfg.model == "linear" else (
        ("snapshots", "model=snapshots") if cfg.model == "snapshots" else
        choose_fem_model(load_model_table(), cfg.accuracy_target, cfg.depth_max))
    return CylinderChoice(spec, order, mesh_reason, kind, why)


def served_model(sc: Scene, cfg: FemConfig | None = None, cache_dir: str | None = None):
    """The model the FEM node serves for ``sc`` with the settings ``cfg`` (:class:`FemConfig`, default the node's
    defaults; the cylinder's mesh and model kind as :func:`choose_cylinder_model` picks them, its max depth,
    strain limit and snapshot reach; the scene's own finger and material, not the no-scene
    ``E``/``nu``/``finger_radius``), its precomputation from ``cache_dir`` (None: the default cache; the installed
    and shipped stores are read too) or computed. Returns (model, what: one line naming the model and its table,
    or "linear ..."). Raises ``ValueError`` for an unusable stored table."""
    cfg = cfg or FemConfig()
    cache_dir = cache_dir or cfg.cache_dir
    cache = ArrayCache(cache_dir)
    if not fem_models_as_cylinder(sc):
        m = SceneModel(sc, DEFAULT_SCENE_SPEC, 2, None, cfg.max_depth, cfg.strain_limit, cache_dir, None)
        kind, where = attach_scene_table(m, cache)
        return m, (f"linear P2 scene model + the {kind} table ({where})" if where else
                   f"linear P2 scene model (no {kind} table stored)")
    mat = Material.of_scene(sc.material)
    ch = choose_cylinder_model(cfg)
    m = RealtimeModel(ch.spec, mat, sc.finger.radius, cfg.max_depth, cfg.strain_limit, cache_dir, None, ch.order)
    if ch.kind != "snapshots":
        return m, f"linear P{ch.order} cylinder model (the model table picks {ch.kind})"
    table = load_snapshot_table(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, sc.finger.radius, sc.finger.contact)
    if table is None:
        return m, f"linear P{ch.order} cylinder model (no snapshot table stored)"
    m.attach_snapshots(table, axial_max=cfg.snapshot_axial_max)
    return m, f"P{ch.order} cylinder model + the nonlinear snapshot table"

def served_finger(sc: Scene, q: np.ndarray, n: np.ndarray, depth: float):
    """The finger pushed ``depth`` m at surface point ``q`` (3,) m along −``n`` (outward unit normal) as the
    scene's served model takes it: the paper's cylinder's by azimuth and axial offset
    (:func:`flexsheet.fem.contact.finger_at`), any other scene's by point and normal
    (:func:`flexsheet.fem.scene_model.finger_on_scene`)."""
    if fem_models_as_cylinder(sc):
        c = sc.center
        return finger_at(math.atan2(q[2] - c[2], q[0] - c[0]), float(depth), sc.finger.radius,
                         sc.object.radius, c, float(q[1] - c[1]))
    return finger_on_scene(q, n, float(depth), sc.finger.radius)


def scene_update_ms(rt, sc, depths, n_calls: int) -> dict:
    """CPU and wall time (ms) of ``rt.update_finger`` at 5 stroke points × ``depths``, ``n_calls`` each."""
    pts, nrm = sc.stroke_points(5)
    ts, cpu, methods = [], [], []
    for q, n in zip(pts, nrm, strict=True):
        for d in depths:
            fg = served_finger(sc, q, n, float(d))
            methods.append(rt.update_finger(fg).method)
            for _ in range(n_calls):
                t, c = time.perf_counter(), time.thread_time()
                rt.update_finger(fg)
                cpu.append(time.thread_time() - c)
                ts.append(time.perf_counter() - t)
    ts, cpu = np.array(ts) * 1e3, np.array(cpu) * 1e3
    return {"median": float(np.median(cpu)), "p90": float(np.percentile(cpu, 90)),
            "wall_median": float(np.median(ts)), "wall_p90": float(np.percentile(ts, 90)), "n": int(len(ts)),
            "sparse_share": float(np.mean([m == "sparse" for m in methods])), "methods": sorted(set(methods))}
