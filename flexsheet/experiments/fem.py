"""``flexsheet experiment fem --out DIR [--quick] [--jobs N] [--linear-study]
[--Jm JM] [--mirror-study | --holdout-study | --fold-study | --material-study] [--scene FILE]``: physically right deformation
of the pushed cylinder, and the real-time model that reproduces it (``--scene`` with another object: the same
study on that scene, :mod:`flexsheet.experiments.fem_scene`).

1. **Reference** (:mod:`flexsheet.fem.hyperelastic`): the default scene's hyperelastic solid (a Gent solid, Jm 97.2,
   since session 18: ``--Jm``; ``--Jm inf`` is the neo-Hookean solid of the committed full, quick_neohookean, fold and
   held-out figures), total Lagrangian, P2, Newton with load
   stepping (≤ 60 iterations per step), rigid frictionless finger (sphere + shaft), pushed 0 → 50 mm at
   azimuth 0 on a sequence of meshes refined along the whole push path (quarter model by symmetry;
   ``--contact sticking``: a fingertip that does not slip, the contact law is a modelling choice). Mesh
   convergence: the visible-surface difference of each mesh to the finest, at every depth
   (``convergence.json/png``); ``reference.converged`` when there are ≥ 3 meshes, that difference falls with
   every refinement, the last refinement changes the visible surface by ≤ half the target, Newton converged at
   every load step of the finest mesh and none of its elements is inverted at a quadrature point.
   **Skin study** (``convergence.json`` ``skin_study``, :func:`skin_study`): the 3.4 mm mesh with only its
   surface layer refined (2.5 and 1.8 mm), against the whole push tube refined, to tell which part of the
   mesh the unconverged deep push depends on. **Mirror study** (``mirror_study.json/png``,
   :func:`mirror_study`; ``--mirror-study`` runs only it): the azimuth-0 push on half models (no z mirror
   plane) at h_fine 6 / 4.5 / 3.4 mm, cut as every other azimuth is (the plane through the push axis meshed,
   no BC on it), against the quarter models: force, distance from the finest quarter model and the
   half model's own asymmetry; and whether the quarter models' symmetric solution is stable against asymmetric
   modes (:func:`mirror_stability`, the 3.4 and 2.5 mm meshes, cached). **Fold study** (``fold_study.json/png``,
   :func:`fold_study`; ``--fold-study`` runs only it): the reference has no self-contact, so the last three
   levels' states are checked for a surface that passes through itself or creases (:mod:`flexsheet.fem.fold`),
   and for where the largest strain and the levels' largest differences sit; then a sequence that refines the
   push point with the tube (:data:`TIP_LEVELS`, :func:`tip_sequence`: its verdict, a finer tip alone, and
   azimuth-0 snapshot tables on the plain and the tip meshes against its finest level). **Material study**
   (``material_study.json/png``, :func:`material_study`; ``--material-study`` runs only it): the same azimuth-0
   convergence and an azimuth-0 snapshot table on the next-to-finest level, for the neo-Hookean reference and
   for a strain-stiffening Gent solid (``--Jm``, default :data:`flexsheet.fem.material.GENT_JM_RUBBER`), and how far
   the two materials' finest solutions lie apart. ``--Jm`` sets the material of every other study (default: the
   default scene's Gent solid; ``--Jm inf``: neo-Hookean).
2. **Candidates**, judged on the real-time model's rendered vertices outside the finger's footprint
   (lateral distance from the push axis > finger radius + 2 mm; the footprint is hidden by the finger):
   the linear P2 capacitance model, and the nonlinear snapshots (:mod:`flexsheet.fem.snapshots`), sampled every
   5 mm from the reference solve on the node's mesh (h_fine 3.4 mm, the next-to-finest level) and judged at
   every output depth against the finest mesh (h_fine 2.5 mm): the depths between snapshots are held out, and
   the snapshot mesh's own error is in the figure. Full mode: snapshots at azimuths 0, 10 and 20 degrees, and
   azimuth 5 held out against its own solve on the snapshot mesh (interpolation across azimuth at the node
   table's spacing; ``--holdout-study`` runs only that check, on a table at 0 and 10 degrees:
   ``holdout_study.json/png``, :func:`holdout_study`). The table's pushes and the held-out ones are read as
   their **stable branch** (:func:`stable_path`): a push off azimuth 0 can be bistable (a fold beside the
   finger that the loading path carries past the depth where a lower-energy state exists, then snaps); the
   finger is withdrawn from 50 mm to the start, and each depth keeps the state of lower total potential. Accuracy against speed (``accuracy_speed.png/.json``) and the failure map, where
   each model breaks by depth and azimuth (``failure_map.png/.json``). **Snapshot-mesh study**
   (``realtime.snapshot_mesh_study``): the same azimuth-0 check for a table on each skin-study mesh.
   ``flexsheet/fem/model_table.json`` (full mode) is what the node chooses from.
3. ``summary.json``: ``realtime.update_ms``, ``realtime.max_visible_error_mm_0_50``, ``reference.converged``
   with the convergence figures.

``--quick``: two coarse meshes (h_fine 12 / 9 mm), 5 mm outputs, snapshots every 10 mm, a penalty study of
two scales, a skin study of one size (5 mm), a mirror study of one cut half model (h_fine 12 mm, against the
quarter model of the same h_fine): a test's run, 133 s cold on the 2-core machine with ``--jobs 2`` and nothing
beside it (session 15, the stable sweeps included; 148 s with the half model at 9 mm), seconds cached; it does
not meet the targets
and cannot be "converged" (fewer than 3 meshes). The full mode (h_fine 8 / 6 / 4.5 / 3.4 / 2.5 mm,
:data:`FULL_LEVELS`, 2.5 mm outputs, snapshots at azimuths 0, 10 and 20 every 5 mm, azimuth 5 held out,
penalty study, mirror study) is ~4.5 h of CPU cold on the 2-core machine with another solve beside it
(sessions 8–10, ``cpu_seconds`` in convergence.json: the 2.5 mm mesh 31 min, the 3.4 mm 9 min, the two skin
meshes 12 and 23 min, the azimuth-5, -10 and -20 paths ~37–39 min each on uncut meshes; session 11, in
mirror_study.json: the mirror study's cut half models 10, 22 and 71 min with two or three solves on the 2 cores,
its stability check 11 min).
Those CPU figures are from the einsum assembly, about twice the present one's (session 12, docs/fem.md).
``--jobs N`` (default: the cores) solves the pushes the run reads in N worker processes first
(:func:`planned_solves`, :func:`prefetch`); ``--level N`` solves one mesh only and ``--node-table --azimuth A``
one azimuth (for a run over several sittings or machines); every solve is cached
(:class:`flexsheet.fem.cache.ArrayCache`), so a second run takes seconds (27 s).
``--linear-study`` also reruns the linear mesh study (``accuracy_table.json``, ``hertz``, ``stability``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import dataclass, field, replace

import numpy as np

from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache, cache_key
from flexsheet.fem.choose import DEFAULT_SPEC, MODEL_TABLE_PATH, visible_mask
from flexsheet.fem.contact import finger_at
from flexsheet.fem.fold import CREASE_STRETCH, VERTEX_TOL, fold_report, lateral_distance, outer_surface
from flexsheet.fem.hyperelastic import (
    CONTACT_LAWS,
    DEFAULT_CONTACT,
    PENALTY_SCALE,
    PREVIOUS_VERSION,
    SOLVER_VERSION,
    UNLOAD_VERSION,
    HyperelasticModel,
    PathState,
    RefSpec,
    capsule_at,
    reference_mesh,
    solve_path,
    solver_tag,
    stable_states,
)
from flexsheet.fem.material import GENT_JM_RUBBER, Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.snapshots import (
    DEFAULT_GRID,
    DEFAULT_REF_SPEC,
    SnapshotGrid,
    load_or_build,
    reusable_table,
    reused_azimuths,
)
from flexsheet.fem.solver import solve_full
from flexsheet.model.scenes import paper_scene

__all__ = ["main", "Settings", "settings_for"]

FINGER_R = 0.008
FULL_LEVELS = (0.008, 0.006, 0.0045, 0.0034, 0.0025)   #: h_fine (m) of the full run's meshes, coarse → fine
TARGET = 0.0007
PENALTY_TOL_MM = 0.1    #: the default penalty must lie this close (visible surface) to a 10× stiffer one
#: the fold study's tip-refined sequence (h_fine, tip_h) m: the push tube and, within TIP_RADIUS of the push point,
#: the material that ends up stretched over the fingertip, refined together (docs/fem.md, fold study)
TIP_LEVELS = ((0.0045, 0.0016), (0.0034, 0.0012), (0.0025, 0.0009))
TIP_RADIUS = 0.005
TIP_CHECK = 0.0008      #: a finer tip alone on the middle tip level's tube (does the apex still move the surface?)
NEWTON_ITERS = 60       #: per load step; a snap-through step (a crease forming beside the finger) needs ~25


@dataclass
class Settings:
    """What one run computes: convergence meshes (coarse → fine, azimuth 0), the snapshot grid and mesh,
    held-out azimuths (deg) checked against their own reference solves, the linear model's mesh (its surface
    vertices are the rendered vertices), the updates timed per configuration."""

    levels: list = field(default_factory=list)
    depth_step: float = 0.0025
    fine_step: float = 0.00125
    grid: SnapshotGrid = DEFAULT_GRID
    snap_spec: RefSpec = DEFAULT_REF_SPEC
    holdout_deg: tuple = ()
    linear_spec: MeshSpec = DEFAULT_SPEC
    n_time: int = 300
    quick: bool = False
    contact: str = DEFAULT_CONTACT
    penalty_level: int = 1
    penalty_scales: tuple = (1e3, 1e4, PENALTY_SCALE, 10 * PENALTY_SCALE)
    skin_sizes: tuple = (0.0025, 0.0018)
    half_levels: tuple = (0.006, 0.0045, 0.0034)
    tip_levels: tuple = TIP_LEVELS
    tip_check: float = TIP_CHECK


def settings_for(quick: bool) -> Settings:
    """The ``--quick`` or the full settings. Every mesh is refined along the whole push path (a tube of radius
    18 mm from the contact point to 55 mm deep, graded to ``h`` over a further 18 mm), the refinement ratio
    between levels ≈ 1.33. The snapshot table is the solution on ``snap_spec`` every ``grid.depth_step``
    (full: the node's mesh, the next-to-finest level; quick: the finest); it is judged against the finest level
    at every ``fine_step``."""
    if quick:
        lv = [RefSpec(0.016, hf, 0.018, True, 0.055) for hf in (0.012, 0.009)]
        return Settings(levels=lv, depth_step=0.005, fine_step=0.005,
                        grid=SnapshotGrid((0.0,), 0.05, 0.01, 1.0, 0.001, 0.002), snap_spec=lv[-1], holdout_deg=(),
                        linear_spec=MeshSpec(0.016, 0.006, 0.012, 0.0), n_time=50, quick=True, penalty_level=0,
                        penalty_scales=(PENALTY_SCALE, 10 * PENALTY_SCALE), skin_sizes=(0.005,),
                        half_levels=(0.012,), tip_levels=((0.012, 0.005), (0.009, 0.004)), tip_check=0.0)
    lv = [replace(DEFAULT_REF_SPEC, h_fine=hf) for hf in FULL_LEVELS]
    grid = SnapshotGrid((0.0, 10.0, 20.0), 0.05, 0.005, DEFAULT_GRID.dtheta_deg, DEFAULT_GRID.dy, DEFAULT_GRID.drho)
    # the snapshots on the node's mesh (DEFAULT_REF_SPEC, the next-to-finest level), judged against the finest at
    # azimuth 0; azimuth 5 held out between snapshots at the node table's 10 deg spacing, against its own solve on
    # that mesh (10, 20: the node table's cached paths, --node-table --azimuth 10 / 20)
    return Settings(levels=lv, depth_step=0.0025, fine_step=0.0025, grid=grid, snap_spec=DEFAULT_REF_SPEC,
                    holdout_deg=(5.0,),
                    linear_spec=MeshSpec(0.012, 0.004, 0.012, 60.0), n_time=1000)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexsheet experiment fem", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example: flexsheet experiment fem --quick --out /tmp/fem\n"
                                       "         flexsheet experiment fem --out /tmp/fem --node-table --azimuth 10\n"
                                       "         flexsheet experiment fem --quick --mirror-study --out /tmp/fem\n"
                                       "         flexsheet experiment fem --holdout-study --out /tmp/fem\n"
                                       "         flexsheet experiment fem --quick --fold-study --out /tmp/fem\n"
                                       "         flexsheet experiment fem --quick --material-study --out /tmp/fem\n"
                                       "         flexsheet experiment fem --quick --scene launch/scenes/sphere.yaml "
                                       "--out /tmp/fem_sphere\n"
                                       "         flexsheet experiment fem --scene launch/scenes/rounded_box.yaml "
                                       "--node-table --jobs 2 --out /tmp/rb_table")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--quick", action="store_true", help="coarse meshes, azimuth 0 only (minutes cold, seconds cached)")
    p.add_argument("--nu", type=float, default=None,
                   help=f"Poisson's ratio (default: the scene's, {Material().nu:g} for the default scene)")
    p.add_argument("--E", type=float, default=None,
                   help=f"Young's modulus, Pa (default: the scene's, {Material().E:g} for the default scene)")
    p.add_argument("--Jm", type=float, default=None, metavar="JM",
                   help="the reference's material: a Gent solid with this limiting extensibility (I1 - 3 <= JM; "
                        f"{GENT_JM_RUBBER:g} is Gent's natural-rubber fit), or inf: neo-Hookean (default: the "
                        f"scene's, {DEFAULT_MATERIAL.Jm:g} for the default scene, launch/scenes/cylinder.yaml; the committed "
                        "figures in docs/figures/fem/full, quick_neohookean, fold and holdout are neo-Hookean runs, --Jm "
                        "inf). Cached apart; see --material-study")
    p.add_argument("--cache-dir", default=DEFAULT_CACHE_DIR, help="cache folder ('' disables; default %(default)s)")
    p.add_argument("--linear-study", action="store_true", help="also rerun the linear mesh study (slow)")
    p.add_argument("--level", type=int, default=None,
                   help="only solve convergence level N (0 = coarsest; fills the cache, so levels can run in "
                        "parallel processes before the full run), then exit")
    p.add_argument("--write-model-table", action="store_true",
                   help=f"write {os.path.relpath(MODEL_TABLE_PATH)} (default in full mode with the default "
                        "--contact and the default scene's material)")
    p.add_argument("--contact", choices=CONTACT_LAWS, default=DEFAULT_CONTACT,
                   help="the finger's contact law in the reference: sticking (the fingertip does not slip on the "
                        "tissue) or frictionless (default %(default)s)")
    p.add_argument("--mirror-study", action="store_true",
                   help="run the mirror study only (the azimuth-0 push on cut half models against the quarter "
                        "models, and the quarter models' stability; it solves what the "
                        "cache lacks, the convergence meshes included: hours cold in full mode) and write "
                        "mirror_study.json/png, then exit")
    p.add_argument("--holdout-study", action="store_true",
                   help="run the held-out azimuth check only (full mode: a snapshot table on azimuths 0 and 10 "
                        "judged at 5 deg against its own solve on the cut half model, and at 0 against the finest "
                        "mesh; it solves what the cache lacks, ~1-2 h of two cores cold) and write "
                        "holdout_study.json/png, then exit")
    p.add_argument("--fold-study", action="store_true",
                   help="run the fold study only: does the reference's surface fold through itself (it has no "
                        "self-contact), and is that where it does not converge? The last three convergence "
                        "levels at azimuth 0 (quick: its two), a tip-refined sequence (the push point refined "
                        "with the tube), a finer tip alone, and azimuth-0 snapshot tables on the plain and tip "
                        "meshes (full: ~1.5 h of two cores cold here, under a minute cached); writes fold_study.json/png, "
                        "then exits")
    p.add_argument("--material-study", action="store_true",
                   help="run the material study only: the azimuth-0 mesh convergence and an azimuth-0 snapshot "
                        "table for the neo-Hookean reference and for a Gent solid (--Jm, default "
                        f"{GENT_JM_RUBBER:g}); full: ~1 h of two cores cold here, seconds cached; writes "
                        "material_study.json/png, then exits")
    p.add_argument("--node-table", action="store_true",
                   help="build the FEM node's nonlinear snapshot table (azimuths 0, 5, 7.5, 10-50 every 10, 55 and 60 deg, "
                        "2.5 mm depth steps, on the full run's h_fine 3.4 mm mesh) into the cache the node reads, "
                        "then exit. ~40 min of one core per azimuth (0 is shared with the full run's 3.4 mm level); "
                        "every azimuth's solve is cached, and a cached or shipped table on fewer azimuths is "
                        "extended (only the azimuths it lacks are solved)")
    p.add_argument("--ship", action="store_true",
                   help="with --node-table: also write the table, packed (float16 surface fields, compressed), into "
                        "flexsheet/fem/data/, which the node reads on a machine that never solved it (commit it)")
    p.add_argument("--holdout-azimuth", type=float, action="append", default=[], metavar="DEG",
                   help="with --node-table: judge the table at this azimuth (between its own) against that push's "
                        "own solve on the table's mesh (solved unless cached, ~30 min of one core); into "
                        "node_table.json. Repeatable")
    p.add_argument("--between-depths", type=float, action="append", default=[], metavar="DEG",
                   help="with --node-table: judge the table between its depths at this azimuth (one of its own) "
                        "against that push solved at half the table's load step (~20 min of one core at 0, cached); "
                        "into node_table.json. Repeatable")
    p.add_argument("--mesh-check", action="store_true",
                   help="the table mesh's noise: with --node-table --holdout-azimuth (the cylinder) each held-out "
                        "push also on a twin of the table's mesh (same sizes, laid out anew; ~30 min of one core "
                        "each); with --scene SPHERE --node-table at each --holdout-azimuth (else 0 degrees) the push "
                        "on the twin and on the study's wider-tube mesh and its twin (~20 min each): each mesh's "
                        "noise, and the table against each")
    p.add_argument("--azimuth", type=float, default=None, metavar="DEG",
                   help="with --node-table: solve only this azimuth's path into the cache and exit (run the "
                        "azimuths in parallel processes, then --node-table alone assembles the table)")
    p.add_argument("--jobs", type=int, default=default_jobs(), metavar="N",
                   help="solve the independent reference pushes the cache lacks in N worker processes first "
                        "(default %(default)s: the cores here; 1 solves them one by one in this process)")
    p.add_argument("--stations", type=int, default=13, metavar="K",
                   help="with --scene (not the cylinder or the sphere) --node-table: the path table's stations, K "
                        "evenly spaced fractions of the stroke, ends included (default %(default)s, the shipped "
                        "rounded box table's; each a 0-50 mm push, 4-9 min wall two at a time on the rounded box); "
                        "see flexsheet.experiments.path_table")
    p.add_argument("--holdout-fraction", type=float, action="append", default=[], metavar="F",
                   help="with --scene (not the cylinder or the sphere) --node-table: judge the path table at this "
                        "fraction of the stroke (between stations) against that push's own solve (default: the "
                        "midpoints of every second interval). Repeatable")
    p.add_argument("--scene", default=None,
                   help="scene file (launch/scenes/*.yaml); another object than the paper's cylinder runs "
                        "flexsheet.experiments.fem_scene on it (same summary keys), e.g. --scene "
                        "launch/scenes/sphere.yaml")
    return p


_LOG_PREFIX = ""         #: set in prefetch workers ("[solver 1] "), so their lines can be told apart


def _log(msg: str) -> None:
    print(_LOG_PREFIX + msg, flush=True)


# ---- reference solves (cached) -------------------------------------------------------------------------------
#: the reference's default material: the default scene's (the paper's cylinder, a Gent solid since session 18;
#: ``--Jm inf`` is the neo-Hookean solid every study before it ran)
DEFAULT_MATERIAL = Material.of_scene(paper_scene().material)


def _law(mat: Material) -> str:
    """The reference's hyperelastic law in words: "neo-Hookean" or "Gent (Jm …)"."""
    return f"Gent (Jm {mat.Jm:g})" if mat.gent else "neo-Hookean"


def _ref_model(spec: RefSpec, angle_deg: float, mat: Material, penalty_scale: float = PENALTY_SCALE
               ) -> HyperelasticModel:
    half_z = spec.half_z and angle_deg == 0.0
    mesh = reference_mesh(replace(spec, half_z=half_z), angle_deg)
    return HyperelasticModel(mesh, mat, sym_y=True, sym_z=half_z, penalty_scale=penalty_scale)


def _load_step(depths: np.ndarray) -> float:
    """Load step (m) of a :func:`reference_path` through ``depths`` m: their spacing, at most 2.5 mm."""
    return float(min(0.0025, np.min(np.diff(np.concatenate([[0.0], depths])))))


def _reference_key(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, probes: np.ndarray,
                   contact: str, penalty_scale: float, version: str = SOLVER_VERSION) -> str:
    """Cache key of a :func:`reference_path` (``spec`` as it solves it: the half model off azimuth 0) with the
    solver ``version``: everything the path depends on."""
    return cache_key(solver_tag(contact, version), spec.key(), angle_deg, np.round(depths, 9).tolist(), mat.key(),
                     FINGER_R, cache_key(np.round(probes, 9).tobytes()), f"step={_load_step(depths):.6g}",
                     f"iters={NEWTON_ITERS}", f"pen={penalty_scale:g}")


def _reference_keys(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, probes: np.ndarray,
                    contact: str, penalty_scale: float) -> tuple[str, str]:
    """(this solver version's, the previous version's) :func:`_reference_key` of the path :func:`reference_path`
    solves for ``spec`` at ``angle_deg`` (:func:`_as_solved` applied)."""
    spec, angle_deg = _as_solved(spec, angle_deg)
    return tuple(_reference_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale, v)
                 for v in (SOLVER_VERSION, PREVIOUS_VERSION))


