"""The real-time model the FEM node serves for a scene, built as the node builds it (:func:`served_model`), so
that an experiment judges what the user sees: the paper's cylinder's :class:`~flexsheet.fem.realtime.RealtimeModel`
(mesh from the model table, the shipped nonlinear snapshots where the model table picks them), any other
scene's :class:`~flexsheet.fem.scene_model.SceneModel` with its stored sphere or path table."""

from __future__ import annotations

from flexsheet.fem.config import FemConfig
from flexsheet.model.scenes import Scene, is_paper_cylinder

__all__ = ["fem_models_as_cylinder", "served_model"]


def fem_models_as_cylinder(sc: Scene) -> bool:
    """Whether the cylinder FEM path models ``sc``: the paper's cylinder
    (:func:`flexsheet.model.scenes.is_paper_cylinder`) with the back-half support and no inclusions (its
    material may differ: E, ν are taken from the scene)."""
    return is_paper_cylinder(sc) and sc.support.kind == "back_half" and not sc.inclusions


def served_model(sc: Scene, cfg: FemConfig | None = None, cache_dir: str | None = None, log=None):
    """The model the FEM node serves for ``sc`` at its default params (``cfg``: :class:`FemConfig`; its accuracy
    target, depth range, max depth, strain limit and arc are used; the mesh overrides, ``model`` and the
    no-scene ``E``/``nu``/``finger_radius`` are not: the scene's own finger and material are), its
    precomputation from ``cache_dir`` (None: the default cache; the installed and shipped stores are read
    too) or computed. Returns (model, what: one line naming the model and its table, or "linear ...").
    Raises ``ValueError`` for an unusable stored table."""
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material

    cfg = cfg or FemConfig()
    cache_dir = cache_dir or cfg.cache_dir
    cache = ArrayCache(cache_dir, log)
    if not fem_models_as_cylinder(sc):
        from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC
        from flexsheet.fem.scene_model import SceneModel, attach_scene_table

        m = SceneModel(sc, DEFAULT_SCENE_SPEC, 2, None, cfg.max_depth, cfg.strain_limit, cache_dir, None, log)
        kind, where = attach_scene_table(m, cache)
        return m, (f"linear P2 scene model + the {kind} table ({where})" if where else
                   f"linear P2 scene model (no {kind} table stored)")
    from flexsheet.fem.choose import choose, choose_model, load_model_table, load_table
    from flexsheet.fem.mesh import MeshSpec
    from flexsheet.fem.realtime import RealtimeModel
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, load_or_build

    mat = Material.of_scene(sc.material)
    ch = choose(load_table(), cfg.accuracy_target, cfg.depth_min, cfg.depth_max, cfg.nu, cfg.finger_radius)
    spec = MeshSpec(ch.spec.h, ch.spec.h_fine, ch.spec.refine_radius, cfg.arc_deg)
    m = RealtimeModel(spec, mat, sc.finger.radius, cfg.max_depth, cfg.strain_limit, cache_dir, None, log, ch.order)
    kind, _ = choose_model(load_model_table(), cfg.accuracy_target, cfg.depth_max)
    if kind != "snapshots":
        return m, f"linear P{ch.order} cylinder model (the model table picks {kind})"
    table, _, _ = load_or_build(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, sc.finger.radius, build=False)
    if table is None:
        return m, f"linear P{ch.order} cylinder model (no snapshot table stored)"
    m.attach_snapshots(table, axial_max=cfg.snapshot_axial_max)
    return m, f"P{ch.order} cylinder model + the nonlinear snapshot table"
