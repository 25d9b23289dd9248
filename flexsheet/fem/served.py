"""The model the FEM node serves for a scene, built one way: :func:`build_model` (the real-time linear model),
then :func:`attach_table` (the scene's nonlinear table, where one is stored). The FEM node runs both at
start-up and the experiments call them through :func:`served_model`, so that they judge what the user sees.

Every object is a scene (``launch/scenes/*.yaml``; the default is
:data:`~flexsheet.model.scenes.DEFAULT_SCENE_FILE`, the paper's cylinder), and its material and finger come
from its file. What is built for it:

- the paper's cylinder with its back-half support and no inclusions (:func:`uses_cylinder_mesh`): the
  cylinder's own mesh, refined along the working arc (``arc_deg``), and its
  :class:`~flexsheet.fem.realtime.RealtimeModel` (mesh and model kind from :func:`choose_cylinder_model`); its
  table is the nonlinear snapshot table (:mod:`flexsheet.fem.snapshots`);
- any other scene: its gmsh mesh refined along its stroke and its
  :class:`~flexsheet.fem.scene_model.SceneModel`; its table is a sphere's sphere table, else the path table
  along its stroke (:func:`flexsheet.fem.scene_model.attach_scene_table`), else the path table built on the
  scene's first use (:mod:`flexsheet.fem.first_use`; the FEM node builds it when none is stored).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.choose import choose, choose_fem_model, load_model_table, load_table
from flexsheet.fem.config import FemConfig
from flexsheet.fem.contact import finger_at
from flexsheet.fem.first_use import load_first_use_table
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC
from flexsheet.fem.scene_model import SceneModel, attach_scene_table, finger_on_scene
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, load_snapshot_table
from flexsheet.model.scenes import Scene, is_paper_cylinder

__all__ = ["uses_cylinder_mesh", "launch_arc_deg", "CylinderChoice", "choose_cylinder_model", "build_model",
           "TableState",
           "attach_table", "path_table_message", "snapshots_message", "served_model", "served_finger",
           "scene_update_ms"]


def uses_cylinder_mesh(sc: Scene) -> bool:
    """Whether scene ``sc`` is served on the cylinder's own mesh (:class:`RealtimeModel`) with the cylinder's
    snapshot table: the paper's cylinder (:func:`flexsheet.model.scenes.is_paper_cylinder`) with the back-half
    support and no inclusions (its material may differ: E, ν and Jm are the scene's)."""
    return is_paper_cylinder(sc) and sc.support.kind == "back_half" and not sc.inclusions


def launch_arc_deg(sc) -> float:
    """The FEM node's ``arc_deg`` for scene ``sc`` as the launch files set it: the paper cylinder's stroke arc
    (launch/sim.yaml, launch/lab.yaml: 60°, so its rendered surface is refined where the finger goes), 0 for
    any other scene (its mesh follows its stroke by itself)."""
    st = sc.stroke
    if uses_cylinder_mesh(sc) and st.kind == "arc":
        return float(max(abs(st.start_deg), abs(st.end_deg)))
    return 0.0


@dataclass(frozen=True)
class CylinderChoice:
    """The cylinder's real-time model as :func:`choose_cylinder_model` picks it: the mesh ``spec`` and element
    ``order`` and why (``mesh_reason``, one log line), the model ``kind`` ("linear" or "snapshots";
    "corotational" where the model table picks it) and why (``kind_reason``)."""

    spec: MeshSpec
    order: int
    mesh_reason: str
    kind: str
    kind_reason: str


def choose_cylinder_model(cfg: FemConfig, sc: Scene) -> CylinderChoice:
    """The model served for the cylinder scene ``sc`` with the settings ``cfg``. Mesh: the one
    ``mesh_h``/``mesh_h_fine``/``refine_radius``/``order`` set when h and h_fine are > 0, else the cheapest
    the accuracy table (:func:`flexsheet.fem.choose.choose`) finds within ``accuracy_target`` over
    [``depth_min``, ``depth_max``] for the scene's ν and finger radius; the working arc ``arc_deg`` either
    way. Kind: ``model`` when "linear" or "snapshots", else ("auto") the model table's pick over ``depth_max``
    (:func:`flexsheet.fem.choose.choose_fem_model`). Raises ``ValueError`` on a non-positive target or
    depth."""
    if cfg.mesh_h > 0 and cfg.mesh_h_fine > 0:
        spec, order = MeshSpec(cfg.mesh_h, cfg.mesh_h_fine, cfg.refine_radius, cfg.arc_deg), cfg.order
        mesh_reason = f"mesh set by params: P{order} {spec.key()}"
    else:
        ch = choose(load_table(), cfg.accuracy_target, cfg.depth_min, cfg.depth_max, sc.material.nu,
                    sc.finger.radius)
        spec, order = MeshSpec(ch.spec.h, ch.spec.h_fine, ch.spec.refine_radius, cfg.arc_deg), ch.order
        mesh_reason = f"model choice: {ch.reason}"
    kind, why = ("linear", "model=linear") if cfg.model == "linear" else (
        ("snapshots", "model=snapshots") if cfg.model == "snapshots" else
        choose_fem_model(load_model_table(), cfg.accuracy_target, cfg.depth_max))
    return CylinderChoice(spec, order, mesh_reason, kind, why)


def build_model(sc: Scene, cfg: FemConfig) -> tuple[RealtimeModel | SceneModel, str]:
    """The real-time linear model of scene ``sc`` with the settings ``cfg`` (module doc): loaded from
    ``cfg.cache_dir`` ("" = no disk cache), the installed or the shipped store, else precomputed (seconds) and
    cached. Returns (model, one log line: mesh, how it was built, size, why this mesh). Raises ``ValueError``
    on bad settings or an inconsistent cache entry."""
    cache_dir = cfg.cache_dir or None
    if uses_cylinder_mesh(sc):
        ch = choose_cylinder_model(cfg, sc)
        spec, order, why = ch.spec, ch.order, f"the cylinder's mesh; {ch.mesh_reason}"
        m = RealtimeModel(spec, Material.of_scene(sc.material), sc.finger.radius, cfg.max_depth,
                          cfg.strain_limit,
                          cache_dir, None, order)
    else:
        spec, order, why = DEFAULT_SCENE_SPEC, 2, "the scene's mesh along its stroke"
        if cfg.mesh_h > 0 and cfg.mesh_h_fine > 0:
            spec, order = MeshSpec(cfg.mesh_h, cfg.mesh_h_fine, cfg.refine_radius), cfg.order
            why += ", sizes set by params"
        m = SceneModel(sc, spec, order, None, cfg.max_depth, cfg.strain_limit, cache_dir, None)
    line = (f"fem: scene {sc.name!r} ready in {m.precompute_s:.2f} s "
            f"({'cache hit' if m.cache_hit else 'precomputed'}): P{order} {spec.key()}, {m.n_nodes} nodes, "
            f"{m.n_candidates} candidate contact points, {m.solver.nbytes / 1e6:.1f} MB ({why})")
    return m, line


@dataclass(frozen=True)
class TableState:
    """What :func:`attach_table` did: ``kind`` of the scene's table ("snapshots": the cylinder's, "sphere",
    "path"; "none" with ``model`` "linear"; "table" when an unusable one's kind is unknown); ``where`` it was
    loaded from (None: not attached, the linear model serves); ``message`` the node's diagnostics line and its
    logging ``level``; ``what`` one line for the experiments' summaries; ``missing``: the table is wanted and
    not stored; ``error``: why a stored table could not be used (else None)."""

    kind: str
    where: str | None
    message: str
    level: int
    what: str
    missing: bool = False
    error: str | None = None


def snapshots_message(sc: Scene, model: RealtimeModel, how: str) -> str:
    """The diagnostics line of the cylinder scene ``sc``'s attached snapshot table, ``how`` it came
    ("loaded from cache", "built in 900 s", ...)."""
    s = model.snapshots
    return (f"fem: scene {sc.name!r}: nonlinear snapshots {how}: |angle| <= {np.degrees(s.angle_max):.0f} "
            f"deg, depth <= {s.depth_max * 1e3:.0f} mm ({s.nbytes / 1e6:.0f} MB)")


def attach_table(model: RealtimeModel | SceneModel, sc: Scene, cfg: FemConfig) -> TableState:
    """Attach scene ``sc``'s nonlinear table to ``model`` (from :func:`build_model`) as the settings ``cfg``
    ask: none with ``model`` "linear" (for the cylinder also where "auto" and the model table pick linear),
    else the table stored in ``cfg.cache_dir``, the shipped store (``flexsheet/fem/data``) or the installed
    one. Without a stored table, or with an unusable one, the linear model serves and the returned
    :class:`TableState` says so (never raises for a table)."""
    name = f"fem: scene {sc.name!r}"
    cache = ArrayCache(cfg.cache_dir or None)
    if isinstance(model, RealtimeModel):
        return _attach_cylinder_table(model, sc, cfg, cache, name)
    desc = f"P{model.order} scene model"
    if cfg.model == "linear":
        return TableState("none", None, f"{name}: linear {desc} (model=linear)", logging.INFO,
                          f"linear {desc} (model=linear)")
    try:
        kind, where = attach_scene_table(model, cache)
        if where is None and kind == "path":
            first = load_first_use_table(model, cache)
            if first is not None:
                model.attach_path_table(first)
                where = "cache (built on first use)"
    except ValueError as exc:
        msg = f"{name}: nonlinear table unusable ({exc}) - serving LINEAR"
        return TableState("table", None, msg, logging.ERROR, f"linear {desc} (table unusable)",
                          error=str(exc))
    if where is None:
        return TableState(kind, None, f"{name}: no nonlinear {kind} table cached - serving the LINEAR model "
                          f"(build it with `flexsheet experiment fem --scene {sc.source or 'SCENE.yaml'} "
                          "--node-table --out DIR`; the FEM node builds a path table on first use with "
                          "table_build=true)",
                          logging.WARNING, f"linear {desc} (no {kind} table stored)", missing=True)
    if kind == "sphere":
        sm = model.snapshots
        msg = (f"{name}: nonlinear sphere snapshots loaded from {where}: polar angle <= "
               f"{np.degrees(sm.alphas[-1]):.0f} deg, depth <= {sm.depth_max * 1e3:.0f} mm; linear elsewhere")
    else:
        msg = path_table_message(sc, model, f"loaded from {where}")
    return TableState(kind, where, msg, logging.INFO, f"linear {desc} + the {kind} table ({where})")


def path_table_message(sc: Scene, model: SceneModel, how: str) -> str:
    """The diagnostics line of scene ``sc``'s attached path table, ``how`` it came ("loaded from cache",
    "built on first use in 300 s", ...)."""
    pt = model.path_table
    return (f"fem: scene {sc.name!r}: nonlinear path table {how}: {len(pt.fractions)} stations along the "
            f"stroke, depth <= {pt.depth_max * 1e3:.0f} mm, within {pt.reach * 1e3:.0f} mm of the stroke; "
            "linear elsewhere")


def _attach_cylinder_table(model: RealtimeModel, sc: Scene, cfg: FemConfig, cache: ArrayCache,
                           name: str) -> TableState:
    """:func:`attach_table` for the cylinder: its snapshot table where the model kind is "snapshots"."""
    ch = choose_cylinder_model(cfg, sc)
    desc = f"P{model.order} cylinder model"
    if ch.kind != "snapshots":
        return TableState("snapshots", None, f"{name}: linear model ({ch.kind_reason})", logging.INFO,
                          f"linear {desc} (the model table picks {ch.kind})")
    mat = Material.of_scene(sc.material)
    try:
        table = load_snapshot_table(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, sc.finger.radius,
                                    sc.finger.contact)
        if table is not None:
            model.attach_snapshots(table, axial_max=cfg.snapshot_axial_max)
    except ValueError as exc:
        msg = f"{name}: nonlinear snapshot table unusable ({exc}) - serving LINEAR"
        return TableState("snapshots", None, msg, logging.ERROR, f"linear {desc} (snapshot table unusable)",
                          error=str(exc))
    if table is None:
        return TableState("snapshots", None, f"{name}: nonlinear snapshots not cached - serving the LINEAR "
                                             "model "
                          f"(build them with `flexsheet experiment fem --node-table --nu {mat.nu:g} --Jm "
                          f"{mat.Jm:g}`, "
                          "or set snapshot_build=true)", logging.WARNING,
                          f"linear {desc} (no snapshot table stored)",
                          missing=True)
    where = "the shipped store (flexsheet/fem/data)" if cache.shipped() else "cache"
    return TableState("snapshots", where, snapshots_message(sc, model, f"loaded from {where}"), logging.INFO,
                      f"{desc} + the nonlinear snapshot table")


def served_model(sc: Scene, cfg: FemConfig | None = None, cache_dir: str | None = None):
    """The model the FEM node serves for ``sc`` with the settings ``cfg`` (:class:`FemConfig`, default the
    node's defaults): :func:`build_model` then :func:`attach_table`, with ``cache_dir`` in place of
    ``cfg.cache_dir`` when given. Returns (model, what: one line naming the model and its table, or "linear
    ..."). Raises ``ValueError`` for an unusable stored table (the node logs it and serves linear)."""
    cfg = cfg or FemConfig()
    if cache_dir is not None:
        cfg = replace(cfg, cache_dir=cache_dir)
    m, _ = build_model(sc, cfg)
    t = attach_table(m, sc, cfg)
    if t.error is not None:
        raise ValueError(f"scene {sc.name!r}: stored {t.kind} table unusable: {t.error}")
    return m, t.what


def served_finger(sc: Scene, q: np.ndarray, n: np.ndarray, depth: float):
    """The finger pushed ``depth`` m at surface point ``q`` (3,) m along −``n`` (outward unit normal) as the
    scene's served model takes it: on the cylinder's mesh by azimuth and axial offset
    (:func:`flexsheet.fem.contact.finger_at`), on any other scene's by point and normal
    (:func:`flexsheet.fem.scene_model.finger_on_scene`)."""
    if uses_cylinder_mesh(sc):
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