def _check_dofs(path: dict, model: HyperelasticModel) -> None:
    """Raise ``RuntimeError`` when the cached reference ``path`` (with its ``dofs``) has another DOF count than
    ``model``, the mesh re-made to read it (the cache key does not carry gmsh's version: a new gmsh may mesh
    differently)."""
    if "dofs" in path and int(path["dofs"]) != model.n:
        raise RuntimeError(f"the cached reference path has {int(path['dofs'])} DOF, the re-meshed model {model.n}: "
                           "gmsh meshes differently now; clear the fem cache (~/.cache/flexsheet/fem) and re-solve")


def _as_solved(spec: RefSpec, angle_deg: float) -> tuple[RefSpec, float]:
    """(spec, azimuth) as :func:`reference_path` solves and keys them: -0.0 → 0.0, and the half model
    (``half_z`` off) away from azimuth 0."""
    angle_deg = float(angle_deg) + 0.0
    return (replace(spec, half_z=False) if angle_deg != 0.0 and spec.half_z else spec), angle_deg


def _previous_version_path(cache: ArrayCache, old_key: str) -> dict | None:
    """The cached path under the previous solver version's key when it is this version's too: no Newton call
    ran out of iterations in it (PREVIOUS_VERSION; such a call counts NEWTON_ITERS at its depth by itself);
    else None."""
    p_old = cache.path("reference", old_key)
    if p_old is None or not os.path.exists(p_old):
        return None
    old = cache.load("reference", old_key)
    return old if old is not None and int(np.max(old["newton"])) < NEWTON_ITERS else None


def _path_record(model: HyperelasticModel, states: list[PathState], probes: np.ndarray, angle_deg: float) -> dict:
    """The per-depth arrays :func:`reference_path` caches for ``states`` on ``model`` (see there), ``probes``
    (k, 3) m the rendered vertices."""
    from flexsheet.fem.snapshots import _probe, _sample

    P = _probe(model, probes)
    qp, vis = [], []
    a = math.radians(angle_deg)
    axis = np.array([math.cos(a), 0.0, math.sin(a)])
    for s in states:
        qp.append(int(np.count_nonzero(np.linalg.det(model.deformation(s.u)).min(axis=1) <= 0)))
        ue = s.u[model.edofs]
        bad = np.flatnonzero(np.linalg.det(model.nodal_deformation(s.u)).min(axis=1) <= 0)
        xc = (model.points[model.edofs[bad]] + ue[bad]).mean(axis=1) - model.mesh.center
        lat = np.linalg.norm(xc - np.outer(xc @ axis, axis), axis=1)
        vis.append(int(np.count_nonzero(lat > FINGER_R + 0.002)))
    return {"u": np.stack([_sample(P, s.u, probes, model) for s in states]),
            "u_dof": np.stack([s.u for s in states]).astype(np.float32),
            "force": np.array([s.force for s in states]), "inverted": np.array([s.inverted for s in states]),
            "inverted_qp": np.array(qp), "inverted_nodal_visible": np.array(vis),
            "min_detF": np.array([s.min_detF for s in states]),
            "max_strain": np.array([s.max_strain for s in states]),
            "penetration": np.array([s.penetration for s in states]),
            "newton": np.array([s.iterations for s in states]), "converged": np.array([s.converged for s in states])}


def reference_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                   probes: np.ndarray, contact: str = DEFAULT_CONTACT, penalty_scale: float = PENALTY_SCALE) -> dict:
    """Hyperelastic (``mat``: neo-Hookean or Gent) push at ``angle_deg`` through ``depths`` (load steps = the depth spacing, ≤ 2.5 mm) on
    ``spec``'s mesh — its half model (``half_z`` off) away from azimuth 0, as
    :func:`flexsheet.fem.snapshots.build_table` meshes it, so one solve serves both — sampled at ``probes`` (k, 3) m
    (display frame, mirrored into the modelled part); cached.
    Returns {"u": (D, k, 3) m, "u_dof": (D, P, 3) m float32 (every DOF point, for the snapshot table), "force",
    "inverted" (elements with det F ≤ 0 at a quadrature point or P2 node), "inverted_qp" (at a quadrature
    point), "inverted_nodal_visible" (nodally inverted elements whose deformed centroid lies outside the
    footprint, > finger radius + 2 mm from the push axis), "min_detF", "max_strain", "penetration", "newton",
    "seconds", "cpu_seconds", "dofs", "converged"}. ``contact``: the finger's contact law
    (:data:`flexsheet.fem.hyperelastic.CONTACT_LAWS`); ``penalty_scale``: the contact penalty κ = scale·E/h."""
    spec, angle_deg = _as_solved(spec, angle_deg)
    step = _load_step(depths)
    key, old_key = _reference_keys(spec, angle_deg, depths, mat, probes, contact, penalty_scale)
    p_new = cache.path("reference", key)
    if p_new is not None and not os.path.exists(p_new):
        old = _previous_version_path(cache, old_key)
        if old is not None:
            _log(f"fem: reference {spec.key()} at {angle_deg:g} deg: the {PREVIOUS_VERSION} path (no Newton call ran "
                 f"out of iterations) is the {SOLVER_VERSION} path; re-keyed")
            cache.save("reference", key, old)
            return old

    def compute() -> dict:
        t, tc = time.perf_counter(), time.process_time()
        model = _ref_model(spec, angle_deg, mat, penalty_scale)
        _log(f"reference {spec.key()} at {angle_deg:g} deg: {model.n} DOF, load steps {step * 1e3:g} mm, "
             f"{contact} contact, penalty {penalty_scale:g} E/h ...")
        states = solve_path(model, math.radians(angle_deg), depths, FINGER_R, step=step, iters=NEWTON_ITERS,
                            log=lambda s: _log("  " + s.strip()), contact=contact)
        return {**_path_record(model, states, probes, angle_deg),
                "seconds": np.array(time.perf_counter() - t), "cpu_seconds": np.array(time.process_time() - tc),
                "dofs": np.array(model.n)}

    z, hit, _ = cache.get_or_compute("reference", key, compute,
                                     f"reference {spec.key()} at {angle_deg:g} deg, penalty {penalty_scale:g} E/h")
    return z


def _stable_key(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, probes: np.ndarray,
                contact: str, penalty_scale: float) -> str:
    """Cache key of a :func:`stable_path`: its loading path's key and the unloading sweep's version."""
    spec, angle_deg = _as_solved(spec, angle_deg)
    return cache_key(UNLOAD_VERSION, _reference_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale))


def stable_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                probes: np.ndarray, contact: str = DEFAULT_CONTACT, penalty_scale: float = PENALTY_SCALE) -> dict:
    """:func:`reference_path` with the stable branch where the push is bistable: the loading path, then the
    finger withdrawn from its deepest state back to the shallowest (:func:`flexsheet.fem.hyperelastic.stable_states`,
    the path's load steps), and at each depth the state of lower total potential Π. The
    snapshot tables and the held-out pushes they are judged on read these, so both sides make the same choice.
    Cached (kind "stable", read before the loading path is); frictionless contact only (else the loading path
    itself). Returns :func:`reference_path`'s dict plus "branch" (D,) int (1: the unloaded state),
    "energy_loading", "energy_unloading" (D,) J (Π of each branch's state), "unload_seconds"."""
    if contact != "frictionless":
        return reference_path(spec, angle_deg, depths, mat, cache, probes, contact, penalty_scale)
    spec, angle_deg = _as_solved(spec, angle_deg)
    key = _stable_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale)

    def compute() -> dict:
        p = reference_path(spec, angle_deg, depths, mat, cache, probes, contact, penalty_scale)
        t = time.perf_counter()
        model = _ref_model(spec, angle_deg, mat, penalty_scale)
        _check_dofs(p, model)
        states = _path_states(p, depths, depths)
        a = math.radians(angle_deg)
        caps = lambda d: capsule_at(a, d, FINGER_R, model.mesh.radius, model.mesh.center)  # noqa: E731
        _log(f"stable branch {spec.key()} at {angle_deg:g} deg: unloading from {depths[-1] * 1e3:g} mm ...")
        chosen, branch, energies = stable_states(model, caps, states, step=_load_step(depths), iters=NEWTON_ITERS,
                                                 log=lambda s: _log("  " + s.strip()))
        return {**_merge_rows(p, branch, lambda rows: _path_record(model, [chosen[j] for j in rows], probes,
                                                                    angle_deg)),
                "branch": branch, "energy_loading": energies[:, 0], "energy_unloading": energies[:, 1],
                "unload_seconds": np.array(time.perf_counter() - t)}

    z, _, _ = cache.get_or_compute("stable", key, compute, f"stable branch {spec.key()} at {angle_deg:g} deg")
    n_un = int(np.sum(z["branch"]))
    _log(f"stable branch {spec.key()} at {angle_deg:g} deg: the unloaded state at {n_un} of {len(depths)} depths"
         + (f" ({', '.join(f'{d * 1e3:g}' for d in depths[np.asarray(z['branch']) == 1])} mm)" if n_un else ""))
    return z


def _merge_rows(p: dict, branch: np.ndarray, record) -> dict:
    """``p`` (a :func:`reference_path` dict, per-depth arrays of length D) with the rows where ``branch`` (D,)
    is 1 replaced by ``record(rows)`` (a :func:`_path_record` of those rows' states), each array's dtype kept."""
    rows = np.flatnonzero(branch)
    out = dict(p)
    if len(rows) == 0:
        return out
    for k_, v in record(rows).items():
        arr = np.array(p[k_], copy=True)
        arr[rows] = v.astype(arr.dtype)
        out[k_] = arr
    return out


def _depths(step: float) -> np.ndarray:
    """Push depths step, 2·step, … 50 mm (m)."""
    return np.round(np.arange(1, int(round(0.05 / step)) + 1) * step, 9)


def _visible(points: np.ndarray, fixed: np.ndarray, angle_deg: float, depth: float, mesh) -> np.ndarray:
    """(k,) bool: rendered vertices the finger does not hide. ``points`` (k, 3) m are the vertices' positions
    in the *deformed* reference surface (rest + the reference's displacement): vertices dragged down onto the
    finger's side lie inside the footprint though they started outside it. ``fixed`` (k,) support vertices."""
    fg = finger_at(math.radians(angle_deg), depth, FINGER_R, mesh.radius, mesh.center)
    return visible_mask(points, fg) & ~fixed


def _visible_diffs(a: dict, b: dict, depths: np.ndarray, verts: np.ndarray, fixed: np.ndarray, mesh,
                   angle_deg: float = 0.0) -> list[float]:
    """Largest distance (m) between two reference paths' fields ``a["u"]``, ``b["u"]`` (D, k, 3) m at the
    rendered vertices ``verts`` (k, 3) m, per depth (D,) m, over the vertices visible on ``b``'s deformed
    surface (:func:`_visible`, the push at azimuth ``angle_deg``)."""
    return [float(np.linalg.norm(a["u"][j] - b["u"][j], axis=1)[
        _visible(verts + b["u"][j], fixed, angle_deg, d, mesh)].max()) for j, d in enumerate(depths)]


def _at_depths(path: dict, path_depths: np.ndarray, depths: np.ndarray) -> dict:
    """``path`` (a :func:`reference_path` result sampled at ``path_depths``, m) with its per-depth arrays taken
    at the nearest of ``depths`` (m)."""
    sub = np.array([int(np.argmin(np.abs(path_depths - d))) for d in depths])
    return {k: (v[sub] if np.ndim(v) and len(v) == len(path_depths) else v) for k, v in path.items()}


FOLD_REGION = 0.03      #: m: surface points within this rest distance of the push axis are checked for folds
FOLD_VERSION = "fold-3"  #: bump when flexsheet/fem/fold.py's checks change (fold_path's cache key)


def fold_path(spec: RefSpec, angle_deg: float, path: dict, depths: np.ndarray, mat: Material,
              cache: ArrayCache) -> dict:
    """Self-contact and crease check (:func:`flexsheet.fem.fold.fold_report`) of every state of a
    :func:`reference_path` ``path`` (its ``u_dof``, at ``depths`` m) on ``spec``'s mesh at ``angle_deg``: the
    reference has no self-contact, so where its surface passes through itself it is not a physical solution.
    Cached (kind "fold", keyed by the states themselves). Returns (D,) arrays: "max_winding" (0.5 on a smooth
    surface, α/2π at the bottom of a fold of interior angle α, > 1 where the surface lies inside the body),
    "n_penetrating" (surface points with w > 1), "max_penetration" m, "min_stretch" (smallest in-plane stretch
    of the surface triangles off the footprint), "n_creased" (triangles below
    :data:`flexsheet.fem.fold.CREASE_STRETCH`), "worst_lateral" / "worst_drop" m (the largest-w point's rest
    distance from the push axis and its motion along the push); the same with the footprint included ("all_…":
    the material over the fingertip); "max_strain" the largest principal Green–Lagrange strain of any element
    and "max_strain_lateral_m" that element's rest distance from the push axis; "seconds". Raises ``RuntimeError`` when the
    re-made mesh has another DOF count than the path (:func:`_check_dofs`)."""
    spec, angle_deg = _as_solved(spec, angle_deg)
    ud = np.asarray(path["u_dof"])
    key = cache_key(FOLD_VERSION, spec.key(), angle_deg, np.round(depths, 9).tolist(), FOLD_REGION, FINGER_R,
                    CREASE_STRETCH, VERTEX_TOL,
                    cache_key(np.ascontiguousarray(ud).tobytes()))

    def compute() -> dict:
        t = time.perf_counter()
        model = _ref_model(spec, angle_deg, mat)
        _check_dofs(path, model)
        surf = outer_surface(model)
        rows = []
        for j, d in enumerate(depths):
            caps = capsule_at(math.radians(angle_deg), float(d), FINGER_R, model.mesh.radius, model.mesh.center)
            u = ud[j].reshape(-1, 3).astype(float)
            r = fold_report(model, surf, u, caps, FOLD_REGION)
            a = fold_report(model, surf, u, caps, FOLD_REGION, margin=-np.inf)     # the footprint too
            F = model.deformation(u)
            ev = np.linalg.eigvalsh(0.5 * (np.einsum("eqki,eqkj->eqij", F, F) - np.eye(3)))[..., -1].max(axis=1)
            e = int(np.argmax(ev))
            r.update(all_max_winding=a["max_winding"], all_n_penetrating=a["n_penetrating"],
                     all_max_stretch=a["max_stretch"], all_max_stretch_lateral_m=a["max_stretch_lateral_m"],
                     max_strain=float(ev[e]),
                     max_strain_lateral_m=float(lateral_distance(model.points[model.edofs[e]].mean(axis=0)[None],
                                                                  caps)[0]))
            rows.append(r)
        out = {k: np.array([r[k] if r[k] is not None else np.nan for r in rows], float)
               for k in ("max_winding", "n_penetrating", "max_penetration_m", "min_stretch", "n_creased_tris",
                         "worst_lateral_m", "worst_drop_m", "all_max_winding", "all_n_penetrating",
                         "all_max_stretch", "all_max_stretch_lateral_m", "max_strain", "max_strain_lateral_m")}
        out["seconds"] = np.array(time.perf_counter() - t)
        return out

    z, _, _ = cache.get_or_compute("fold", key, compute, f"fold check {spec.key()} at {angle_deg:g} deg")
    return z


def _fold_rep(f: dict) -> dict:
    """The JSON form of a :func:`fold_path` result (mm where a length)."""
    return {"max_winding": f["max_winding"].tolist(), "n_penetrating": f["n_penetrating"].astype(int).tolist(),
            "max_penetration_mm": (f["max_penetration_m"] * 1e3).tolist(), "min_stretch": f["min_stretch"].tolist(),
            "n_creased_tris": f["n_creased_tris"].astype(int).tolist(),
            "worst_lateral_mm": (f["worst_lateral_m"] * 1e3).tolist(),
            "worst_drop_mm": (f["worst_drop_m"] * 1e3).tolist(),
            "with_footprint": {"max_winding": f["all_max_winding"].tolist(),
                               "n_penetrating": f["all_n_penetrating"].astype(int).tolist(),
                               "max_stretch": f["all_max_stretch"].tolist(),
                               "max_stretch_rest_lateral_mm": (f["all_max_stretch_lateral_m"] * 1e3).tolist()},
            "max_principal_strain": f["max_strain"].tolist(),
            "max_strain_rest_lateral_mm": (f["max_strain_lateral_m"] * 1e3).tolist(), "seconds": float(f["seconds"])}


def _where_worst(a: dict, b: dict, j: int, depth: float, verts: np.ndarray, fixed: np.ndarray, mesh) -> dict:
    """Where the largest visible difference between paths ``a`` and ``b`` (D, k, 3) m at row ``j`` sits: its
    rendered vertex's rest distance from the push axis (azimuth 0) and its motion along the push on ``b`` (mm)."""
    vis = _visible(verts + b["u"][j], fixed, 0.0, depth, mesh)
    dist = np.linalg.norm(a["u"][j] - b["u"][j], axis=1)
    i = int(np.flatnonzero(vis)[np.argmax(dist[vis])])
    rel = verts[i] - mesh.center
    return {"lateral_mm": float(math.hypot(rel[1], rel[2]) * 1e3), "drop_mm": float(-b["u"][j][i][0] * 1e3),
            "difference_mm": float(dist[i] * 1e3)}


def fold_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Does the reference fold its own surface, and is that where it does not converge? The last three
    convergence levels (quick: its two) pushed at azimuth 0 (their loading paths, as :func:`convergence` reads
    them): per level and depth the :func:`fold_path` figures, the visible-surface difference to the finest level
    and where the largest one sits (rest distance from the push axis, drop along the push). "fold_free_to_mm":
    on the finest level, the deepest depth to which no surface point lies inside the body (the reference is a
    solution of the modelled problem there; past it the model lacks the self-contact the folding surface
    needs); "tip_sequence" (:func:`tip_sequence`). Returns {"depths_mm", "region_mm", "levels" (per level:
    "h_fine_mm", "dofs", :func:`_fold_rep`'s keys, "force_N", and for the coarser ones
    "difference_to_finest_mm" and "worst_difference_at" [{"lateral_mm", "drop_mm", "difference_mm"}]),
    "tip_sequence", "fold_free_to_mm", "first_penetration_mm_by_h_fine_mm", "crease_stretch", "what"}; lengths
    in mm. Raises ``RuntimeError`` as :func:`fold_path`."""
    depths = _depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    lv = st.levels[-3:]
    fdepths = _depths(st.fine_step)
    fine = _at_depths(reference_path(lv[-1], 0.0, fdepths, mat, cache, verts, st.contact), fdepths, depths)
    rows = []
    for i, s in enumerate(lv):
        p = fine if i == len(lv) - 1 else reference_path(s, 0.0, depths, mat, cache, verts, st.contact)
        f = fold_path(s, 0.0, p, depths, mat, cache)
        row = {"h_fine_mm": s.h_fine * 1e3, "dofs": int(p["dofs"]), **_fold_rep(f), "force_N": p["force"].tolist()}
        if i < len(lv) - 1:
            row["difference_to_finest_mm"] = [e * 1e3 for e in _visible_diffs(p, fine, depths, verts, fixed, rm.mesh)]
            row["worst_difference_at"] = [_where_worst(p, fine, j, d, verts, fixed, rm.mesh)
                                          for j, d in enumerate(depths)]
        rows.append(row)
    tip = tip_sequence(st, mat, cache, rm, fine)
    pen = np.asarray(rows[-1]["n_penetrating"]) > 0
    free = float(depths[np.argmax(pen) - 1] * 1e3) if pen.any() and pen.argmax() > 0 else \
        (0.0 if pen.any() else float(depths[-1] * 1e3))
    first = {r["h_fine_mm"]: (float(depths[np.argmax(np.asarray(r["n_penetrating"]) > 0)] * 1e3)
                              if np.any(np.asarray(r["n_penetrating"]) > 0) else None) for r in rows}
    return {"depths_mm": (depths * 1e3).tolist(), "region_mm": FOLD_REGION * 1e3, "levels": rows,
            "tip_sequence": tip, "fold_free_to_mm": free, "first_penetration_mm_by_h_fine_mm": first,
            "crease_stretch": CREASE_STRETCH,
            "what": "self-contact and crease check of the reference at azimuth 0 (flexsheet/fem/fold.py): the "
                    "generalised winding number w of the closed outer surface at its own points within "
                    f"{FOLD_REGION * 1e3:g} mm (rest) of the push axis, off the finger's footprint: 0.5 on a "
                    "smooth surface, alpha/2pi at the bottom of a fold of interior angle alpha, > 1 where the "
                    "point lies inside the body (the surface has passed through itself: the model has no "
                    "self-contact); max_penetration_mm how deep; min_stretch the smallest in-plane stretch of "
                    "the surface triangles off the footprint (a neo-Hookean surface creases below ~0.65)"}


def tip_specs(st: Settings) -> tuple[list[RefSpec], RefSpec | None]:
    """(the tip-refined sequence, coarse → fine: ``st.tip_levels`` (h_fine, tip_h) m on the finest level's spec
    with ``tip_radius`` :data:`TIP_RADIUS`; the tip check: the middle level with the finer tip ``st.tip_check``,
    or None when it is 0)."""
    seq = [replace(st.levels[-1], h_fine=hf, tip_h=th, tip_radius=TIP_RADIUS) for hf, th in st.tip_levels]
    chk = replace(seq[len(seq) // 2], tip_h=st.tip_check) if st.tip_check > 0 and len(seq) > 1 else None
    return seq, chk


def _tip_verdict(e: np.ndarray, depths: np.ndarray, newton_ok: bool, inverted_qp: int,
                 tip_change_mm: float | None) -> dict:
    """The tip sequence's verdict: ``e`` (L-1, D) mm each coarser level's visible difference to the finest at
    ``depths`` (D,) m (:func:`_sequence_verdict`), the finest level's Newton convergence and inverted count, and
    ``tip_change_mm`` the tip check's largest change (mm; None without one). "converged": ≥ 3 levels, monotone,
    the last change and the tip check's each ≤ half the target, Newton converged, nothing inverted."""
    half = TARGET * 1e3 / 2
    monotone, last, to_depth = _sequence_verdict(e, depths) if len(e) else (False, float("nan"), 0.0)
    conv = len(e) + 1 >= 3 and monotone and last <= half and bool(newton_ok) and int(inverted_qp) == 0
    crit = ("convergence.json's: at least 3 meshes, the visible-surface difference to the finest falls with every "
            "refinement (depths >= 5 mm), the last refinement changes it by <= half the 0.7 mm target, Newton "
            "converged at every load step of the finest mesh, no element of it inverted at a quadrature point")
    if tip_change_mm is not None:
        conv = conv and tip_change_mm <= half
        crit += "; and a finer tip alone on the middle level changes it by <= half the target (tip_check)"
    return {"monotone_decrease": monotone, "last_refinement_change_mm": last, "converged_to_depth_mm": to_depth,
            "converged": conv, "criterion": crit}


def tip_sequence(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, tube_fine: dict) -> dict:
    """The push at azimuth 0 on meshes that refine the push tube *and* the material at the push point (within
    :data:`TIP_RADIUS`; the material stretched over the fingertip, where the plain levels are unresolved) together
    (``st.tip_levels``). Per level: DOF, CPU, force, the largest strain and stretch, the visible-surface
    difference to the finest tip level and to the finest plain level (``tube_fine``); the sequence's verdict by
    :func:`convergence`'s criterion ("converged": ≥ 3 levels, monotone at every depth ≥ 5 mm, last change ≤ half
    the target, Newton converged at every step of the finest, nothing inverted at a quadrature point, and, with a
    tip check, that check within half the target too); the tip check: the middle level with a finer tip alone,
    its difference to that level (does the apex still move the visible surface?); the azimuth-0 snapshot tables
    of :func:`_tip_snapshots`."""
    depths = _depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    seq, chk = tip_specs(st)
    paths = [reference_path(s, 0.0, depths, mat, cache, verts, st.contact) for s in seq]
    rows = []
    for s, p in zip(seq, paths, strict=True):
        f = fold_path(s, 0.0, p, depths, mat, cache)
        rows.append({"h_fine_mm": s.h_fine * 1e3, "tip_h_mm": s.tip_h * 1e3, "tip_radius_mm": s.tip_radius * 1e3,
                     "dofs": int(p["dofs"]), "cpu_seconds": float(p["cpu_seconds"]), "force_N": p["force"].tolist(),
                     "newton_converged": bool(p["converged"].all()), "inverted_qp_max": int(p["inverted_qp"].max()),
                     "newton_iterations": p["newton"].tolist(),
                     "max_principal_strain": p["max_strain"].tolist(),
                     "max_surface_stretch": f["all_max_stretch"].tolist(),
                     "max_winding_with_footprint": f["all_max_winding"].tolist(),
                     "n_penetrating": f["all_n_penetrating"].astype(int).tolist(),
                     "difference_to_finest_mm": [e * 1e3 for e in _visible_diffs(p, paths[-1], depths, verts, fixed,
                                                                                  rm.mesh)],
                     "difference_to_finest_plain_level_mm": [e * 1e3 for e in _visible_diffs(
                         p, tube_fine, depths, verts, fixed, rm.mesh)]})
    out = {"levels": rows}
    tc = None
    if chk is not None:
        pc = reference_path(chk, 0.0, depths, mat, cache, verts, st.contact)
        mid = paths[len(seq) // 2]
        out["tip_check"] = {"h_fine_mm": chk.h_fine * 1e3, "tip_h_mm": chk.tip_h * 1e3, "dofs": int(pc["dofs"]),
                            "cpu_seconds": float(pc["cpu_seconds"]), "max_principal_strain": pc["max_strain"].tolist(),
                            "newton_iterations": pc["newton"].tolist(),
                            "difference_to_its_level_mm": [e * 1e3 for e in _visible_diffs(pc, mid, depths, verts,
                                                                                           fixed, rm.mesh)],
                            "difference_to_finest_mm": [e * 1e3 for e in _visible_diffs(pc, paths[-1], depths, verts,
                                                                                       fixed, rm.mesh)]}
        tc = max(out["tip_check"]["difference_to_its_level_mm"])
    fine = rows[-1]
    out.update(_tip_verdict(np.array([r["difference_to_finest_mm"] for r in rows[:-1]]), depths,
                            fine["newton_converged"], fine["inverted_qp_max"], tc))
    monotone, last = out["monotone_decrease"], out["last_refinement_change_mm"]
    out["snapshots"] = _tip_snapshots(st, mat, cache, rm, seq, paths[-1])
    _log(f"tip sequence: last refinement {last:.3f} mm, monotone {monotone}, converged {out['converged']}")
    return out


def _tip_snapshots(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, seq: list[RefSpec],
                   finest: dict) -> dict:
    """Azimuth-0 snapshot tables (``st.grid``'s depth step, from the stable branch as every table) on the
    next-to-finest tip level and on the next-to-finest plain level (full mode: the node's mesh), each judged
    against the finest tip level ``finest`` at every output depth (the depths between snapshots held out): the
    worst visible error (mm) and the depth from which it exceeds the target. ``rm``'s table is left as it was."""
    depths = _depths(st.depth_step)
    snap_d = st.grid.depths()
    cases = [{"angle_deg": 0.0, "depth": float(d), "u": finest["u"][j],
              "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(depths)]
    rows = []
    for spec in (st.levels[-2], seq[-2]):
        src, err = _azimuth0_table_errors(st, mat, cache, rm, spec, cases)
        err = np.array(err) * 1e3
        over = np.flatnonzero(err > TARGET * 1e3)
        rows.append({"spec": spec.key(), "h_fine_mm": spec.h_fine * 1e3, "tip_h_mm": spec.tip_h * 1e3,
                     "dofs": int(src["dofs"]), "error_mm": err.tolist(), "max_visible_error_mm": float(err.max()),
                     "over_target_from_mm": float(depths[over[0]] * 1e3) if len(over) else None})
        _log(f"tip snapshots {spec.key()}: azimuth 0 worst {err.max():.2f} mm against the finest tip level")
    return {"azimuth_deg": 0.0, "snapshot_depth_step_mm": st.grid.depth_step * 1e3, "target_mm": TARGET * 1e3,
            "against": "the finest tip level, every output depth", "tables": rows}


def plot_fold_study(out: str, fs: dict) -> None:
    """fold_study.png: per level, the largest winding number (off the footprint, and with it) and the smallest
    surface stretch against depth, beside the visible-surface difference to the finest level (:func:`fold_study`, the numbers in
    ``fold_study.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = fs["depths_mm"]
    fig, axs = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axs.ravel()
    for k, r in enumerate(fs["levels"]):
        lab = f"h_fine {r['h_fine_mm']:g} mm ({r['dofs']} DOF)"
        col = f"C{k}"
        ax[0].plot(d, r["max_winding"], "o-", color=col, ms=3, label=f"{lab}, off the footprint")
        ax[0].plot(d, r["with_footprint"]["max_winding"], "s--", color=col, ms=3, lw=0.8,
                   label=f"{lab}, footprint too (fingertip)")
        ax[1].plot(d, r["min_stretch"], "o-", color=col, ms=3, label=lab)
        if "difference_to_finest_mm" in r:
            ax[2].plot(d, r["difference_to_finest_mm"], "o-", color=col, ms=3, label=f"{lab} vs finest")
    ax[0].axhline(0.5, color="k", lw=0.6, ls=":")
    ax[0].axhline(1.0, color="r", lw=0.8, ls="--", label="w = 1: surface inside the body")
    ax[0].set_ylabel("largest winding number w of the surface")
    ax[1].axhline(fs["crease_stretch"], color="r", lw=0.8, ls="--", label="neo-Hookean crease onset")
    ax[1].set_ylabel("smallest in-plane surface stretch off the footprint")
    ax[2].axhline(0.35, color="k", lw=0.8, ls="--", label="half the 0.7 mm target")
    ax[2].set_ylabel("visible-surface difference to the finest (mm)")
    tip = fs["tip_sequence"]
    for k, r in enumerate(tip["levels"][:-1]):
        ax[3].plot(d, r["difference_to_finest_mm"], "o-", color=f"C{k + 3}", ms=3,
                   label=f"tube {r['h_fine_mm']:g} mm + tip {r['tip_h_mm']:g} mm ({r['dofs']} DOF) vs finest")
    fin = tip["levels"][-1]
    ax[3].plot(d, fin["difference_to_finest_plain_level_mm"], "s--", color="k", ms=3, lw=0.8,
               label=f"finest (tube {fin['h_fine_mm']:g} + tip {fin['tip_h_mm']:g} mm) vs the finest plain level")
    if "tip_check" in tip:
        tc = tip["tip_check"]
        ax[3].plot(d, tc["difference_to_its_level_mm"], "^-", color="C7", ms=3,
                   label=f"tip {tc['tip_h_mm']:g} mm vs its level (tube {tc['h_fine_mm']:g} mm)")
    ax[3].axhline(0.35, color="k", lw=0.8, ls="--", label="half the 0.7 mm target")
    ax[3].set_ylabel("visible-surface difference (mm)")
    ax[3].set_title(f"tip-refined sequence: last refinement {tip['last_refinement_change_mm']:.2f} mm, "
                    f"converged {tip['converged']}", fontsize=9)
    for a in ax:
        a.set_xlabel("push depth (mm)")
        a.legend(fontsize=6)
    pen = max(max(r["max_penetration_mm"]) for r in fs["levels"])
    fig.suptitle(f"Reference at azimuth 0: folds of its own surface (no self-contact); fold-free to "
                 f"{fs['fold_free_to_mm']:g} mm on the finest mesh; deepest self-penetration {pen:.2f} mm",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fold_study.png"), dpi=110)
    plt.close(fig)


def _sequence_verdict(e: np.ndarray, depths: np.ndarray) -> tuple[bool, float, float]:
    """Mesh-sequence verdict from ``e`` (L-1, D) mm, each coarser level's visible-surface difference to the
    finest at ``depths`` (D,) m: (the difference falls with every refinement at every depth ≥ 5 mm, the last
    refinement's largest change in mm, the deepest depth in mm to which both hold with the last change ≤ half
    the target; 0 with fewer than 3 levels)."""
    deep = depths >= 0.005 - 1e-12
    monotone = bool(np.all(np.diff(e[:, deep], axis=0) < 0)) if len(e) > 1 else False
    last = float(e[-1].max())
    ok = (e[-1] <= TARGET * 1e3 / 2) & (~deep | np.all(np.diff(e, axis=0) < 0, axis=0) if len(e) > 1 else False)
    n_ok = int(np.argmin(ok)) if not np.all(ok) else len(ok)
    return monotone, last, (float(depths[n_ok - 1] * 1e3) if n_ok and len(e) > 1 else 0.0)


def convergence(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> tuple[dict, dict]:
    """Mesh convergence at azimuth 0 on the rendered vertices; returns (report, finest level's path, sampled
    every ``st.fine_step``)."""
    depths = _depths(st.depth_step)
    fdepths = _depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    paths = [reference_path(s, 0.0, depths, mat, cache, verts, st.contact) for s in st.levels[:-1]]
    fine = reference_path(st.levels[-1], 0.0, fdepths, mat, cache, verts, st.contact)
    paths.append(_at_depths(fine, fdepths, depths))
    rep = {"depths_m": depths.tolist(), "levels": []}
    for s, p in zip(st.levels, paths, strict=True):
        err = _visible_diffs(p, paths[-1], depths, verts, fixed, rm.mesh)
        rep["levels"].append({"spec": s.__dict__, "h_fine_m": s.h_fine, "dofs": int(p["dofs"]),
                              "seconds": float(p["seconds"]), "error_vs_finest_mm": [e * 1e3 for e in err],
                              "force_N": p["force"].tolist(), "inverted_nodal": p["inverted"].tolist(),
                              "inverted_qp": p["inverted_qp"].tolist(), "min_detF": p["min_detF"].tolist(),
                              "inverted_nodal_visible": p["inverted_nodal_visible"].tolist(),
                              "max_strain": p["max_strain"].tolist(), "penetration_mm": (p["penetration"] * 1e3).tolist(),
                              "newton_iterations": p["newton"].tolist(), "newton_converged": bool(p["converged"].all()),
                              "cpu_seconds": float(p["cpu_seconds"])})
    e = np.array([lv["error_vs_finest_mm"] for lv in rep["levels"][:-1]])          # (L-1, D)
    deep = depths >= 0.005 - 1e-12
    monotone, last, rep["converged_to_depth_mm"] = _sequence_verdict(e, depths)
    no_qp = int(fine["inverted_qp"].max()) == 0
    rep.update({"monotone_decrease": monotone, "last_refinement_change_mm": last,
                "finest_inverted_nodal_at_50mm": int(fine["inverted"][-1]),
                "finest_inverted_nodal_visible_max": int(fine["inverted_nodal_visible"].max()),
                "finest_inverted_qp_at_50mm": int(fine["inverted_qp"][-1]),
                "finest_inverted_qp_max": int(fine["inverted_qp"].max()),
                "finest_newton_converged": bool(fine["converged"].all()),
                "converged": monotone and last <= TARGET * 1e3 / 2 and bool(fine["converged"].all()) and no_qp,
                "criterion": "at least 3 meshes; the visible-surface difference to the finest mesh falls with every "
                             "refinement (depths >= 5 mm), the last refinement changes it by <= half the 0.7 mm "
                             "target, Newton converged at every load step of the finest mesh, and no element of it "
                             "is inverted at a quadrature point"})
    if len(e) > 1:
        r = st.levels[-3].h_fine / st.levels[-2].h_fine if len(st.levels) >= 3 else 2.0
        with np.errstate(divide="ignore", invalid="ignore"):
            p_obs = np.log(e[-2] / e[-1]) / np.log(r)
        rep["observed_order_median"] = float(np.nanmedian(p_obs[deep]))
    _log(f"convergence: errors vs finest at 50 mm {[round(float(x[-1]), 3) for x in e]} mm, converged "
         f"{rep['converged']}")
    return rep, fine


def penalty_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Convergence in the contact penalty κ = scale·E/h on one mesh (``st.penalty_level``), azimuth 0: per
    scale the largest visible-surface difference (mm) to the stiffest scale per depth, the deepest penetration
    and the force at 50 mm. ``converged``: the default scale (:data:`PENALTY_SCALE`) lies within
    ``PENALTY_TOL_MM`` of the next 10× stiffer one at every depth (the penalty error is then below the mesh's)
    and Newton converged at every load step of both."""
    depths = _depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    spec = st.levels[st.penalty_level]
    scales = sorted(st.penalty_scales)
    paths = [reference_path(spec, 0.0, depths, mat, cache, verts, st.contact, sc) for sc in scales]
    rows = [{"penalty_scale": sc,
             "error_vs_stiffest_mm": [e * 1e3 for e in _visible_diffs(p, paths[-1], depths, verts, fixed, rm.mesh)], "penetration_mm_at_50mm": float(p["penetration"][-1]) * 1e3,
             "penetration_mm_max": float(np.max(p["penetration"])) * 1e3, "force_N_at_50mm": float(p["force"][-1]),
             "newton_converged": bool(p["converged"].all()), "cpu_seconds": float(p["cpu_seconds"])}
            for sc, p in zip(scales, paths, strict=True)]
    i = scales.index(PENALTY_SCALE)
    nxt = 10 * PENALTY_SCALE
    if nxt in scales:
        j = scales.index(nxt)
        change = max(_visible_diffs(paths[i], paths[j], depths, verts, fixed, rm.mesh)) * 1e3
    else:
        change = float("nan")
    rep = {"mesh": spec.__dict__, "depths_m": depths.tolist(), "default_scale": PENALTY_SCALE, "scales": rows,
           "default_vs_10x_stiffer_mm": change, "tolerance_mm": PENALTY_TOL_MM,
           "converged": bool(change <= PENALTY_TOL_MM and rows[i]["newton_converged"]
                             and (nxt not in scales or rows[scales.index(nxt)]["newton_converged"]))}
    _log(f"penalty study on h_fine {spec.h_fine * 1e3:g} mm: default vs 10x stiffer {change:.3f} mm, penetration at "
         f"50 mm {[round(r['penetration_mm_at_50mm'], 3) for r in rows]} mm for {scales}")
    return rep


def skin_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict, fine: dict) -> dict:
    """Where the unconverged part of the reference lies: the next-to-finest convergence mesh (full mode: the
    snapshot mesh) with only its surface layer refined (``skin_h`` in ``st.skin_sizes``: the material that
    wraps the fingertip and lines the crater, :class:`flexsheet.fem.hyperelastic.RefSpec`), against the same mesh
    refined throughout its push tube (the finest convergence level). ``conv``: :func:`convergence`'s report;
    ``fine``: its finest path. Per variant the largest visible-surface difference (mm, per depth) to the
    unrefined mesh and to the finest level (visible on the finer of the two, as in :func:`convergence`), the
    force at 50 mm, DOF and CPU, and ``change_vs_previous_mm`` (to the previous, coarser skin; the first: to the
    unrefined mesh); ``tube_change_mm``: the finest level against the unrefined mesh (from ``conv``). Azimuth 0,
    every ``st.depth_step``."""
    depths = _depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    unrefined = st.levels[-2]
    base = reference_path(unrefined, 0.0, depths, mat, cache, verts, st.contact)
    fine = _at_depths(fine, _depths(st.fine_step), depths)
    rows, prev = [], base
    for h in st.skin_sizes:
        spec = replace(unrefined, skin_h=h)
        p = reference_path(spec, 0.0, depths, mat, cache, verts, st.contact)
        rows.append({"skin_h_m": h, "spec": spec.__dict__, "dofs": int(p["dofs"]), "cpu_seconds": float(p["cpu_seconds"]),
                     "newton_converged": bool(p["converged"].all()), "force_N_at_50mm": float(p["force"][-1]),
                     "change_vs_unrefined_mm": [e * 1e3 for e in _visible_diffs(base, p, depths, verts, fixed, rm.mesh)],
                     "change_vs_previous_mm": [e * 1e3 for e in _visible_diffs(prev, p, depths, verts, fixed, rm.mesh)],
                     "diff_vs_finest_mm": [e * 1e3 for e in _visible_diffs(p, fine, depths, verts, fixed, rm.mesh)]})
        prev = p
    tube = conv["levels"][-2]["error_vs_finest_mm"]
    _log("skin study at 50 mm: skin refinement moves the visible surface by "
         f"{[round(r['change_vs_unrefined_mm'][-1], 2) for r in rows]} mm, the tube refinement by {tube[-1]:.2f} mm")
    return {"depths_m": depths.tolist(), "unrefined": unrefined.__dict__, "finest": st.levels[-1].__dict__,
            "unrefined_dofs": int(base["dofs"]), "unrefined_force_N_at_50mm": float(base["force"][-1]),
            "finest_force_N_at_50mm": float(fine["force"][-1]), "tube_change_mm": tube, "skins": rows}


def mirror_asymmetry(path: dict, spec: RefSpec, depths: np.ndarray, mat: Material, rm: RealtimeModel) -> list[float]:
    """Per depth (D,) m, the largest |u(x) − M·u(M·x)| (m) over the rendered vertices x visible on the deformed
    surface of an azimuth-0 :func:`reference_path` ``path`` solved on ``spec``'s mesh, M the mirror in z
    through the cylinder's axis: how far the solution is from mirror-symmetric. u(M·x) is probed from the
    path's DOF field (``u_dof``) on the re-meshed model (gmsh is deterministic). A quarter model (``half_z``)
    gives 0 up to float32 rounding, by construction."""
    from flexsheet.fem.snapshots import _probe, _sample

    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    mirrored = verts.copy()
    mirrored[:, 2] = 2 * rm.mesh.center[2] - mirrored[:, 2]
    model = _ref_model(spec, 0.0, mat)
    _check_dofs(path, model)
    P = _probe(model, mirrored)
    out = []
    for j, d in enumerate(depths):
        um = _sample(P, path["u_dof"][j].astype(float), mirrored, model)
        um[:, 2] *= -1.0
        vis = _visible(verts + path["u"][j], fixed, 0.0, d, rm.mesh)
        out.append(float(np.linalg.norm(path["u"][j] - um, axis=1)[vis].max()))
    return out


def mirror_blocks(m: HyperelasticModel) -> tuple[np.ndarray, np.ndarray]:
    """The fixed DOFs (P, 3) bool of the two symmetry blocks of a quarter model ``m`` (``sym_z``): symmetric —
    ``m``'s own BCs (support, y plane u_y = 0, z plane u_z = 0); antisymmetric in z — on the z plane u_x = u_y = 0
    and u_z free (the y plane keeps u_y = 0 and the support stays fixed, so both are symmetric in y). Raises
    ``ValueError`` when ``m`` has no z mirror plane."""
    if not m.sym_z:
        raise ValueError("mirror_blocks needs a quarter model (sym_z)")
    P = len(m.points)
    sym = m.fixed_mask.reshape(P, 3).copy()
    anti = sym.copy()
    anti[np.abs(m.points[:, 2] - m.mesh.center[2]) < 1e-9] = [True, True, False]
    anti[m.support] = True
    return sym, anti


def mirror_stability(path: dict, spec: RefSpec, depths: np.ndarray, mat: Material, contact: str = DEFAULT_CONTACT,
                     n_eig: int = 2) -> dict:
    """Is the mirror-symmetric azimuth-0 solution of a quarter model (``spec.half_z``; its
    :func:`reference_path` ``path`` at ``depths`` (D,) m) stable against modes antisymmetric in z, which the
    quarter model cannot make? At a symmetric equilibrium on a symmetric mesh the tangent splits into a
    symmetric and an antisymmetric block (:func:`mirror_blocks`; both symmetric in y). Per converged state:
    the lowest eigenvalue of each (N/m, unit-norm DOF vectors, so mesh-dependent; scipy ``eigsh`` shift-invert,
    fixed start vector) and, definitively, whether the antisymmetric block is positive definite (CHOLMOD's
    Cholesky succeeds: :func:`flexsheet.fem.solver.factor`). An antisymmetric block that is not positive definite is
    a symmetry-breaking bifurcation; a small positive eigenvalue, a state a small asymmetry moves far
    (imperfection sensitivity, Koiter). Linear stability at the sampled states only: it does not exclude an
    asymmetric branch coexisting with the symmetric one. Returns {"sym_N_per_m", "anti_N_per_m",
    "anti_positive_definite", "residual_N" (D,) free residual norm (u_dof is float32), "dofs", "cpu_seconds"}.
    Raises ``ValueError`` for a spec without the z mirror plane or a contact law other than frictionless (the
    sticking anchors are not stored with the path), ``RuntimeError`` when the re-meshed model has another DOF
    count than the path (gmsh meshes differently)."""
    import scipy.sparse.linalg as sla

    from flexsheet.fem.hyperelastic import capsule_at
    from flexsheet.fem.solver import NotPositiveDefinite, factor

    if not spec.half_z:
        raise ValueError(f"mirror_stability needs a quarter model (half_z), got {spec.key()}")
    if contact != "frictionless":
        raise ValueError(f"mirror_stability supports the frictionless contact law only, got {contact!r}")
    tc = time.process_time()
    m = _ref_model(spec, 0.0, mat)
    _check_dofs(path, m)
    sym, anti = mirror_blocks(m)
    k = m.penalty()
    out = {"sym_N_per_m": [], "anti_N_per_m": [], "anti_positive_definite": [], "residual_N": [], "dofs": int(m.n)}
    for j, d in enumerate(depths):
        u = path["u_dof"][j].astype(float)
        r, K = m.residual_tangent(u, capsule_at(0.0, float(d), FINGER_R, m.mesh.radius, m.mesh.center), k)
        out["residual_N"].append(float(np.linalg.norm(r[~sym.ravel()])))
        for name, fixed in (("sym_N_per_m", sym), ("anti_N_per_m", anti)):
            fr = np.flatnonzero(~fixed.ravel())
            Kf = K[fr][:, fr].tocsc()
            ev = sla.eigsh(Kf, k=n_eig, sigma=-1e-3 * float(np.abs(Kf.diagonal()).mean()), which="LM",
                           v0=np.ones(len(fr)), return_eigenvectors=False)
            out[name].append(float(np.min(ev)))
            if name == "anti_N_per_m":
                try:
                    factor(Kf, "cholmod")
                    out["anti_positive_definite"].append(True)
                except NotPositiveDefinite:
                    out["anti_positive_definite"].append(False)
    out["cpu_seconds"] = time.process_time() - tc
    return out


def mirror_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict, fine: dict) -> dict:
    """Does the z mirror plane change the azimuth-0 answer? The convergence meshes are quarter models (u_z = 0
    on the plane z = z_O through the push axis, so their solution is mirror-symmetric by construction); every
    other azimuth, the held-out check and the node table's off-axis snapshots are half models, *cut*: meshed
    with nodes on the plane through their push axis but no BC there (:class:`RefSpec` ``cut``,
    :data:`flexsheet.fem.snapshots.DEFAULT_REF_SPEC`; uncut half models were 8–12 % stiffer at 40–50 mm than the
    quarter models of the same h_fine, session 10, docs/fem.md). Here the azimuth-0 push is solved on cut half
    models (``st.half_levels``, h_fine m, else as the convergence levels) and compared, every ``st.fine_step``,
    with the finest quarter model (``fine``) and with the quarter model of the same h_fine (from ``conv``'s
    levels, when there is one): per level the force (N), the largest visible-surface difference (mm) and the
    solution's own asymmetry, the largest |u(x) − M·u(M·x)| (mm) over the rendered vertices visible on it, M
    the mirror in z (u at M·x probed from the half model's field). A half-model solution asymmetric well beyond
    the mesh's own asymmetry would have left the symmetric branch (a bifurcation); one close to the quarter
    model of the same h_fine says the off-axis snapshots' meshes are as good as the quarter models the
    convergence study measures. Also ``stability``: :func:`mirror_stability` of the last two quarter levels
    (frictionless contact only; cached)."""
    depths = _depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    quarter = {round(lv["h_fine_m"], 9): lv for lv in conv["levels"]}
    rows = []
    for hf in st.half_levels:
        spec = replace(st.levels[-1], h_fine=hf, half_z=False, cut=True)
        p = reference_path(spec, 0.0, depths, mat, cache, verts, st.contact)
        asym = [a * 1e3 for a in mirror_asymmetry(p, spec, depths, mat, rm)]
        q = quarter.get(round(hf, 9))
        rows.append({"h_fine_m": hf, "spec": spec.__dict__, "dofs": int(p["dofs"]),
                     "cpu_seconds": float(p["cpu_seconds"]),
                     "newton_converged": bool(p["converged"].all()), "newton_iterations": p["newton"].tolist(),
                     "force_N": p["force"].tolist(), "asymmetry_mm": asym,
                     "diff_vs_finest_quarter_mm": [e * 1e3 for e in _visible_diffs(p, fine, depths, verts, fixed, rm.mesh)],
                     "quarter_same_h_dofs": int(q["dofs"]) if q else None,
                     "quarter_same_h_force_N": q["force_N"] if q and len(q["force_N"]) == len(depths) else None})
        _log(f"mirror study: half model (cut) h_fine {hf * 1e3:g} mm ({rows[-1]['dofs']} DOF) at 50 mm: "
             f"{p['force'][-1]:.2f} N, {rows[-1]['diff_vs_finest_quarter_mm'][-1]:.2f} mm from the finest quarter "
             f"model, asymmetry {asym[-1]:.2f} mm")
    stab = []
    # the next-to-finest (full mode: the node's) mesh and the finest; sticking contact: its anchors are not stored
    for spec in (st.levels[-2:] if st.contact == "frictionless" else []):
        sd = depths if spec == st.levels[-1] else _depths(st.depth_step)
        p = fine if spec == st.levels[-1] else reference_path(spec, 0.0, sd, mat, cache, verts, st.contact)
        t = time.perf_counter()
        key = cache_key("mirror_stability-2", _reference_key(spec, 0.0, sd, mat, verts, st.contact, PENALTY_SCALE))
        z, _, _ = cache.get_or_compute("stability", key,
                                       lambda spec=spec, p=p, sd=sd: {k: np.asarray(v) for k, v in
                                                                      mirror_stability(p, spec, sd, mat, st.contact).items()},
                                       f"mirror stability of {spec.key()}")
        row = {"h_fine_m": spec.h_fine, "dofs": int(z["dofs"]), "depths_m": sd.tolist(),
               "sym_N_per_m": z["sym_N_per_m"].tolist(), "anti_N_per_m": z["anti_N_per_m"].tolist(),
               "anti_over_sym": (z["anti_N_per_m"] / z["sym_N_per_m"]).tolist(),
               "anti_positive_definite": z["anti_positive_definite"].tolist(), "residual_N": z["residual_N"].tolist(),
               "cpu_seconds": float(z["cpu_seconds"])}
        row["stable"] = bool(np.all(z["anti_positive_definite"]))
        stab.append(row)
        i = int(np.argmin(row["anti_over_sym"]))
        n_bad = len(sd) - int(np.sum(z["anti_positive_definite"]))
        verdict = "stable at every depth" if row["stable"] else f"UNSTABLE at {n_bad} of {len(sd)} depths"
        _log(f"mirror stability, quarter model h_fine {spec.h_fine * 1e3:g} mm: antisymmetric modes {verdict}; "
             f"lowest antisymmetric / symmetric eigenvalue {row['anti_over_sym'][i]:.3f} at {sd[i] * 1e3:g} mm "
             f"({time.perf_counter() - t:.0f} s)")
    return {"depths_m": depths.tolist(), "finest_quarter": st.levels[-1].__dict__,
            "finest_quarter_force_N": fine["force"].tolist(), "quarter_depths_m": conv["depths_m"],
            "quarter_levels": [{k: lv[k] for k in ("h_fine_m", "dofs", "force_N", "cpu_seconds")} for lv in conv["levels"]],
            "half_levels": rows, "stability": stab}


# ---- candidates ------------------------------------------------------------------------------------------------
def validation_set(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, fine: dict) -> list[dict]:
    """Reference fields at the rendered vertices for the configurations the candidates are judged on: azimuth 0
    from the finest convergence mesh (every depth), and each held-out azimuth on the snapshot mesh."""
    depths = _depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    snap_d = st.grid.depths()
    out = [{"angle_deg": 0.0, "depth": float(d), "u": fine["u"][j], "source": "finest convergence mesh",
            "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(depths)]
    for a in st.holdout_deg:
        p = stable_path(st.snap_spec, a, depths, mat, cache, verts, st.contact)
        out += [{"angle_deg": float(a), "depth": float(d), "u": p["u"][j], "source": "held-out azimuth",
                 "held_out": True} for j, d in enumerate(depths)]
    return out


def _path_states(src: dict, src_depths: np.ndarray, depths, model=None) -> list[PathState] | None:
    """The states of the cached reference path ``src`` (:func:`reference_path`, solved at ``src_depths`` (D,) m)
    at ``depths`` m, as :class:`PathState` for :func:`flexsheet.fem.snapshots.build_table`; None if one is missing.
    Raises ``RuntimeError`` when ``model`` (the mesh the table samples) has another DOF count than the solve
    (the cache key does not carry gmsh's version: a new gmsh may mesh differently)."""
    if model is not None:
        _check_dofs(src, model)
    out = []
    for d in depths:
        j = int(np.argmin(np.abs(src_depths - d)))
        if abs(src_depths[j] - d) > 1e-9:
            return None
        out.append(PathState(float(d), src["u_dof"][j].astype(float), float(src["force"][j]), np.zeros(3),
                             int(src["newton"][j]), bool(src["converged"][j]), float(src["min_detF"][j]),
                             int(src["inverted"][j]), float(src["max_strain"][j]), float(src["penetration"][j]), 0))
    return out


def snapshot_source(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, fine: dict):
    """``solved`` for :func:`snapshot_table`: azimuth 0 sampled from the solve on the snapshot mesh (``fine``
    when it is the finest level; otherwise its :func:`reference_path`, which the convergence or skin study
    cached, else solved here once), other azimuths from their cached :func:`reference_path` on the half model
    (the node table's paths when ``snap_spec`` is the node's), so nothing is solved twice. Also returns the
    azimuth-0 solve, for its timing."""
    verts = rm.rest_vertices.astype(float)
    # the finest level (quick) or another level or a skin variant, which the convergence / skin study cached
    # (else solved here, once); the stable branch of it (stable_path), as every azimuth's
    sd = _depths(st.fine_step if st.snap_spec == st.levels[-1] else st.depth_step)
    src = stable_path(st.snap_spec, 0.0, sd, mat, cache, verts, st.contact)

    def solved(ang, model, depths):
        if ang == 0.0:
            return _path_states(src, sd, depths, model)
        fd = _depths(st.fine_step)          # other azimuths: the cached path the held-out check also reads
        p = stable_path(st.snap_spec, ang, fd, mat, cache, verts, st.contact)
        return _path_states(p, fd, depths, model)

    return solved, src


def snapshot_table(st: Settings, mat: Material, cache: ArrayCache, solved,
                   reuse: dict | None = None) -> tuple[dict, bool, float]:
    """The snapshot table of these settings (cached): (table, cache hit, seconds to build). ``solved``:
    callable (azimuth deg, model, depths m) → states or None (:func:`flexsheet.fem.snapshots.build_table`), the
    reference solves already made (:func:`snapshot_source`, :func:`node_table_path`); ``reuse``: a table whose
    azimuths are copied, not solved (:func:`flexsheet.fem.snapshots.build_table`)."""
    _log(f"snapshots: azimuths {st.grid.angles_deg} deg, depth step {st.grid.depth_step * 1e3:g} mm, "
         f"mesh {st.snap_spec.key()} ...")

    table, hit, sec = load_or_build(cache, st.grid, st.snap_spec, mat, FINGER_R, build=True,
                                    log=lambda s: _log("  " + s.strip()), solved=solved, contact=st.contact,
                                    reuse=reuse)
    if hit:
        sec = float(np.sum(table["seconds"]))
    return table, hit, sec


def errors(rm: RealtimeModel, cases: list[dict], kind: str, rest_footprint: bool = False) -> list[float]:
    """Largest visible-surface error (m) of model ``kind`` ("snapshots" | "linear") per validation case; the
    footprint taken on the deformed reference surface, or (``rest_footprint``) on the rest surface as before
    solver nh-3 (it counts vertices lying on the finger's side as visible; reported beside, for comparison)."""
    fixed = rm.mesh.fixed[rm.surface_nodes]
    verts = rm.rest_vertices.astype(float)
    model = rm.model if kind == "linear" else None
    surf_pts = rm.surface_nodes
    out = []
    for c in cases:
        a = math.radians(c["angle_deg"])
        fg = finger_at(a, c["depth"], FINGER_R, rm.mesh.radius, rm.mesh.center)
        if kind == "snapshots":
            u = rm.snapshots.surface(a, c["depth"], 0.0)[0]
        else:
            u = solve_full(model, fg).u[surf_pts]
        vis = _visible(verts if rest_footprint else verts + c["u"], fixed, c["angle_deg"], c["depth"], rm.mesh)
        out.append(float(np.linalg.norm(u - c["u"], axis=1)[vis].max()))
    return out


def update_ms(rm: RealtimeModel, angles_deg, depths, n: int) -> dict:
    """Median and 90th-percentile wall time (ms) of ``rm.update_finger`` over ``n`` calls per configuration."""
    ts = []
    for a in angles_deg:
        for d in depths:
            fg = finger_at(math.radians(a), d, FINGER_R, rm.mesh.radius, rm.mesh.center)
            rm.update_finger(fg)
            for _ in range(n):
                t = time.perf_counter()
                rm.update_finger(fg)
                ts.append(time.perf_counter() - t)
    ts = np.array(ts) * 1e3
    return {"median": float(np.median(ts)), "p90": float(np.percentile(ts, 90)), "n": int(len(ts))}


def candidates(st: Settings, mat: Material, rm: RealtimeModel, table: dict, cases: list[dict]) -> dict:
    """Accuracy and speed of the linear and the snapshot model on the validation cases."""
    res = {}
    t_angles = sorted({0.0, *st.holdout_deg})
    t_depths = [0.01, 0.03, 0.05]
    snap = rm.snapshots
    rm.snapshots = None
    _log("linear (capacitance) model: errors against the nonlinear reference ...")
    res["linear"] = {"name": f"linear P2 {st.linear_spec.key()}", "kind": "linear",
                     "errors_m": errors(rm, cases, "linear"),
                     "time_ms": update_ms(rm, [a for a in t_angles if a <= st.linear_spec.arc_deg + 1e-9],
                                          t_depths, st.n_time)}
    rm.snapshots = snap
    res["snapshots"] = {"name": "nonlinear snapshots", "kind": "snapshots", "errors_m": errors(rm, cases, "snapshots"),
                        "errors_rest_footprint_m": errors(rm, cases, "snapshots", rest_footprint=True),
                        "time_ms": update_ms(rm, t_angles, t_depths, st.n_time), "table_MB": snap.nbytes / 1e6}
    for k, v in res.items():
        _log(f"  {k}: worst visible error {max(v['errors_m']) * 1e3:.2f} mm, update {v['time_ms']['median']:.3f} ms")
    return res


def _azimuth0_table_errors(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, spec: RefSpec,
                           cases: list[dict]) -> tuple[dict, list[float]]:
    """(the stable branch of ``spec``'s azimuth-0 push at ``_depths(st.depth_step)``, :func:`errors` in m of an
    azimuth-0 snapshot table on ``st.grid``'s depths built from it, on ``cases``): how :func:`snapshot_mesh_study`
    and :func:`_tip_snapshots` judge a candidate snapshot mesh. ``rm``'s table is left as it was."""
    sd = _depths(st.depth_step)
    src = stable_path(spec, 0.0, sd, mat, cache, rm.rest_vertices.astype(float), st.contact)   # as every table
    table = load_or_build(cache, replace(st.grid, angles_deg=(0.0,)), spec, mat, FINGER_R, build=True,
                          contact=st.contact,
                          solved=lambda ang, model, depths: _path_states(src, sd, depths, model))[0]
    keep = rm.snapshots
    try:
        rm.attach_snapshots(table)
        return src, errors(rm, cases, "snapshots")
    finally:
        rm.snapshots = keep


def snapshot_mesh_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, cases: list[dict]
                        ) -> dict:
    """Which mesh the snapshots need: an azimuth-0 table (``st.grid``'s depths) on the next-to-finest mesh (full
    mode: the snapshot mesh) and on each of its skin-refined variants (``st.skin_sizes``; the convergence and skin
    studies' solves, read from the cache), judged on the azimuth-0 validation cases (the finest convergence
    mesh; depths between snapshots held out). Per mesh: DOF, CPU of its azimuth-0 path and the worst visible
    error (mm). ``rm``'s snapshot table is left as it was."""
    az0 = [c for c in cases if c["angle_deg"] == 0.0]
    rows = []
    base = st.levels[-2]                        # the skin study's meshes (full mode: the snapshot mesh and its skins)
    for spec in [base] + [replace(base, skin_h=h) for h in st.skin_sizes]:
        src, err = _azimuth0_table_errors(st, mat, cache, rm, spec, az0)
        rows.append({"spec": spec.__dict__, "skin_h_m": spec.skin_h, "dofs": int(src["dofs"]),
                     "cpu_seconds_per_azimuth": float(src["cpu_seconds"]),
                     "max_visible_error_mm": max(err) * 1e3,
                     "max_visible_error_mm_held_out_depths": max(
                         (e for c, e in zip(az0, err, strict=True) if c["held_out"]), default=float("nan")) * 1e3})
        _log(f"snapshot mesh {spec.key()}: {rows[-1]['dofs']} DOF, azimuth 0 worst visible error "
             f"{rows[-1]['max_visible_error_mm']:.2f} mm")
    return {"azimuth_deg": 0.0, "depth_step_mm": st.grid.depth_step * 1e3, "target_mm": TARGET * 1e3,
            "against": f"the finest convergence mesh (h_fine {st.levels[-1].h_fine * 1e3:g} mm), every "
                       f"{st.fine_step * 1e3:g} mm",
            "meshes": rows}


def material_study(st: Settings, mats: tuple[Material, ...], cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Does the reference converge with a strain-stiffening material? For each of ``mats`` (neo-Hookean and a
    Gent solid, :class:`flexsheet.fem.material.Material` ``Jm``; same E, ν, finger, penalty, meshes): the azimuth-0
    mesh convergence of :func:`convergence` (its verdict, every level's visible-surface difference to the
    finest, force, largest Green–Lagrange strain), and an azimuth-0 snapshot table (``st.grid``'s depths) taken
    from the stable branch of the next-to-finest level (full mode: the node's 3.4 mm mesh) judged at every
    ``st.fine_step`` against that material's finest level — never against the solve it was sampled from; and
    the visible-surface distance between the materials' finest solutions (how far the choice of material
    moves what the display shows). Full mode also a tip check per material (the fold study's, :func:`tip_specs`:
    the next-to-finest level's tube with the push point alone refined further), its visible-surface distance to
    that level and to the finest (neo-Hookean: the apex the fold study found unresolved). Returns {"depths_mm",
    "target_mm", "materials": [{"name", "Jm", "convergence", "snapshots_azimuth0", "tip_check" (full mode)}],
    "difference_between_materials_mm", "what"}; lengths in mm."""
    depths = _depths(st.depth_step)
    fdepths = _depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    snap_d = st.grid.depths()
    chk = tip_specs(st)[1]
    rows, fines = [], []
    for mat in mats:
        conv, fine = convergence(st, mat, cache, rm)
        fines.append(_at_depths(fine, fdepths, depths))
        cases = [{"angle_deg": 0.0, "depth": float(d), "u": fine["u"][j],
                  "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(fdepths)]
        src, err = _azimuth0_table_errors(st, mat, cache, rm, st.levels[-2], cases)
        name = f"Gent, Jm {mat.Jm:g}" if mat.gent else "neo-Hookean"
        tip = {}
        if chk is not None:             # does refining the apex alone still move the visible surface?
            tp = reference_path(chk, 0.0, depths, mat, cache, verts, st.contact)
            plain = reference_path(st.levels[-2], 0.0, depths, mat, cache, verts, st.contact)
            tip = {"tip_check": {
                "spec": chk.__dict__, "dofs": int(tp["dofs"]), "newton_converged": bool(tp["converged"].all()),
                "difference_to_plain_level_mm": [e * 1e3 for e in _visible_diffs(tp, plain, depths, verts, fixed, rm.mesh)],
                "difference_to_finest_mm": [e * 1e3 for e in _visible_diffs(tp, fines[-1], depths, verts, fixed, rm.mesh)],
                "max_strain": tp["max_strain"].tolist(), "force_N": tp["force"].tolist(),
                "cpu_seconds": float(tp["cpu_seconds"])}}
        rows.append({"name": name, "Jm": mat.Jm if mat.gent else None, "convergence": conv, **tip,
                     "snapshots_azimuth0": {
                         "mesh": st.levels[-2].__dict__, "dofs": int(src["dofs"]),
                         "error_mm": [e * 1e3 for e in err], "depths_mm": (fdepths * 1e3).tolist(),
                         "max_visible_error_mm": max(err) * 1e3,
                         "max_visible_error_mm_held_out_depths": max(
                             (e for c, e in zip(cases, err, strict=True) if c["held_out"]), default=math.nan) * 1e3}})
        _log(f"material study, {name}: converged {conv['converged']}, last refinement "
             f"{conv['last_refinement_change_mm']:.3f} mm, azimuth-0 snapshots worst {max(err) * 1e3:.2f} mm")
    diff = [e * 1e3 for e in _visible_diffs(fines[0], fines[-1], depths, verts, fixed, rm.mesh)] \
        if len(fines) > 1 else []
    return {"depths_mm": (depths * 1e3).tolist(), "target_mm": TARGET * 1e3, "materials": rows,
            "difference_between_materials_mm": diff,
            "what": "azimuth-0 mesh convergence of the reference (convergence()) for each material, an azimuth-0 "
                    "snapshot table on the next-to-finest level judged against that material's finest level, "
                    "and the visible-surface distance between the first and the last material's finest "
                    "solutions (visible on the last's surface)"}


def plot_material_study(out: str, ms: dict) -> None:
    """material_study.png: per material, each level's visible-surface difference to its finest level (left) and
    the azimuth-0 snapshot table's error (right), against depth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, row in enumerate(ms["materials"]):
        conv = row["convergence"]
        d = np.array(conv["depths_m"]) * 1e3
        ls = "-" if i == len(ms["materials"]) - 1 else "--"
        for lv in conv["levels"][-3:-1]:
            a1.plot(d, lv["error_vs_finest_mm"], ls, marker="o", ms=2.5,
                    label=f"{row['name']}: h_fine {lv['h_fine_m'] * 1e3:.1f} mm")
        sn = row["snapshots_azimuth0"]
        a2.plot(sn["depths_mm"], sn["error_mm"], ls, marker="o", ms=2.5,
                label=f"{row['name']} (worst {sn['max_visible_error_mm']:.2f} mm)")
    for ax, yl in ((a1, "difference to the finest level (mm)"), (a2, "azimuth-0 snapshot error (mm)")):
        ax.axhline(ms["target_mm"], color="k", ls=":", lw=0.8, label=f"target {ms['target_mm']:g} mm")
        ax.set_xlabel("push depth (mm)")
        ax.set_ylabel(yl)
        ax.legend(fontsize=7)
    a1.axhline(ms["target_mm"] / 2, color="grey", ls=":", lw=0.8)
    a1.set_title("mesh convergence (last refinement within the grey line: half the target)", fontsize=9)
    a2.set_title("snapshots on the next-to-finest mesh against the finest", fontsize=9)
    fig.suptitle("reference material: " + " vs ".join(
        f"{r['name']} (converged = {r['convergence']['converged']})" for r in ms["materials"]), fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "material_study.png"), dpi=110)
    plt.close(fig)


def holdout_grid(st: Settings) -> Settings:
    """``st`` with its snapshot azimuths cut to the grid's first azimuth (0, judged too) and the two around each
    held-out one (full mode: 0 and 10 for 5), the ones the table's blend reads. ``ValueError`` when there is no
    held-out azimuth or one is not inside the grid."""
    if not st.holdout_deg:
        raise ValueError("these settings hold no azimuth out (the quick settings): nothing to study")
    g = sorted(st.grid.angles_deg)
    keep = {g[0]}
    for a in st.holdout_deg:
        lo, hi = [x for x in g if x <= a], [x for x in g if x >= a]
        if not lo or not hi:
            raise ValueError(f"held-out azimuth {a:g} deg is outside the snapshot grid {g} deg")
        keep |= {lo[-1], hi[0]}
    return replace(st, grid=replace(st.grid, angles_deg=tuple(sorted(keep))))


def holdout_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, fine: dict) -> dict:
    """The nonlinear snapshots between azimuths, alone (``--holdout-study``): a table on the grid azimuths
    around each held-out azimuth (:func:`holdout_grid`; the snapshot mesh's cut half model away from 0, every
    ``grid.depth_step``), judged at the held-out azimuth against its own solve on that mesh, and at azimuth 0
    against the finest mesh, at every ``fine_step`` 0–50 mm, on the visible surface (:func:`errors`). The same
    check as the full run's failure map at the held-out azimuth, without the studies that need the other
    solves. Returns per azimuth: depths (mm), worst visible error (mm) per depth, its maximum and the first
    depth over the 0.7 mm target; ``rm``'s snapshot table is left as it was."""
    hs = holdout_grid(st)
    keep = rm.snapshots
    try:
        solved, _ = snapshot_source(hs, mat, cache, rm, fine)
        table, hit, sec = snapshot_table(hs, mat, cache, solved)
        rm.attach_snapshots(table)
        cases = validation_set(hs, mat, cache, rm, fine)
        err = errors(rm, cases, "snapshots")
    finally:
        rm.snapshots = keep
    rows = []
    for a in sorted({c["angle_deg"] for c in cases}):
        pairs = [(c["depth"] * 1e3, e * 1e3) for c, e in zip(cases, err, strict=True) if c["angle_deg"] == a]
        bad = [d for d, e in pairs if e > TARGET * 1e3]
        rows.append({"azimuth_deg": a, "held_out": a in hs.holdout_deg,
                     "against": "its own solve on the snapshot mesh (cut half model)" if a in hs.holdout_deg
                     else f"the finest convergence mesh (h_fine {st.levels[-1].h_fine * 1e3:g} mm)",
                     "depths_mm": [d for d, _ in pairs], "error_mm": [e for _, e in pairs],
                     "max_error_mm": max(e for _, e in pairs), "breaks_at_depth_mm": min(bad) if bad else None})
        _log(f"holdout study: azimuth {a:g} deg: worst visible error {rows[-1]['max_error_mm']:.2f} mm"
             + (f", over the target from {min(bad):g} mm" if bad else ", within the target"))
    return {"snapshot_azimuths_deg": list(hs.grid.angles_deg), "held_out_deg": list(hs.holdout_deg),
            "snapshot_depth_step_mm": hs.grid.depth_step * 1e3, "snapshot_mesh": hs.snap_spec.__dict__,
            "table_build_s": sec, "table_cache_hit": hit, "target_mm": TARGET * 1e3,
            "footprint": f"left out: vertices whose deformed position (the reference's) lies within "
                         f"{(FINGER_R + 0.002) * 1e3:g} mm of the push axis (finger radius + 2 mm), hidden by the finger",
            "azimuths": rows}


def plot_holdout_study(out: str, hs: dict) -> None:
    """holdout_study.png: worst visible error against depth per azimuth (:func:`holdout_study`, the numbers in
    ``holdout_study.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in hs["azimuths"]:
        ax.semilogy(r["depths_mm"], r["error_mm"], "o-" if r["held_out"] else "s--", ms=3,
                    label=f"azimuth {r['azimuth_deg']:g}° ({'held out' if r['held_out'] else 'on the grid'}), "
                          f"against {r['against']}")
    ax.axhline(hs["target_mm"], color="k", ls="--", lw=0.8, label="target 0.7 mm (1 projector px)")
    ax.set_xlabel("push depth (mm)")
    ax.set_ylabel("worst visible-surface error (mm)")
    ax.set_title(f"Nonlinear snapshots at azimuths {hs['snapshot_azimuths_deg']} deg, every "
                 f"{hs['snapshot_depth_step_mm']:g} mm", fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "holdout_study.png"), dpi=110)
    plt.close(fig)


# ---- outputs -----------------------------------------------------------------------------------------------------
def failure_map(cases: list[dict], cand: dict) -> dict:
    """Per candidate: error (mm) on the (azimuth, depth) grid of the validation cases and where it breaks."""
    angles = sorted({c["angle_deg"] for c in cases})
    depths = sorted({c["depth"] for c in cases})
    out = {"angles_deg": angles, "depths_mm": [d * 1e3 for d in depths], "target_mm": TARGET * 1e3, "models": {}}
    for k, v in cand.items():
        grid = np.full((len(angles), len(depths)), np.nan)
        for c, e in zip(cases, v["errors_m"], strict=True):
            grid[angles.index(c["angle_deg"]), depths.index(c["depth"])] = e * 1e3
        breaks = {}
        for i, a in enumerate(angles):
            bad = [depths[j] * 1e3 for j in range(len(depths)) if grid[i, j] > TARGET * 1e3]
            breaks[f"{a:g}"] = min(bad) if bad else None
        out["models"][k] = {"name": v["name"], "error_mm": grid.tolist(), "breaks_at_depth_mm": breaks}
    return out


def model_table(cases: list[dict], cand: dict, law: str = "neo-Hookean") -> dict:
    """``flexsheet/fem/model_table.json``: each candidate's worst visible error per depth (over azimuths) and speed."""
    depths = sorted({c["depth"] for c in cases})
    rows = []
    for v in cand.values():
        by = {f"{d:.4f}": max(e for c, e in zip(cases, v["errors_m"], strict=True) if c["depth"] == d)
              for d in depths}
        rows.append({"kind": v["kind"], "name": v["name"], "max_error_m_by_depth": by,
                     "update_ms": v["time_ms"]["median"]})
    return {"target_m": TARGET, "finger_radius": FINGER_R, "angles_deg": sorted({c["angle_deg"] for c in cases}),
            "note": f"worst visible-surface error against the {law} reference over the tabulated azimuths",
            "candidates": rows}


def summary(st: Settings, conv: dict, cand: dict, cases: list[dict], snap_info: dict, mat: Material,
            wall: float) -> dict:
    """The ``summary.json`` object (keys named in issue 17 first)."""
    s = cand["snapshots"]
    lin = cand["linear"]
    worst = max(s["errors_m"])
    wc = cases[int(np.argmax(s["errors_m"]))]
    ho = [e for c, e in zip(cases, s["errors_m"], strict=True) if c.get("held_out")]
    at = [e for c, e in zip(cases, s["errors_m"], strict=True) if not c.get("held_out")]
    snap_info = snap_info | {
        "max_visible_error_mm_held_out_depths": max(ho) * 1e3 if ho else None,
        "max_visible_error_mm_snapshot_depths": max(at) * 1e3 if at else None,
        "validation": "azimuth 0 against the finest convergence mesh every "
                      f"{st.fine_step * 1e3:g} mm; the depths between snapshots are held out (interpolation "
                      "error); "
                      + ("at the snapshot depths only the surface-grid sampling is checked; the mesh's own "
                         "error is the reference's convergence figure" if st.snap_spec == st.levels[-1] else
                         "the snapshots come from a coarser mesh than the reference (h_fine "
                         f"{st.snap_spec.h_fine * 1e3:g} mm against {st.levels[-1].h_fine * 1e3:g} mm), so every "
                         "figure includes that mesh's own error")
                      + (f"; held-out azimuths {[f'{a:g}' for a in st.holdout_deg]} deg against their own solves "
                         f"on the snapshot mesh (interpolation between the snapshot azimuths "
                         f"{[f'{a:g}' for a in st.grid.angles_deg]} deg; the mesh's own error not included there)"
                         if st.holdout_deg else ""),
        "max_visible_error_mm_by_azimuth": {
            f"{a:g}": max(e for c, e in zip(cases, s["errors_m"], strict=True) if c["angle_deg"] == a) * 1e3
            for a in sorted({c["angle_deg"] for c in cases})}}
    return {
        "realtime": {"method": "snapshots", "update_ms": s["time_ms"]["median"], "update_ms_p90": s["time_ms"]["p90"],
                     "max_visible_error_mm_0_50": worst * 1e3,
                     "worst_case": {"angle_deg": wc["angle_deg"], "depth_mm": wc["depth"] * 1e3},
                     "angles_checked_deg": sorted({c["angle_deg"] for c in cases}), "target_mm": TARGET * 1e3,
                     "footprint": f"vertices whose deformed position (the reference's) lies within "
                                  f"{FINGER_R * 1e3 + 2:.0f} mm of the push axis are hidden by the finger and left "
                                  "out (the footprint under the tip and the wall dragged onto the finger's side)",
                     "max_visible_error_mm_0_50_rest_footprint": max(s["errors_rest_footprint_m"]) * 1e3,
                     **snap_info},
        "linear": {"update_ms": lin["time_ms"]["median"], "max_visible_error_mm_0_50": max(lin["errors_m"]) * 1e3},
        "reference": {"converged": conv["converged"], "model": f"compressible {_law(mat)}, total Lagrangian, P2, "
                      f"Newton + load stepping, rigid finger (penalty), {st.contact} contact", "contact": st.contact,
                      "solver": solver_tag(st.contact), **{
                          k: conv[k] for k in ("monotone_decrease", "last_refinement_change_mm",
                                               "finest_inverted_nodal_at_50mm", "finest_inverted_qp_at_50mm",
                                               "finest_inverted_nodal_visible_max", "finest_inverted_qp_max",
                                               "finest_newton_converged", "converged_to_depth_mm", "criterion",
                                               "mesh_converged")},
                      "penalty_study": {k: conv["penalty_study"][k] for k in (
                          "default_scale", "default_vs_10x_stiffer_mm", "tolerance_mm", "converged")} | {
                          "h_fine_m": conv["penalty_study"]["mesh"]["h_fine"],
                          "scales": [{k: r[k] for k in ("penalty_scale", "penetration_mm_at_50mm", "force_N_at_50mm",
                                                        "cpu_seconds")} | {"error_vs_stiffest_mm_max":
                                                                           max(r["error_vs_stiffest_mm"])}
                                     for r in conv["penalty_study"]["scales"]]},
                      "skin_study": {"tube_change_mm_at_50mm": conv["skin_study"]["tube_change_mm"][-1],
                                     "skins": [{k: r[k] for k in ("skin_h_m", "dofs", "cpu_seconds", "newton_converged",
                                                                  "force_N_at_50mm")}
                                               | {"change_vs_unrefined_mm_at_50mm": r["change_vs_unrefined_mm"][-1],
                                                  "change_vs_previous_mm_at_50mm": r["change_vs_previous_mm"][-1],
                                                  "diff_vs_finest_mm_at_50mm": r["diff_vs_finest_mm"][-1]}
                                               for r in conv["skin_study"]["skins"]]},
                      "levels": [{k: lv[k] for k in ("h_fine_m", "dofs", "seconds", "cpu_seconds", "newton_converged")}
                                 | {"error_vs_finest_mm_max": max(lv["error_vs_finest_mm"]),
                                    "error_vs_finest_mm_at_50mm": lv["error_vs_finest_mm"][-1],
                                    "force_N_at_50mm": lv["force_N"][-1],
                                    "inverted_nodal_at_50mm": lv["inverted_nodal"][-1],
                                    "inverted_qp_max": max(lv["inverted_qp"])} for lv in conv["levels"]],
                      "figures": "convergence.json, convergence.png"},
        "material": {"E": mat.E, "nu": mat.nu, "model": "gent" if mat.gent else "neo_hookean",
                     **({"Jm": mat.Jm} if mat.gent else {})},
        "finger_radius_m": FINGER_R, "quick": st.quick,
        "note": "timings on a shared 2-core machine (pessimistic)", "wall_s": wall,
    }


def _write(out: str, name: str, data: dict) -> None:
    with open(os.path.join(out, name + ".json"), "w") as fh:
        json.dump(data, fh, indent=1)


def plot_convergence(out: str, conv: dict, law: str = "neo-Hookean") -> None:
    """convergence.png: visible-surface difference to the finest mesh against depth, and against h at 3 depths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.array(conv["depths_m"]) * 1e3
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for lv in conv["levels"][:-1]:
        a1.plot(d, lv["error_vs_finest_mm"], "o-", ms=3, label=f"h_fine {lv['h_fine_m'] * 1e3:.1f} mm ({lv['dofs']} DOF)")
    a1.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm")
    a1.set_xlabel("push depth (mm)")
    a1.set_ylabel("max visible-surface difference to finest (mm)")
    a1.legend(fontsize=8)
    h = np.array([lv["h_fine_m"] for lv in conv["levels"][:-1]]) * 1e3
    for dd in (10.0, 30.0, 50.0):
        j = int(np.argmin(np.abs(d - dd)))
        a2.loglog(h, [lv["error_vs_finest_mm"][j] for lv in conv["levels"][:-1]], "o-", label=f"{d[j]:.0f} mm push")
    a2.set_xlabel("element size under the finger, h_fine (mm)")
    a2.set_ylabel("difference to finest (mm)")
    a2.legend(fontsize=8)
    fig.suptitle(f"{law} reference, mesh convergence (finest h_fine = {conv['levels'][-1]['h_fine_m'] * 1e3:.1f} mm)"
                 f": converged = {conv['converged']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "convergence.png"), dpi=110)
    plt.close(fig)


def plot_mirror_study(out: str, ms: dict) -> None:
    """mirror_study.png: finger force against depth on the quarter (dashed) and cut half models (solid); each
    half model's asymmetry and distance from the finest quarter model; the quarter models' lowest
    antisymmetric over symmetric tangent eigenvalue (:func:`mirror_stability`). The numbers: ``ms``
    (:func:`mirror_study`, ``mirror_study.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(16, 4.4))
    d = np.array(ms["quarter_depths_m"]) * 1e3
    hs = sorted({round(lv["h_fine_m"], 9) for lv in ms["quarter_levels"]} |
                {round(r["h_fine_m"], 9) for r in ms["half_levels"]}, reverse=True)
    col = {h: f"C{k}" for k, h in enumerate(hs)}         # one colour per h_fine in both panels
    for lv in ms["quarter_levels"]:
        a1.plot(d[:len(lv["force_N"])], lv["force_N"], "--", lw=1, color=col[round(lv["h_fine_m"], 9)],
                label=f"quarter, h_fine {lv['h_fine_m'] * 1e3:.1f} mm")
    dm = np.array(ms["depths_m"]) * 1e3
    for row in ms["half_levels"]:
        lab = f"cut half, h_fine {row['h_fine_m'] * 1e3:.1f} mm ({row['dofs']} DOF)"
        c = col[round(row["h_fine_m"], 9)]
        a1.plot(dm, row["force_N"], "-", lw=1.8, color=c, label=lab)
        a2.plot(dm, row["diff_vs_finest_quarter_mm"], "o-", ms=3, color=c, label=f"{lab}: from finest quarter")
        a2.plot(dm, row["asymmetry_mm"], "s--", ms=3, color=c, label=f"h_fine {row['h_fine_m'] * 1e3:.1f} mm: "
                "own asymmetry")
    a1.set_xlabel("push depth (mm)")
    a1.set_ylabel("finger force (N)")
    a1.legend(fontsize=7)
    a2.axhline(TARGET * 1e3, color="k", ls=":", lw=0.8, label="target 0.7 mm")
    a2.set_xlabel("push depth (mm)")
    a2.set_ylabel("max visible-surface distance (mm)")
    a2.legend(fontsize=7)
    for row in ms.get("stability", []):
        a3.plot(np.array(row["depths_m"]) * 1e3, row["anti_over_sym"], "o-", ms=3,
                color=col.get(round(row["h_fine_m"], 9)), label=f"quarter, h_fine {row['h_fine_m'] * 1e3:.1f} mm")
    a3.axhline(0.0, color="k", lw=0.8)
    a3.set_xlabel("push depth (mm)")
    a3.set_ylabel("lowest antisymmetric / symmetric\ntangent eigenvalue (< 0: unstable)")
    a3.legend(fontsize=7)
    fig.suptitle("azimuth-0 push: quarter models (z mirror plane) against cut half models (nodes on that plane, "
                 "no BC), and the symmetric solution's stability against asymmetric modes", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "mirror_study.png"), dpi=110)
    plt.close(fig)


def plot_candidates(out: str, cand: dict, fmap: dict, law: str = "neo-Hookean") -> None:
    """accuracy_speed.png (worst visible error 0–50 mm against time per update) and failure_map.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for k, v in cand.items():
        ax.scatter([v["time_ms"]["median"]], [max(v["errors_m"]) * 1e3], s=60, label=v["name"])
        ax.annotate(k, (v["time_ms"]["median"], max(v["errors_m"]) * 1e3), fontsize=8)
    ax.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm (1 projector px)")
    ax.axvline(1.0, color="grey", ls=":", lw=0.8, label="1 kHz")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per update (ms, median), shared 2-core CPU")
    ax.set_ylabel("worst visible-surface error, 0–50 mm push (mm)")
    ax.set_title(f"Accuracy vs speed against the {law} reference", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "accuracy_speed.png"), dpi=110)
    plt.close(fig)

    models = list(fmap["models"])
    fig, axes = plt.subplots(1, len(models), figsize=(5.2 * len(models), 3.8), squeeze=False)
    d = np.array(fmap["depths_mm"])
    for ax, k in zip(axes[0], models, strict=True):
        g = np.array(fmap["models"][k]["error_mm"])
        for i, a in enumerate(fmap["angles_deg"]):
            ax.semilogy(d, g[i], "o-", ms=3, label=f"azimuth {a:g}°")
        ax.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8)
        ax.fill_between(d, TARGET * 1e3, max(np.nanmax(g), 1.0) * 1.2, color="r", alpha=0.07)
        ax.set_title(f"{fmap['models'][k]['name']}", fontsize=9)
        ax.set_xlabel("push depth (mm)")
        ax.set_ylabel("worst visible error (mm); red: broken")
        ax.legend(fontsize=7)
    fig.suptitle("Failure map: where each model leaves the 0.7 mm target", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "failure_map.png"), dpi=110)
    plt.close(fig)


def _check_azimuth(angle_deg: float) -> None:
    """``SystemExit`` unless ``angle_deg`` is one of DEFAULT_GRID's azimuths."""
    if float(angle_deg) not in DEFAULT_GRID.angles_deg:
        raise SystemExit(f"flexsheet experiment fem: --azimuth must be one of the node table's "
                         f"{[f'{a:g}' for a in DEFAULT_GRID.angles_deg]} deg, got {angle_deg:g}")


def node_table_path(angle_deg: float, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                    contact: str = DEFAULT_CONTACT) -> tuple[dict, np.ndarray]:
    """One azimuth of the node's table: the reference path on its mesh (DEFAULT_REF_SPEC) through DEFAULT_GRID's
    depths, solved or taken from the cache (azimuth 0 is the full run's 3.4 mm level); returns
    (path, depths (D,) m). Raises ``SystemExit`` for an azimuth DEFAULT_GRID does not have."""
    _check_azimuth(angle_deg)
    depths = _depths(DEFAULT_GRID.depth_step)
    return stable_path(DEFAULT_REF_SPEC, angle_deg, depths, mat, cache, rm.rest_vertices.astype(float),
                       contact), depths


def node_table_report(table: dict, paths: dict[float, dict], mat: Material, key: str) -> dict:
    """What ``node_table.json`` records of the FEM node's table (:func:`build_node_table`): per azimuth the
    reference path's DOF, the loading path's CPU and the unloading sweep's wall time, the Newton iterations of the
    states kept (one branch per depth), the depths where the stable
    branch took the unloaded state, and the finger force (N), largest Green–Lagrange strain and inverted
    elements at every depth; plus a check against the finger's geometry, not against the reference the table
    came from: the table's displacement of the surface point under the fingertip along the inward normal, minus
    the push depth (mm; the rigid apex's penetration plus the surface grid's sampling), largest per azimuth.
    ``paths``: azimuth (deg) → its :func:`stable_path` dict, or None when not cached (its facts are then left
    out). Units in keys."""
    from flexsheet.fem.snapshots import SnapshotModel

    R, c = float(table["radius"]), np.asarray(table["center"], float)
    phis = np.asarray(table["angles"], float)
    depths = np.asarray(table["depths"], float)
    pts = np.column_stack([c[0] + R * np.cos(phis), np.full(len(phis), c[1]), c[2] + R * np.sin(phis)])
    sm = SnapshotModel(table, pts, E=mat.E)
    reused = reused_azimuths(table)
    rows = []
    for i, phi in enumerate(phis):
        n_in = -np.array([math.cos(phi), 0.0, math.sin(phi)])
        apex = [float(sm.surface(float(phi), float(d))[0][i] @ n_in - d) * 1e3 for d in depths[1:]]
        p = paths.get(round(math.degrees(phi), 6))
        gone = "taken from the table this one extends (that table's report has its path's facts)" \
            if round(math.degrees(phi), 6) in reused else "not in this machine's cache"
        facts = {"path": gone} if p is None else {
            "dofs": int(p["dofs"]), "cpu_seconds_loading": float(p["cpu_seconds"]),
            "unload_seconds": float(p["unload_seconds"]) if "unload_seconds" in p else None,
            "newton_iterations": int(np.sum(p["newton"])), "converged": bool(np.all(p["converged"])),
            "unloaded_state_at_mm": [round(float(d) * 1e3, 3) for d in depths[1:][
                np.asarray(p.get("branch", np.zeros(len(depths) - 1))) == 1]]}
        rows.append({"azimuth_deg": round(math.degrees(phi), 6), **facts, "force_N": sm.force[i].tolist(), "max_strain": np.asarray(table["max_strain"])[i].tolist(),
                     "inverted": np.asarray(table["inverted"])[i].tolist(),
                     "apex_depth_error_mm": apex, "apex_depth_error_max_mm": max(abs(a) for a in apex)})
    return {"key": key, "material": {"E": mat.E, "nu": mat.nu, "Jm": mat.Jm if mat.gent else None,
                                     "law": _law(mat)},
            "mesh": DEFAULT_REF_SPEC.__dict__, "grid": DEFAULT_GRID.key(), "depths_mm": (depths * 1e3).tolist(),
            "table_MB_float32": float(sum(np.asarray(table[k]).size * 4 for k in ("side", "cap")) / 1e6),
            "apex_check": "the table's displacement of the surface point under the fingertip along the inward "
                          "normal minus the push depth: the finger's geometry, not the reference it came from",
            "azimuths": rows}


TWIN_DR = 0.0001    #: m: a twin mesh's wider refinement tube (:func:`twin_spec`)


def twin_spec(spec: RefSpec) -> RefSpec:
    """The **twin** of a reference mesh: the same sizes, the refinement tube :data:`TWIN_DR` wider, so gmsh
    lays the elements out anew. The same push on a mesh and on its twin differs by that mesh's noise, which no
    interpolation between pushes solved on such meshes can beat."""
    return replace(spec, refine_radius=spec.refine_radius + TWIN_DR)


def node_table_holdout(table: dict, mat: Material, cache: ArrayCache, rm: RealtimeModel, azimuth_deg: float,
                       contact: str = DEFAULT_CONTACT, twin: bool = False) -> dict:
    """The node's table at an azimuth it does not hold, against that push's own stable path on the table's mesh
    (:func:`stable_path` on DEFAULT_REF_SPEC, solved here unless cached: ~30 min of one core): the
    interpolation across azimuth alone, every table depth, largest distance (mm) over the visible rendered
    vertices (not held, outside the finger's footprint on the reference's deformed surface, :func:`_visible`).
    ``twin``: also the same push on the mesh's twin (:func:`twin_spec`; another ~30 min), and that mesh's noise
    (``noise_mm``, the same distance between the two) beside the error. Raises ``ValueError`` for an azimuth
    the table holds or outside it."""
    from flexsheet.fem.snapshots import SnapshotModel

    held = np.degrees(np.asarray(table["angles"], float))
    if np.any(np.abs(held - azimuth_deg) < 1e-9) or not held[0] < azimuth_deg < held[-1]:
        raise ValueError(f"held-out azimuth must lie strictly between the table's, off them "
                         f"({held.round(6).tolist()} deg), got {azimuth_deg!r}")
    depths = np.asarray(table["depths"], float)
    verts = rm.rest_vertices.astype(float)
    p = stable_path(DEFAULT_REF_SPEC, azimuth_deg, depths[1:], mat, cache, verts, contact)
    cases = [{"angle_deg": float(azimuth_deg), "depth": float(d), "u": p["u"][j]} for j, d in enumerate(depths[1:])]
    keep = rm.snapshots
    try:                                    # the check every snapshot table gets (errors), on this table
        rm.snapshots = SnapshotModel(table, verts, E=mat.E)
        err = [e * 1e3 for e in errors(rm, cases, "snapshots")]
    finally:
        rm.snapshots = keep
    bad = [float(d) * 1e3 for d, e in zip(depths[1:], err, strict=True) if e > TARGET * 1e3]
    row = {"azimuth_deg": float(azimuth_deg), "against": "its own stable path on the table's mesh (cut half model)",
           "depths_mm": (depths[1:] * 1e3).tolist(), "error_mm": err, "max_error_mm": max(err),
           "over_target_from_mm": min(bad) if bad else None, "dofs": int(p["dofs"]),
           "cpu_seconds_loading": float(p["cpu_seconds"])}
    if twin:
        q = stable_path(twin_spec(DEFAULT_REF_SPEC), azimuth_deg, depths[1:], mat, cache, verts, contact)
        noise = [e * 1e3 for e in _visible_diffs(q, p, depths[1:], verts, rm.mesh.fixed[rm.surface_nodes], rm.mesh,
                                                 azimuth_deg)]
        row["twin"] = {"spec": twin_spec(DEFAULT_REF_SPEC).__dict__, "dofs": int(q["dofs"]),
                       "converged": bool(np.all(q["converged"])), "noise_mm": noise, "max_noise_mm": max(noise),
                       "what": "the same push on the twin mesh (same sizes, the tube 0.1 mm wider, laid out anew) "
                               "against the table mesh's solve, the same vertices: the mesh's noise"}
    return row


def node_table_compare(tables: dict[str, dict], azimuths, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                       contact: str = DEFAULT_CONTACT) -> list[dict]:
    """Several tables (name → table, e.g. the node's before and after azimuths were added) judged at the same
    held-out ``azimuths`` (deg) as :func:`node_table_holdout` judges each (its push solved unless cached). One row
    per azimuth: {"azimuth_deg", "depths_mm", and per name {"error_mm" (rounded to µm), "max_error_mm",
    "over_target_from_mm"} or "holds this azimuth" where that table holds it}."""
    rows = []
    for az in (float(a) for a in azimuths):
        row: dict = {"azimuth_deg": az}
        for name, tab in tables.items():
            if np.any(np.abs(np.degrees(np.asarray(tab["angles"], float)) - az) < 1e-9):
                row[name] = "holds this azimuth"
                continue
            r = node_table_holdout(tab, mat, cache, rm, az, contact)
            row[name] = {"error_mm": [round(e, 3) for e in r["error_mm"]], "max_error_mm": round(r["max_error_mm"], 3),
                         "over_target_from_mm": r["over_target_from_mm"]}
            row["depths_mm"] = r["depths_mm"]
        rows.append(row)
    return rows


def node_table_between_depths(table: dict, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                              azimuth_deg: float, contact: str = DEFAULT_CONTACT) -> dict:
    """The node's table between its depths, at one of its azimuths: against that push's own stable path on the
    table's mesh solved at **half** the table's load step (:func:`stable_path` on DEFAULT_REF_SPEC through
    depths every step/2 to the table's deepest; solved unless cached: ~20 min of one core at azimuth 0, the
    quarter model). Judged as :func:`node_table_holdout` judges (:func:`errors`: largest distance, mm, over the
    visible rendered vertices) at every depth of that path: the midpoints are the interpolation in depth, and
    with a bistable push they show what blending two branches' states costs; at the table's own depths the
    two sides differ only by float16 rounding and by a branch that the finer load step may leave elsewhere.
    Returns per-depth errors, the largest at the midpoints and at the table's depths, and the depths where each
    side holds the unloaded (stable-branch) state. Raises ``ValueError`` for an azimuth the table does not hold."""
    from flexsheet.fem.snapshots import SnapshotModel

    held = np.degrees(np.asarray(table["angles"], float))
    if not np.any(np.abs(held - azimuth_deg) < 1e-9):
        raise ValueError(f"azimuth must be one of the table's ({held.round(6).tolist()} deg), got {azimuth_deg!r}")
    depths = np.asarray(table["depths"], float)
    step = float(depths[1] - depths[0])
    fine = np.round(np.arange(1, int(round(depths[-1] / (step / 2))) + 1) * (step / 2), 9)
    verts = rm.rest_vertices.astype(float)
    p = stable_path(DEFAULT_REF_SPEC, azimuth_deg, fine, mat, cache, verts, contact)
    cases = [{"angle_deg": float(azimuth_deg), "depth": float(d), "u": p["u"][j]} for j, d in enumerate(fine)]
    keep = rm.snapshots
    try:
        rm.snapshots = SnapshotModel(table, verts, E=mat.E)
        err = np.array([e * 1e3 for e in errors(rm, cases, "snapshots")])
    finally:
        rm.snapshots = keep
    mid = np.abs(np.round(fine / step) * step - fine) > 1e-9
    bad = fine[err > TARGET * 1e3]
    return {"azimuth_deg": float(azimuth_deg),
            "against": f"its own stable path on the table's mesh, load step {step / 2 * 1e3:g} mm",
            "depths_mm": (fine * 1e3).tolist(), "error_mm": err.tolist(), "max_error_mm": float(err.max()),
            "max_error_mm_between_depths": float(err[mid].max()),
            "max_error_mm_at_table_depths": float(err[~mid].max()),
            "over_target_from_mm": float(bad.min() * 1e3) if len(bad) else None,
            "unloaded_state_at_mm": (fine[np.asarray(p["branch"]) == 1] * 1e3).tolist() if "branch" in p else None,
            "dofs": int(p["dofs"]), "cpu_seconds_loading": float(p["cpu_seconds"])}


def _table_update_ms(table: dict, verts: np.ndarray, mat: Material, n: int = 50) -> dict:
    """CPU time (``time.thread_time``) of one snapshot look-up for the rendered vertices ``verts`` (k, 3) m — what
    the node does per update on the cylinder (:meth:`flexsheet.fem.snapshots.SnapshotModel.surface`) — at pushes
    between the table's azimuths (the first, middle and last midpoints: 5°, 35°, 55° for the node's) and at 0.1,
    0.4, 0.9 of its deepest push (5, 20, 45 mm), ``n`` calls each: median and 90th percentile, ms."""
    from flexsheet.fem.snapshots import SnapshotModel

    sm = SnapshotModel(table, verts, E=mat.E)
    mids = np.degrees(np.asarray(table["angles"], float))
    mids = (mids[:-1] + mids[1:]) / 2 if len(mids) > 1 else mids
    ts = []
    for a in sorted({float(mids[0]), float(mids[len(mids) // 2]), float(mids[-1])}):
        for d in (0.1 * sm.depth_max, 0.4 * sm.depth_max, 0.9 * sm.depth_max):
            for _ in range(n):
                t = time.thread_time()
                sm.surface(math.radians(a), d)
                ts.append(time.thread_time() - t)
    return {"median_ms": float(np.median(ts) * 1e3), "p90_ms": float(np.percentile(ts, 90) * 1e3),
            "vertices": int(len(verts)), "calls": len(ts),
            "what": "SnapshotModel.surface CPU time (thread_time) per call, the node's per-update look-up"}


def plot_node_table(out: str, rep: dict) -> None:
    """node_table.png: finger force against depth per azimuth, and the apex check (:func:`node_table_report`), with
    the held-out azimuths' and the between-depths checks' errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    d = rep["depths_mm"]
    for r in rep["azimuths"]:
        a.plot(d, r["force_N"], ".-", ms=3, label=f"{r['azimuth_deg']:g}°")
        b.plot(d[1:], r["apex_depth_error_mm"], ".-", ms=3, label=f"{r['azimuth_deg']:g}°")
    a.set_xlabel("push depth (mm)")
    a.set_ylabel("finger force (N)")
    a.set_title(f"node table, {rep['material']['law']}, E {rep['material']['E'] / 1e3:g} kPa", fontsize=10)
    a.legend(fontsize=7, title="azimuth")
    for i, h in enumerate(rep.get("held_out", [])):
        b.plot(h["depths_mm"], h["error_mm"], ".-", color=("k", "0.45", "0.7")[i % 3], ms=4, lw=1.5,
               label=f"held out {h['azimuth_deg']:g}°: visible-surface error")
        if h.get("twin"):
            b.plot(h["depths_mm"], h["twin"]["noise_mm"], "v:", color=("k", "0.45", "0.7")[i % 3], ms=3, lw=1.2,
                   label=f"{h['azimuth_deg']:g}°: the mesh's noise (twin mesh)")
    for h in rep.get("between_depths", []):
        b.plot(h["depths_mm"], h["error_mm"], "rx-", ms=4, lw=1,
               label=f"{h['azimuth_deg']:g}°, every {h['depths_mm'][0]:g} mm: visible-surface error")
    if rep.get("held_out") or rep.get("between_depths"):
        b.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm")
    b.set_xlabel("push depth (mm)")
    b.set_ylabel("mm")
    b.set_title("apex displacement − depth per azimuth; held-out error", fontsize=10)
    b.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "node_table.png"), dpi=110)
    plt.close(fig)


def _cached_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                 probes: np.ndarray, contact: str = DEFAULT_CONTACT) -> dict | None:
    """:func:`stable_path` (frictionless; else :func:`reference_path`) when it is in ``cache``, else None —
    never solved here."""
    if contact == "frictionless":
        return cache.load("stable", _stable_key(spec, angle_deg, depths, mat, probes, contact, PENALTY_SCALE))
    return cache.load("reference", _reference_keys(spec, angle_deg, depths, mat, probes, contact, PENALTY_SCALE)[0])


def build_node_table(mat: Material, cache: ArrayCache, cache_dir: str | None, contact: str = DEFAULT_CONTACT,
                     azimuth: float | None = None, jobs: int = 1, ship: bool = False, out: str | None = None,
                     holdout: tuple[float, ...] = (), between: tuple[float, ...] = (), twin: bool = False) -> int:
    """Build (or find) the FEM node's snapshot table: :data:`flexsheet.fem.snapshots.DEFAULT_GRID` on
    :data:`flexsheet.fem.snapshots.DEFAULT_REF_SPEC`, the key the node looks up (its ``finger_radius`` default is
    the experiment's 8 mm). Every azimuth's path is a cached :func:`node_table_path` (azimuth 0: the full run's
    3.4 mm level), so ``azimuth`` (deg) solves just that one and returns: run the azimuths in parallel
    processes, or over several sittings, then once without it to assemble the table; without it the azimuths
    the cache lacks are solved in ``jobs`` worker processes first (:func:`prefetch`). ``ship``: also write the
    table, packed (:func:`flexsheet.fem.snapshots.pack_table`: float16 surface fields, compressed), into the
    repository's ``flexsheet/fem/data/`` (:meth:`flexsheet.fem.cache.ArrayCache.ship`), where the node finds it on a
    machine that never solved it. A table on fewer azimuths in the cache or the shipped store
    (:func:`flexsheet.fem.snapshots.reusable_table`) is extended: only the azimuths it lacks are solved. ``out``:
    write ``node_table.json/png`` there (:func:`node_table_report`), with
    the table judged at each ``holdout`` azimuth (deg, between the table's) against its own solve
    (:func:`node_table_holdout`; solved unless cached) and between its depths at each ``between`` azimuth (deg,
    one of the table's; :func:`node_table_between_depths`); ``twin`` (``--mesh-check``): each held-out push also
    on the mesh's twin, its noise beside the error. Returns 0."""
    from flexsheet.fem.snapshots import table_key

    st = replace(settings_for(False), grid=DEFAULT_GRID, snap_spec=DEFAULT_REF_SPEC, contact=contact)
    t0 = time.perf_counter()
    rm = realtime_model(st, mat, cache_dir)
    if azimuth is not None:
        node_table_path(azimuth, mat, cache, rm, contact)
        _log(f"node table: azimuth {azimuth:g} deg cached in {time.perf_counter() - t0:.0f} s")
        return 0
    key = table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, mat.nu, FINGER_R, contact, mat.Jm)
    _log(f"node table: azimuths {DEFAULT_GRID.angles_deg} deg on {DEFAULT_REF_SPEC.key()}; key {key}")
    table, hit, _ = load_or_build(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, FINGER_R, build=False,
                                  contact=contact)
    verts = rm.rest_vertices.astype(float)
    if hit:     # in the cache or shipped: its paths are not solved again (a held-out check needs only its own)
        _log("node table found (this machine's cache or flexsheet/fem/data): not solving its paths again")
    else:
        base = reusable_table(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, FINGER_R, contact)
        have = set() if base is None else {round(float(a), 6) for a in np.degrees(base["angles"])}
        if base is not None:
            _log(f"node table: extending the table on azimuths {sorted(have)} deg (this machine's cache or "
                 f"flexsheet/fem/data): only {[a for a in DEFAULT_GRID.angles_deg if a not in have]} deg are solved")
        prefetch([Solve(DEFAULT_REF_SPEC, a, DEFAULT_GRID.depth_step, stable=True) for a in DEFAULT_GRID.angles_deg
                  if a not in have], jobs, mat, cache, verts, contact)

        def solved(ang, model, depths):
            states = _path_states(*node_table_path(ang, mat, cache, rm, contact), depths, model)
            if states is None:          # else build_table would solve it again, uncached
                raise RuntimeError(f"the node table's path at {ang:g} deg lacks a depth of {DEFAULT_GRID.key()}")
            return states

        table, _, sec = snapshot_table(st, mat, cache, solved, reuse=base)
        _log(f"node table built in {sec:.0f} s: {sum(v.nbytes for v in table.values()) / 1e6:.0f} MB; total "
             f"{time.perf_counter() - t0:.0f} s. The FEM node loads it at start (model: auto)")
    depths = _depths(DEFAULT_GRID.depth_step)
    paths = {a: _cached_path(DEFAULT_REF_SPEC, a, depths, mat, cache, verts, contact) for a in DEFAULT_GRID.angles_deg}
    # an azimuth copied from an extended table was checked when that table shipped (or was built from this cache)
    reused = reused_azimuths(table)
    missing = [a for a, q in paths.items() if q is None and round(a, 6) not in reused]
    unconverged = [a for a, q in paths.items() if q is not None and not np.all(q["converged"])]
    if ship and (missing or unconverged):
        raise SystemExit(f"flexsheet experiment fem: not shipping the node table: Newton did not converge at every "
                         f"load step at azimuth(s) {unconverged} deg, paths not in this machine's cache (so not "
                         f"checked) at {missing} deg")
    if ship:
        from flexsheet.fem.snapshots import pack_table

        packed, err = pack_table(table)
        p = cache.ship("snapshots", table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, mat.nu, FINGER_R, contact, mat.Jm),
                       packed)
        _log(f"node table shipped: {p} ({os.path.getsize(p) / 1e6:.1f} MB, float16 surface fields: rounding "
             f"<= {err * 1e3:.4f} mm); commit it")
    if out and holdout:     # the held-out pushes (and their twins) the cache lacks, in worker processes
        specs = [DEFAULT_REF_SPEC] + ([twin_spec(DEFAULT_REF_SPEC)] if twin else [])
        prefetch([Solve(sp, a, DEFAULT_GRID.depth_step, stable=True) for a in holdout for sp in specs], jobs, mat,
                 cache, verts, contact)
    if out:
        rep = node_table_report(table, paths, mat, key)
        if ship:
            rep["shipped"] = {"path": os.path.relpath(p, os.getcwd()), "MB": os.path.getsize(p) / 1e6,
                              "float16_rounding_mm": err * 1e3}
        rep["update"] = _table_update_ms(table, verts, mat)
        rep["held_out"] = [node_table_holdout(table, mat, cache, rm, a, contact, twin) for a in holdout]
        rep["between_depths"] = [node_table_between_depths(table, mat, cache, rm, a, contact) for a in between]
        for h in rep["between_depths"]:
            _log(f"node table between its depths at {h['azimuth_deg']:g} deg: worst visible error "
                 f"{h['max_error_mm_between_depths']:.2f} mm (at its own depths {h['max_error_mm_at_table_depths']:.2f})")
        for h in rep["held_out"]:
            _log(f"node table held out at {h['azimuth_deg']:g} deg: worst visible error {h['max_error_mm']:.2f} mm"
                 + (f", over the target from {h['over_target_from_mm']:g} mm" if h["over_target_from_mm"] else ""))
        _write(out, "node_table", rep)
        plot_node_table(out, rep)
        _log(f"node table report -> {out}/node_table.json")
    return 0


# ---- parallel solves --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Solve:
    """One :func:`reference_path` a run reads: mesh, azimuth (deg), output depth spacing (m; depths
    ``_depths(step)``) and contact penalty scale; ``stable``: its :func:`stable_path` (the snapshot tables and
    the held-out pushes)."""

    spec: RefSpec
    angle_deg: float
    step: float
    penalty_scale: float = PENALTY_SCALE
    stable: bool = False

    def cost(self) -> float:
        """Relative CPU estimate for ordering (largest first): ∝ h_fine⁻³ (× (h_fine/skin)² with a skin), × 2 for
        a half model, × the load steps."""
        c = self.spec.h_fine ** -3 * (self.spec.h_fine / self.spec.skin_h) ** 2 if self.spec.skin_h else \
            self.spec.h_fine ** -3
        c *= self.spec.h_fine / self.spec.tip_h if self.spec.tip_h else 1.0      # a rough share for the tip
        half = self.angle_deg != 0.0 or not self.spec.half_z
        return c * (2.0 if half else 1.0) / _load_step(_depths(self.step))


def planned_solves(st: Settings, study: str = "full") -> list[Solve]:
    """Every reference path :func:`main`'s run reads (``study``: "full", or the "mirror" / "holdout" / "fold" /
    "material" study alone, ``--mirror-study`` / ``--holdout-study`` / ``--fold-study`` / ``--material-study``,
    the last per material), once each (as :func:`reference_path` keys them), most
    expensive first. Keep it in step with the functions that read them: :func:`convergence`,
    :func:`mirror_study` (its stability check reads the last two levels), :func:`penalty_study`,
    :func:`skin_study`, :func:`validation_set`, :func:`snapshot_source`, :func:`snapshot_mesh_study` (the skin
    study's meshes) and :func:`holdout_study`; a path may be listed twice. A run after :func:`prefetch` of this
    list solves nothing itself (tests/unit/fem/test_fem_experiment.py checks the quick run's log). ``ValueError`` on
    another ``study``."""
    if study not in ("full", "mirror", "holdout", "fold", "material"):
        raise ValueError(f"study must be 'full', 'mirror', 'holdout', 'fold' or 'material', got {study!r}")
    lv = st.levels
    if study == "material":              # material_study, per material: the levels and the table's stable branch
        jobs = [Solve(s, 0.0, st.depth_step) for s in lv[:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
        jobs.append(Solve(lv[-2], 0.0, st.depth_step, stable=True))
        chk = tip_specs(st)[1]
        jobs += [Solve(chk, 0.0, st.depth_step)] if chk is not None else []
        return sorted(jobs, key=lambda j: -j.cost())
    if study == "fold":                  # fold_study: the last three levels, the tip sequence and its check
        seq, chk = tip_specs(st)
        jobs = [Solve(s, 0.0, st.depth_step) for s in lv[-3:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
        jobs += [Solve(s, 0.0, st.depth_step) for s in seq + ([chk] if chk is not None else [])]
        jobs += [Solve(s, 0.0, st.depth_step, stable=True) for s in (lv[-2], seq[-2])]     # _tip_snapshots
        return sorted(jobs, key=lambda j: -j.cost())

    def snapshot_jobs(s: Settings) -> list[Solve]:      # validation_set's held-out paths, snapshot_source's
        jobs = [Solve(s.snap_spec, a, s.fine_step, stable=True) for a in s.holdout_deg]
        jobs += [Solve(s.snap_spec, a, s.fine_step, stable=True) for a in s.grid.angles_deg if a != 0.0]
        jobs.append(Solve(s.snap_spec, 0.0, s.fine_step if s.snap_spec == lv[-1] else s.depth_step, stable=True))
        return jobs

    if study == "holdout":
        jobs = [Solve(lv[-1], 0.0, st.fine_step)] + snapshot_jobs(holdout_grid(st))
        return sorted(jobs, key=lambda j: -j.cost())
    jobs = [Solve(s, 0.0, st.depth_step) for s in lv[:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
    jobs += [Solve(replace(lv[-1], h_fine=hf, half_z=False, cut=True), 0.0, st.fine_step) for hf in st.half_levels]
    if study == "full":
        jobs += [Solve(lv[st.penalty_level], 0.0, st.depth_step, sc) for sc in st.penalty_scales]
        # the skin study's paths, read as their stable branch by snapshot_mesh_study's tables (its base mesh:
        # the snapshot mesh in full mode, a job of its own in quick mode)
        jobs += [Solve(replace(lv[-2], skin_h=h), 0.0, st.depth_step, stable=True) for h in st.skin_sizes]
        jobs.append(Solve(lv[-2], 0.0, st.depth_step, stable=True))
        jobs += snapshot_jobs(st)
    return sorted(jobs, key=lambda j: -j.cost())      # repeats are dropped by prefetch (by cache key)


def _solver_init(counter) -> None:
    """Prefetch worker start: a log prefix "[solver N] "; SIGINT ignored (the parent terminates the pool on
    Ctrl-C); one BLAS and OpenMP thread, CHOLMOD's libraries loaded first so the limit reaches them; tied to
    the parent, dies with it (:func:`flexsheet.runtime.background.lower_priority`, niceness unchanged)."""
    global _LOG_PREFIX
    from flexsheet.runtime.background import lower_priority

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        import sksparse.cholmod  # noqa: F401 - loads the BLAS/OpenMP CHOLMOD uses before the thread limit
    except ImportError:
        pass
    lower_priority(0, idle=False)
    with counter.get_lock():
        counter.value += 1
        _LOG_PREFIX = f"[solver {counter.value}] "


def _solve_one(args: tuple) -> tuple[int, float, str | None]:
    """Worker: one :func:`reference_path` (or :func:`stable_path`) into the cache; (job index, seconds, None or
    the error)."""
    i, job, mat, cache_dir, probes, contact = args
    t = time.perf_counter()
    try:
        solve = stable_path if job.stable else reference_path
        solve(job.spec, job.angle_deg, _depths(job.step), mat, ArrayCache(cache_dir, _log), probes, contact,
              job.penalty_scale)
    except Exception as exc:                    # noqa: BLE001 - reported; the run solves it again and raises
        return i, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"
    return i, time.perf_counter() - t, None


def missing_solves(jobs: list[Solve], mat: Material, cache: ArrayCache, probes: np.ndarray, contact: str
                   ) -> list[Solve]:
    """The ``jobs`` :func:`reference_path` (or, ``stable``, :func:`stable_path`) would solve, not read, from
    ``cache`` (a previous version's path counts only when that version's path is this one's,
    :func:`_previous_version_path`), each loading path once (its ``stable`` job where there is one)."""
    todo: dict[str, Solve] = {}             # by the loading path's key: one worker per path, its sweep included
    for j in jobs:
        keys = _reference_keys(j.spec, j.angle_deg, _depths(j.step), mat, probes, contact, j.penalty_scale)
        missing = not os.path.exists(cache.path("reference", keys[0])) and _previous_version_path(cache, keys[1]) is None
        if j.stable and contact == "frictionless":     # its unloading sweep too (stable_path)
            sk = _stable_key(j.spec, j.angle_deg, _depths(j.step), mat, probes, contact, j.penalty_scale)
            missing = missing or not os.path.exists(cache.path("stable", sk))
        if missing and (keys[0] not in todo or j.stable):
            todo[keys[0]] = j
    return list(todo.values())


def prefetch(jobs: list[Solve], n_workers: int, mat: Material, cache: ArrayCache, probes: np.ndarray,
             contact: str) -> None:
    """Solve the ``jobs`` the cache lacks in ``n_workers`` processes (spawned, one BLAS thread each, their log
    lines prefixed "[solver N]"), into ``cache``; the run then reads them from it. Does nothing with one
    worker, a disabled cache or fewer than two solves missing. A failed solve is logged and left to the run,
    which solves it again and raises with the cause. Ctrl-C terminates the workers at once."""

    if n_workers < 2 or not cache.cache_dir:
        return
    todo = missing_solves(jobs, mat, cache, probes, contact)
    if len(todo) < 2:
        return
    n = min(n_workers, len(todo))
    _log(f"prefetch: {len(todo)} reference solves the cache lacks, in {n} worker processes (--jobs)")
    t0 = time.perf_counter()
    work = [(i, j, mat, cache.cache_dir, probes, contact) for i, j in enumerate(todo)]
    for i, sec, err in run_workers(_solve_one, work, n):
        j = todo[i]
        what = f"{j.spec.key()} at {j.angle_deg:g} deg, penalty {j.penalty_scale:g} E/h"
        _log(f"prefetch: {what} done in {sec:.0f} s" if err is None else
             f"prefetch: {what} failed ({err}); the run solves it itself")
    _log(f"prefetch: done in {time.perf_counter() - t0:.0f} s")


def run_workers(fn, work: list, n: int):
    """Yield ``fn(w)`` for every ``w`` of ``work``, in the order they finish, computed in ``n`` spawned worker
    processes started by :func:`_solver_init` (one BLAS thread, SIGINT ignored, tied to this process: killed with
    it, even by ``kill -9``). Ctrl-C, an error or leaving the loop early terminates the workers at once. The
    one pool of every long solve here (:func:`prefetch`, the sphere and path tables): a pool without the tie
    left its workers solving for minutes after its parent was killed (session 25). ``fn`` must be importable
    (module level) and catch its own errors."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    pool = ctx.Pool(n, initializer=_solver_init, initargs=(ctx.Value("i", 0),))
    try:
        yield from pool.imap_unordered(fn, work)
        pool.close()
    finally:
        pool.terminate()            # at once on Ctrl-C or an error; after close() the workers have exited
        pool.join()


def default_jobs() -> int:
    """Worker processes for :func:`prefetch`: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


# ---- main ---------------------------------------------------------------------------------------------------------
def realtime_model(st: Settings, mat: Material, cache_dir: str | None) -> RealtimeModel:
    """The node's real-time model (linear capacitance part) on the settings' mesh."""
    rm = RealtimeModel(st.linear_spec, mat, FINGER_R, max_depth=0.06, cache_dir=cache_dir, order=2)
    _log(f"real-time mesh P2 {st.linear_spec.key()}: {rm.n_nodes} nodes, {len(rm.surface_nodes)} rendered vertices, "
         f"{'cache hit' if rm.cache_hit else f'precomputed in {rm.precompute_s:.1f} s'}")
    return rm


def main(argv: list[str] | None = None) -> int:
    """Run the experiment; returns 0. See the module docstring for the outputs."""
    args = _parser().parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    studies = ("--mirror-study", args.mirror_study), ("--holdout-study", args.holdout_study), \
        ("--fold-study", args.fold_study), ("--material-study", args.material_study)
    for flag, on in studies:
        if on and (args.node_table or args.level is not None or args.linear_study or args.scene
                   or sum(o for _, o in studies) > 1):
            raise SystemExit(f"flexsheet experiment fem: {flag} (the paper's cylinder) takes none of "
                             "--node-table, --level, --linear-study, --scene, and runs alone")
    if args.holdout_study and args.quick:
        raise SystemExit("flexsheet experiment fem: --holdout-study is a full-mode study (the quick settings hold "
                         "no azimuth out); leave out --quick")
    if args.mesh_check and not (args.node_table and (args.scene or args.holdout_azimuth)):
        raise SystemExit("flexsheet experiment fem: --mesh-check is for --node-table with --holdout-azimuth (the "
                         "cylinder) or --scene SPHERE.yaml --node-table")
    sm = DEFAULT_MATERIAL                        # the default scene's; a paper-cylinder --scene file's below
    if args.scene:
        from flexsheet.model.scenes import is_paper_cylinder, load_scene_or_paper

        try:
            sc = load_scene_or_paper(args.scene)
        except ValueError as exc:
            raise SystemExit(f"flexsheet experiment fem: {exc}") from None
        if not is_paper_cylinder(sc) and args.between_depths:
            raise SystemExit("flexsheet experiment fem: --between-depths is for the paper's cylinder's table")
        if not is_paper_cylinder(sc) and args.node_table:
            from flexsheet.fem.sphere_snapshots import sphere_frame

            try:
                sphere_frame(sc)
            except ValueError:          # no symmetry to carry one push onto another: the path table
                from flexsheet.experiments.path_table import build_path_table

                if args.azimuth is not None or args.holdout_azimuth:
                    raise SystemExit("flexsheet experiment fem: --azimuth / --holdout-azimuth are the cylinder's and "
                                     "the sphere's; a path table takes --stations and --holdout-fraction") from None
                return build_path_table(args.scene, args.out, args.cache_dir or None, args.stations,
                                        tuple(args.holdout_fraction) or None, args.jobs, args.mesh_check, args.ship)
            from flexsheet.experiments.sphere_table import build_sphere_table

            return build_sphere_table(args.scene, args.out, args.cache_dir or None, args.azimuth,
                                      tuple(args.holdout_azimuth), args.jobs, args.mesh_check, args.ship)
        if not is_paper_cylinder(sc):
            from flexsheet.experiments.fem_scene import run_scene

            run_scene(args.scene, args.out, args.quick, args.cache_dir or None)
            return 0
        sm = Material.of_scene(sc.material)
    if args.jobs < 1:
        raise SystemExit(f"flexsheet experiment fem: --jobs must be >= 1, got {args.jobs}")
    try:
        mat = Material(sm.E if args.E is None else args.E, sm.nu if args.nu is None else args.nu,  # given: replace
                       sm.Jm if args.Jm is None else args.Jm)                                     # the scene's
    except ValueError as exc:
        raise SystemExit(f"flexsheet experiment fem: {exc}") from None
    if args.holdout_azimuth:
        inner = DEFAULT_GRID.angles_deg
        for a in args.holdout_azimuth:
            if not (math.isfinite(a) and inner[0] < a < inner[-1]) or a in inner:
                raise SystemExit(f"flexsheet experiment fem: --holdout-azimuth must lie strictly between the node "
                                 f"table's azimuths {[f'{x:g}' for x in inner]} deg and off them, got {a:g}")
    for a in args.between_depths:
        if a not in DEFAULT_GRID.angles_deg:
            raise SystemExit(f"flexsheet experiment fem: --between-depths must be one of the node table's azimuths "
                             f"{[f'{x:g}' for x in DEFAULT_GRID.angles_deg]} deg, got {a:g}")
    if args.between_depths and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --between-depths is for --node-table without --azimuth")
    if args.ship and args.contact != DEFAULT_CONTACT:
        raise SystemExit(f"flexsheet experiment fem: --ship ships the table the node looks up ({DEFAULT_CONTACT} "
                         f"contact); got --contact {args.contact}")
    st = replace(settings_for(args.quick), contact=args.contact)
    t0 = time.perf_counter()
    cache = ArrayCache(args.cache_dir or None, _log)
    if args.holdout_azimuth and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --holdout-azimuth is for --node-table without --azimuth")
    if args.ship and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --ship is for --node-table without --azimuth (it ships the "
                         "assembled table)")
    if args.azimuth is not None:
        if not args.node_table:
            raise SystemExit("flexsheet experiment fem: --azimuth is for --node-table")
        _check_azimuth(args.azimuth)
    if args.node_table:
        if args.quick or args.level is not None:
            raise SystemExit("flexsheet experiment fem: --node-table builds the node's full table; it takes neither "
                             "--quick nor --level")
        return build_node_table(mat, cache, args.cache_dir or None, st.contact, args.azimuth, args.jobs, args.ship,
                                args.out, tuple(args.holdout_azimuth), tuple(args.between_depths), args.mesh_check)
    for h in st.skin_sizes:     # before any solve: a bad size would otherwise fail after the convergence study
        replace(st.levels[-2], skin_h=h)
    rm = realtime_model(st, mat, args.cache_dir or None)
    probes = rm.rest_vertices.astype(float)       # the rendered vertices every reference path is sampled at
    if args.level is not None:
        if not 0 <= args.level < len(st.levels):
            raise SystemExit(f"--level must be in [0, {len(st.levels) - 1}], got {args.level}")
        last = args.level == len(st.levels) - 1
        reference_path(st.levels[args.level], 0.0, _depths(st.fine_step if last else st.depth_step), mat, cache,
                       probes, st.contact)
        _log(f"level {args.level} cached in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.material_study:
        mats = (Material(mat.E, mat.nu), Material(mat.E, mat.nu, mat.Jm if mat.gent else GENT_JM_RUBBER))
        for m in mats:
            prefetch(planned_solves(st, "material"), args.jobs, m, cache, probes, st.contact)
        ms = material_study(st, mats, cache, rm)
        _write(args.out, "material_study", ms)
        plot_material_study(args.out, ms)
        _log(f"material study done in {time.perf_counter() - t0:.1f} s -> {args.out}/material_study.json")
        return 0
    study = "mirror" if args.mirror_study else "holdout" if args.holdout_study else \
        "fold" if args.fold_study else "full"
    prefetch(planned_solves(st, study), args.jobs, mat, cache, probes, st.contact)
    if args.holdout_study:
        fine = reference_path(st.levels[-1], 0.0, _depths(st.fine_step), mat, cache, probes, st.contact)
        hs = holdout_study(st, mat, cache, rm, fine)
        _write(args.out, "holdout_study", hs)
        plot_holdout_study(args.out, hs)
        _log(f"holdout study done in {time.perf_counter() - t0:.1f} s -> {args.out}/holdout_study.json")
        return 0
    if args.fold_study:
        fs = fold_study(st, mat, cache, rm)
        _write(args.out, "fold_study", fs)
        plot_fold_study(args.out, fs)
        _log(f"fold study done in {time.perf_counter() - t0:.1f} s -> {args.out}/fold_study.json")
        return 0
    conv, fine = convergence(st, mat, cache, rm)
    if args.mirror_study:
        ms = mirror_study(st, mat, cache, rm, conv, fine)
        _write(args.out, "mirror_study", ms)
        plot_mirror_study(args.out, ms)
        _log(f"mirror study done in {time.perf_counter() - t0:.1f} s -> {args.out}/mirror_study.json")
        return 0
    pen = penalty_study(st, mat, cache, rm)
    conv["penalty_study"] = pen
    conv["mesh_converged"] = conv["converged"]
    conv["converged"] = conv["converged"] and pen["converged"]
    conv["criterion"] += (f"; and the contact penalty converged: the default {PENALTY_SCALE:g}·E/h within "
                          f"{PENALTY_TOL_MM:g} mm of a 10x stiffer one (penalty_study)")
    conv["skin_study"] = skin_study(st, mat, cache, rm, conv, fine)
    ms = mirror_study(st, mat, cache, rm, conv, fine)
    solved, src = snapshot_source(st, mat, cache, rm, fine)
    table, hit, sec = snapshot_table(st, mat, cache, solved)
    sec += float(src["seconds"])              # the solve the table was sampled from
    rm.attach_snapshots(table)
    snap_info = {"snapshot_azimuths_deg": list(st.grid.angles_deg), "snapshot_depth_step_mm": st.grid.depth_step * 1e3,
                 "snapshot_mesh": st.snap_spec.__dict__, "precompute_s": sec, "precompute_cache_hit": hit,
                 "table_MB": rm.snapshots.nbytes / 1e6}
    cases = validation_set(st, mat, cache, rm, fine)
    cand = candidates(st, mat, rm, table, cases)
    snap_info["snapshot_mesh_study"] = snapshot_mesh_study(st, mat, cache, rm, cases)
    fmap = failure_map(cases, cand)
    summ = summary(st, conv, cand, cases, snap_info, mat, time.perf_counter() - t0)
    _write(args.out, "convergence", conv)
    _write(args.out, "mirror_study", ms)
    _write(args.out, "failure_map", fmap)
    _write(args.out, "accuracy_speed", {k: {"name": v["name"], "update_ms": v["time_ms"],
                                            "max_visible_error_mm_0_50": max(v["errors_m"]) * 1e3}
                                        for k, v in cand.items()})
    _write(args.out, "summary", summ)
    # the node's model table: a full run of the default scene's material and contact law (or asked for)
    if (not st.quick and st.contact == DEFAULT_CONTACT and mat == DEFAULT_MATERIAL) \
            or args.write_model_table:
        with open(MODEL_TABLE_PATH, "w") as fh:
            json.dump(model_table(cases, cand, _law(mat)), fh, indent=1)
    plot_convergence(args.out, conv, _law(mat))
    plot_mirror_study(args.out, ms)
    plot_candidates(args.out, cand, fmap, _law(mat))
    if args.linear_study:
        linear_study(args.out, mat)
    _log(json.dumps(summ["realtime"], indent=1))
    _log(f"done in {time.perf_counter() - t0:.1f} s -> {args.out}")
    return 0


# ---- the linear mesh study (--linear-study): which linear mesh, Hertz check, where linear breaks ---------------------
def linear_study(out: str, mat: Material) -> None:
    """Linear P1/P2 meshes against a fine linear P2 solution (``accuracy_table.json``, read by
    :func:`flexsheet.fem.choose.choose`), the Hertz exponent check and the linear/corotational stability curve.
    Writes linear_accuracy_speed, hertz, stability (.json/.png) and accuracy_table.json into ``out``."""
    from flexsheet.fem.choose import choose
    from flexsheet.fem.mesh import cylinder_mesh
    from flexsheet.fem.solver import FemModel

    ref_spec = MeshSpec(0.010, 0.002, 0.015)
    depths = [0.005, 0.01, 0.02, 0.03, 0.04, 0.05]
    cands = [(MeshSpec(h, hf, rr), 1) for h, hf, rr in ((0.012, 0.004, 0.012), (0.010, 0.003, 0.012),
                                                         (0.008, 0.003, 0.012), (0.008, 0.002, 0.015))]
    cands += [(MeshSpec(h, hf, rr), 2) for h, hf, rr in ((0.016, 0.006, 0.012), (0.012, 0.006, 0.012),
                                                         (0.012, 0.004, 0.012), (0.012, 0.003, 0.012),
                                                         (0.010, 0.004, 0.012))]
    ref_mesh = cylinder_mesh(ref_spec)
    ref_model = FemModel(ref_mesh, mat, order=2)
    refs = {d: solve_full(ref_model, finger_at(0.0, d, FINGER_R, ref_mesh.radius, ref_mesh.center)) for d in depths}
    table, rows = _linear_candidates(cands, ref_spec, ref_model, refs, mat)
    table["depths"] = depths
    _write(out, "accuracy_table", table)
    ch = choose(table, TARGET, 0.005, 0.03, mat.nu, FINGER_R)
    _log("linear mesh choice over 5-30 mm: " + ch.reason)
    _write(out, "linear_accuracy_speed", {"candidates": rows, "depth_m": 0.03, "choice": ch.reason})
    hz = _hertz(mat)
    _write(out, "hertz", hz)
    stab = _stability(ch.spec, mat)
    _write(out, "stability", stab)
    _plots_linear(out, rows, hz, stab)


def _linear_candidates(cands, ref_spec, ref_model, refs, mat):
    from flexsheet.fem.choose import evaluate_spec

    table = {"nu": mat.nu, "finger_radius": FINGER_R, "reference": {"spec": ref_spec.__dict__, "order": 2,
                                                                   "dofs": ref_model.n_dofs}, "candidates": []}
    rows = []
    for spec, order in cands:
        ev = evaluate_spec(spec, ref_model, refs, mat, FINGER_R, order=order)
        table["candidates"].append(ev)
        rm = RealtimeModel(spec, mat, FINGER_R, cache_dir=None, order=order)
        fg = finger_at(0.0, 0.03, FINGER_R, rm.mesh.radius, rm.mesh.center)
        t = update_ms(rm, [0.0], [0.03], 100)["median"]
        rows.append({"spec": spec.__dict__, "order": order, "mesh_nodes": ev["mesh_nodes"], "dofs": ev["dofs"],
                     "precompute_s": rm.precompute_s, "update_ms": t,
                     "surface_error_mm_at_30mm": ev["surface_error_m"]["0.0300"] * 1e3,
                     "force_error_pct_at_30mm": ev["force_error_pct"]["0.0300"],
                     "max_error_mm": max(ev["surface_error_m"].values()) * 1e3})
        _log(f"  linear P{order} {spec.key()}: err@30 {rows[-1]['surface_error_mm_at_30mm']:.2f} mm, "
             f"update {t:.3f} ms ({fg.depth * 1e3:.0f} mm)")
    return table, rows


def _hertz(mat: Material) -> dict:
    """Small-depth force exponent of the linear P2 model against Hertz (Johnson, Contact Mechanics §4.2)."""
    from flexsheet.fem.mesh import cylinder_mesh
    from flexsheet.fem.solver import FemModel

    spec = MeshSpec(0.012, 0.002, 0.008)
    depths = [0.0005, 0.00075, 0.001, 0.0015, 0.002]
    mesh = cylinder_mesh(spec)
    model = FemModel(mesh, mat, order=2)
    F = [solve_full(model, finger_at(0.0, d, FINGER_R, mesh.radius, mesh.center)).force for d in depths]
    if min(F) <= 0:
        raise RuntimeError(f"Hertz check: no contact at some depth {depths}: forces {F}")
    slope, _ = np.polyfit(np.log(depths), np.log(F), 1)
    R_eff = math.sqrt(FINGER_R * (FINGER_R * mesh.radius / (FINGER_R + mesh.radius)))
    FH = [4.0 / 3.0 * mat.E_star * math.sqrt(R_eff) * d ** 1.5 for d in depths]
    return {"depths_m": depths, "force_N": F, "hertz_force_N": FH, "exponent": float(slope),
            "hertz_error_pct": float(abs(slope - 1.5) / 1.5 * 100.0),
            "finite_size_factor": float(np.mean(np.array(F) / np.array(FH))), "R_eff_m": R_eff,
            "E_star_Pa": mat.E_star, "mesh": spec.__dict__, "order": 2, "mesh_nodes": len(mesh.points),
            "note": "bonded contact on a finite cylinder held on its back half; exponent is the check"}


def _stability(spec: MeshSpec, mat: Material) -> dict:
    """Linear against corotational (P1) over depth on ``spec``: strain, inverted tets, force, difference."""
    from flexsheet.fem.mesh import cylinder_mesh
    from flexsheet.fem.solver import FemModel, element_checks, solve_corotational

    mesh = cylinder_mesh(spec)
    model = FemModel(mesh, mat)
    surf = np.flatnonzero(model.boundary & ~model.fixed)
    depths = [0.0025, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05]
    keys = ("linear_force_N", "corot_force_N", "linear_max_strain", "corot_max_strain", "linear_inverted",
            "corot_inverted", "lin_vs_corot_mm", "corot_converged")
    stab = {"depths_m": depths, **{k: [] for k in keys}}
    u0 = None
    for d in depths:
        fg = finger_at(0.0, d, FINGER_R, mesh.radius, mesh.center)
        lin = solve_full(model, fg)
        co, _, conv = solve_corotational(model, fg, u0=u0)
        u0 = co.u
        s_l, i_l = element_checks(mesh.points, mesh.tets, lin.u)
        s_c, i_c = element_checks(mesh.points, mesh.tets, co.u)
        vals = (lin.force, co.force, s_l, s_c, i_l, i_c,
                float(np.linalg.norm(lin.u[surf] - co.u[surf], axis=1).max() * 1e3), bool(conv))
        for k, v in zip(keys, vals, strict=True):
            stab[k].append(v)
    return stab


def _plots_linear(out: str, rows: list, hz: dict, stab: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for order, mk in ((1, "o"), (2, "D")):
        r = [x for x in rows if x["order"] == order]
        ax.scatter([x["update_ms"] for x in r], [x["surface_error_mm_at_30mm"] for x in r], marker=mk,
                   label=f"condensed P{order} (vs linear P2 reference)")
    ax.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm")
    ax.set_xscale("log")
    ax.set_xlabel("time per update (ms)")
    ax.set_ylabel("max surface error outside finger, 30 mm (mm)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "linear_accuracy_speed.png"), dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 4))
    d = np.array(hz["depths_m"]) * 1e3
    ax.loglog(d, hz["force_N"], "o-", label=f"FEM (exponent {hz['exponent']:.3f})")
    ax.loglog(d, hz["hertz_force_N"], "k--", label="Hertz half-space, F ∝ d^1.5")
    ax.set_xlabel("push depth (mm)")
    ax.set_ylabel("force (N)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "hertz.png"), dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 4))
    d = np.array(stab["depths_m"]) * 1e3
    ax.plot(d, stab["lin_vs_corot_mm"], "o-", label="max |u_lin − u_corot| (mm)")
    ax.plot(d, stab["linear_inverted"], "s-", label="inverted tets, linear")
    ax.plot(d, stab["corot_inverted"], "^-", label="inverted tets, corotational")
    ax.set_xlabel("push depth (mm)")
    ax.set_yscale("symlog")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stability.png"), dpi=110)
    plt.close(fig)
