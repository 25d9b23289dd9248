"""``flexsheet experiment fem --out DIR [--quick] [--jobs N] [--linear-study] [--Jm JM] [--mirror-study |
--holdout-study | --fold-study | --material-study] [--scene
FILE]``: physically right deformation of the pushed cylinder, and the real-time model that reproduces it
(``--scene`` with another object: the same study on that scene, :mod:`flexsheet.experiments.fem_scene`).

1. **Reference** (:mod:`flexsheet.fem.reference.hyperelastic`): the default scene's hyperelastic solid (a Gent
   solid, Jm 97.2, ``--Jm``; ``--Jm inf`` is the neo-Hookean solid of the committed full, quick_neohookean,
   fold and held-out figures), total Lagrangian, P2, Newton with load stepping (≤ 60 iterations per step),
   rigid frictionless finger (sphere + shaft), pushed 0 → 50 mm at azimuth 0 on a sequence of meshes refined
   along the whole push path (quarter model by symmetry; ``--contact sticking``: a fingertip that does not
   slip, the contact law is a modelling choice). Mesh
   convergence: the visible-surface difference of each mesh to the finest, at every depth
   (``convergence.json/png``); ``reference.converged`` when there are ≥ 3 meshes, that difference falls with
   every refinement, the last refinement changes the visible surface by ≤ half the target, Newton converged at
   every load step of the finest mesh and none of its elements is inverted at a quadrature point. **Skin
   study** (``convergence.json`` ``skin_study``, :func:`skin_study`): the 3.4 mm mesh with only its surface
   layer refined (2.5 and 1.8 mm), against the whole push tube refined, to tell which part of the mesh the
   unconverged deep push depends on. **Mirror study** (``mirror_study.json/png``, :func:`mirror_study`;
   ``--mirror-study`` runs only it): the azimuth-0 push on half models (no z mirror plane) at h_fine 6 / 4.5 /
   3.4 mm, cut as every other azimuth is (the plane through the push axis meshed, no BC on it), against the
   quarter models: force, distance from the finest quarter model and the half model's own asymmetry; and
   whether the quarter models' symmetric solution is stable against asymmetric modes
   (:func:`mirror_stability`, the 3.4 and 2.5 mm meshes, cached). **Fold study** (``fold_study.json/png``,
   :func:`fold_study`; ``--fold-study`` runs only it): the reference has no self-contact, so the last three
   levels' states are checked for a surface that passes through itself or creases
   (:mod:`flexsheet.fem.reference.fold`), and for where the largest strain and the levels' largest differences
   sit; then a sequence that refines the push point with the tube (:data:`TIP_LEVELS`, :func:`tip_sequence`:
   its verdict, a finer tip alone, and azimuth-0 snapshot tables on the plain and the tip meshes against its
   finest level). **Material study** (``material_study.json/png``, :func:`material_study`;
   ``--material-study`` runs only it): the same azimuth-0 convergence and an azimuth-0 snapshot table on the
   next-to-finest level, for the neo-Hookean reference and for a strain-stiffening Gent solid (``--Jm``,
   default :data:`flexsheet.fem.material.GENT_JM_RUBBER`), and how far the two materials' finest solutions lie
   apart. ``--Jm`` sets the material of every other study (default: the default scene's Gent solid;
   ``--Jm inf``: neo-Hookean).
2. **Candidates**, judged on the real-time model's rendered vertices outside the finger's footprint (lateral
   distance from the push axis > finger radius + 2 mm; the footprint is hidden by the finger): the linear P2
   capacitance model, and the nonlinear snapshots (:mod:`flexsheet.fem.snapshots`), sampled every 5 mm from
   the reference solve on the node's mesh (h_fine 3.4 mm, the next-to-finest level) and judged at every output
   depth against the finest mesh (h_fine 2.5 mm): the depths between snapshots are held out, and the snapshot
   mesh's own error is in the figure. Full mode: snapshots at azimuths 0, 10 and 20 degrees, and azimuth 5
   held out against its own solve on the snapshot mesh (interpolation across azimuth at the node table's
   spacing; ``--holdout-study`` runs only that check, on a table at 0 and 10 degrees:
   ``holdout_study.json/png``, :func:`holdout_study`). The table's pushes and the held-out ones are read as
   their **stable branch** (:func:`stable_path`): a push off azimuth 0 can be bistable (a fold beside the
   finger that the loading path carries past the depth where a lower-energy state exists, then snaps); the
   finger is withdrawn from 50 mm to the start, and each depth keeps the state of lower total potential.
   Accuracy against speed (``accuracy_speed.png/.json``) and the failure map, where each model breaks by depth
   and azimuth (``failure_map.png/.json``). **Snapshot-mesh study** (``realtime.snapshot_mesh_study``): the
   same azimuth-0 check for a table on each skin-study mesh. ``flexsheet/fem/model_table.json`` (full mode) is
   what the node chooses from.
3. ``summary.json``: ``realtime.update_ms``, ``realtime.max_visible_error_mm_0_50``, ``reference.converged``
   with the convergence figures.

``--quick``: two coarse meshes (h_fine 12 / 9 mm), 5 mm outputs, snapshots every 10 mm, a penalty study of two
scales, a skin study of one size (5 mm), a mirror study of one cut half model (h_fine 12 mm, against the
quarter model of the same h_fine): a test's run, 133 s cold on the 2-core machine with ``--jobs 2`` and
nothing beside it (the stable sweeps included; 148 s with the half model at 9 mm), seconds cached; it does not
meet the targets and cannot be "converged" (fewer than 3 meshes). The full mode (h_fine 8 / 6 / 4.5 / 3.4 /
2.5 mm, :data:`FULL_LEVELS`, 2.5 mm outputs, snapshots at azimuths 0, 10 and 20 every 5 mm, azimuth 5 held
out, penalty study, mirror study) is ~4.5 h of CPU cold on the 2-core machine with another solve beside it
(``cpu_seconds`` in convergence.json: the 2.5 mm mesh 31 min, the 3.4 mm 9 min, the two skin meshes 12 and 23
min, the azimuth-5, -10 and -20 paths ~37–39 min each on uncut meshes; in
mirror_study.json: the mirror study's cut half models 10, 22 and 71 min with two or three solves on the 2
cores, its stability check 11 min). Those CPU figures are from the einsum assembly, about twice the present
one's (docs/fem.md). ``--jobs N`` (default: the cores) solves the pushes the run reads in N worker processes
first (:func:`planned_solves`, :func:`prefetch`); ``--level N`` solves one mesh only and ``--node-table
--azimuth A`` one azimuth (for a run over several sittings or machines); every solve is cached
(:class:`flexsheet.fem.cache.ArrayCache`), so a second run takes seconds (27 s). ``--linear-study`` also
reruns the linear mesh study (``accuracy_table.json``, ``hertz``, ``stability``).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import time
from dataclasses import replace

from flexsheet.experiments.fem.plots import plot_node_table
from flexsheet.experiments.fem.runs import run
from flexsheet.experiments.fem_scene import run_scene
from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
from flexsheet.fem.choose import MODEL_TABLE_PATH
from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import CONTACT_LAWS, DEFAULT_CONTACT
from flexsheet.fem.reference.node_table import build_node_table, check_azimuth
from flexsheet.fem.reference.path_table import build_path_table
from flexsheet.fem.reference.settings import DEFAULT_MATERIAL, settings_for
from flexsheet.fem.reference.sphere_table import build_sphere_table
from flexsheet.fem.reference.workers import default_jobs, set_scheduler
from flexsheet.fem.snapshots import DEFAULT_GRID
from flexsheet.fem.sphere_snapshots import sphere_frame
from flexsheet.model.scene_parts import GENT_JM_RUBBER
from flexsheet.model.scenes import DEFAULT_SCENE_FILE, is_paper_cylinder, load_scene, load_scene_or_paper

log = logging.getLogger(__name__)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexsheet experiment fem", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example: flexsheet experiment fem --quick --out /tmp/fem\n"
                                       "         flexsheet experiment fem --out /tmp/fem --node-table "
                                       "--azimuth 10\n"
                                       "         flexsheet experiment fem --quick --mirror-study --out "
                                       "/tmp/fem\n         flexsheet experiment fem --holdout-study --out "
                                       "/tmp/fem\n         flexsheet experiment fem --quick --fold-study "
                                       "--out /tmp/fem\n         flexsheet experiment fem --quick "
                                       "--material-study --out /tmp/fem\n         flexsheet experiment fem "
                                       "--quick --scene launch/scenes/sphere.yaml --out /tmp/fem_sphere\n"
                                       "         flexsheet experiment fem --scene "
                                       "launch/scenes/rounded_box.yaml --node-table --jobs 2 --out "
                                       "/tmp/rb_table")
    _add_run_args(p)
    _add_study_args(p)
    _add_node_table_args(p)
    _add_scene_args(p)
    return p


def _add_run_args(p: argparse.ArgumentParser) -> None:
    """The flags of the run: output, mode, material, cache, contact law."""
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--quick", action="store_true", help="coarse meshes, azimuth 0 only (minutes cold, "
                                                        "seconds cached)")
    p.add_argument("--nu", type=float, default=None,
                   help=f"Poisson's ratio (default: the scene's, {Material().nu:g} for the default scene)")
    p.add_argument("--E", type=float, default=None,
                   help=f"Young's modulus, Pa (default: the scene's, {Material().E:g} for the default scene)")
    p.add_argument("--Jm", type=float, default=None, metavar="JM",
                   help="the reference's material: a Gent solid with this limiting extensibility (I1 - 3 <= "
                        f"JM; {GENT_JM_RUBBER:g} is Gent's natural-rubber fit), or inf: neo-Hookean "
                        f"(default: the scene's, {DEFAULT_MATERIAL.Jm:g} for the default scene, "
                        "launch/scenes/cylinder.yaml; the committed figures in docs/figures/fem/full, "
                        "quick_neohookean, fold and holdout are neo-Hookean runs, --Jm inf). Cached apart; "
                        "see --material-study")
    p.add_argument("--cache-dir", default=DEFAULT_CACHE_DIR, help="cache folder ('' disables; default "
                                                                  "%(default)s)")
    p.add_argument("--linear-study", action="store_true", help="also rerun the linear mesh study (slow)")
    p.add_argument("--level", type=int, default=None,
                   help="only solve convergence level N (0 = coarsest; fills the cache, so levels can run in "
                        "parallel processes before the full run), then exit")
    p.add_argument("--write-model-table", action="store_true",
                   help=f"write {os.path.relpath(MODEL_TABLE_PATH)} (default in full mode with the default "
                        "--contact and the default scene's material)")
    p.add_argument("--contact", choices=CONTACT_LAWS, default=None,
                   help="the finger's contact law in the reference: sticking (the fingertip does not slip on "
                        f"the tissue) or frictionless (default: with --node-table the default scene's, else "
                        f"{DEFAULT_CONTACT})")


def _add_study_args(p: argparse.ArgumentParser) -> None:
    """The flags of the studies that run alone."""
    p.add_argument("--mirror-study", action="store_true",
                   help="run the mirror study only (the azimuth-0 push on cut half models against the "
                        "quarter models, and the quarter models' stability; it solves what the "
                        "cache lacks, the convergence meshes included: hours cold in full mode) and write "
                        "mirror_study.json/png, then exit")
    p.add_argument("--holdout-study", action="store_true",
                   help="run the held-out azimuth check only (full mode: a snapshot table on azimuths 0 and "
                        "10 judged at 5 deg against its own solve on the cut half model, and at 0 against "
                        "the finest mesh; it solves what the cache lacks, ~1-2 h of two cores cold) and "
                        "write holdout_study.json/png, then exit")
    p.add_argument("--fold-study", action="store_true",
                   help="run the fold study only: does the reference's surface fold through itself (it has "
                        "no "
                        "self-contact), and is that where it does not converge? The last three convergence "
                        "levels at azimuth 0 (quick: its two), a tip-refined sequence (the push point "
                        "refined with the tube), a finer tip alone, and azimuth-0 snapshot tables on the "
                        "plain and tip meshes (full: ~1.5 h of two cores cold here, under a minute cached); "
                        "writes fold_study.json/png, then exits")
    p.add_argument("--material-study", action="store_true",
                   help="run the material study only: the azimuth-0 mesh convergence and an azimuth-0 "
                        "snapshot table for the neo-Hookean reference and for a Gent solid (--Jm, default "
                        f"{GENT_JM_RUBBER:g}); full: ~1 h of two cores cold here, seconds cached; writes "
                        "material_study.json/png, then exits")


def _add_node_table_args(p: argparse.ArgumentParser) -> None:
    """The flags of the node table's build and checks, and the worker processes."""
    p.add_argument("--node-table", action="store_true",
                   help="build the FEM node's nonlinear snapshot table (azimuths 0, 5, 7.5, 10-50 every 10, "
                        "55 and 60 deg, 2.5 mm depth steps, on the full run's h_fine 3.4 mm mesh) into the "
                        "cache the node reads, then exit. ~40 min of one core per azimuth (0 is shared with "
                        "the full run's 3.4 mm level); every azimuth's solve is cached, and a cached or "
                        "shipped table on fewer azimuths is extended (only the azimuths it lacks are solved)")
    p.add_argument("--ship", action="store_true",
                   help="with --node-table: also write the table, packed (float16 surface fields, "
                        "compressed), into flexsheet/fem/data/, which the node reads on a machine that never "
                        "solved it (commit it)")
    p.add_argument("--holdout-azimuth", type=float, action="append", default=[], metavar="DEG",
                   help="with --node-table: judge the table at this azimuth (between its own) against that "
                        "push's own solve on the table's mesh (solved unless cached, ~30 min of one core); "
                        "into node_table.json. Repeatable")
    p.add_argument("--between-depths", type=float, action="append", default=[], metavar="DEG",
                   help="with --node-table: judge the table between its depths at this azimuth (one of its "
                        "own) against that push solved at half the table's load step (~20 min of one core at "
                        "0, cached); into node_table.json. Repeatable")
    p.add_argument("--mesh-check", action="store_true",
                   help="the table mesh's noise: with --node-table --holdout-azimuth (the cylinder) each "
                        "held-out push also on a twin of the table's mesh (same sizes, laid out anew; ~30 "
                        "min of one core each); with --scene SPHERE --node-table at each --holdout-azimuth "
                        "(else 0 degrees) the push on the twin and on the study's wider-tube mesh and its "
                        "twin (~20 min each): each mesh's noise, and the table against each")
    p.add_argument("--azimuth", type=float, default=None, metavar="DEG",
                   help="with --node-table: solve only this azimuth's path into the cache and exit (run the "
                        "azimuths in parallel processes, then --node-table alone assembles the table)")
    p.add_argument("--jobs", type=int, default=default_jobs(), metavar="N",
                   help="solve the independent reference pushes the cache lacks in N worker processes first "
                        "(default %(default)s: the cores here; 1 solves them one by one in this process)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="solve them on the dask cluster whose scheduler listens at ADDRESS (tcp://HOST:8786; "
                        "its workers need flexsheet installed and this --cache-dir on a shared disk) instead "
                        "of a local cluster of --jobs processes")


def _add_scene_args(p: argparse.ArgumentParser) -> None:
    """The flags of another scene and its path table."""
    p.add_argument("--stations", type=int, default=13, metavar="K",
                   help="with --scene (not the cylinder or the sphere) --node-table: the path table's "
                        "stations, K evenly spaced fractions of the stroke, ends included (default "
                        "%(default)s, the shipped rounded box table's; each a 0-50 mm push, 4-9 min wall two "
                        "at a time on the rounded box); see flexsheet.fem.reference.path_table")
    p.add_argument("--holdout-fraction", type=float, action="append", default=[], metavar="F",
                   help="with --scene (not the cylinder or the sphere) --node-table: judge the path table at "
                        "this fraction of the stroke (between stations) against that push's own solve "
                        "(default: the midpoints of every second interval). Repeatable")
    p.add_argument("--scene", default=None,
                   help="scene file (launch/scenes/*.yaml); another object than the paper's cylinder runs "
                        "flexsheet.experiments.fem_scene on it (same summary keys), e.g. --scene "
                        "launch/scenes/sphere.yaml")


def main(argv: list[str] | None = None) -> int:
    """Run the experiment; returns 0. See the module docstring for the outputs. Progress goes to the modules'
    loggers at INFO (``flexsheet experiment fem`` shows them:
    :func:`flexsheet.runtime.console.show_lines`)."""
    args = _parser().parse_args(argv)
    try:
        set_scheduler(args.scheduler)
    except ValueError as exc:
        raise SystemExit(f"flexsheet experiment fem: {exc}") from None
    if args.jobs < 1:
        raise SystemExit(f"flexsheet experiment fem: --jobs must be >= 1, got {args.jobs}")
    if args.contact is None:
        args.contact = _node_law() if args.node_table and not args.scene else DEFAULT_CONTACT
    os.makedirs(args.out, exist_ok=True)
    _check_modes(args)
    sm = DEFAULT_MATERIAL                        # the default scene's; a paper-cylinder --scene file's below
    if args.scene:
        done, sm = _scene(args)
        if done is not None:
            return done
    try:
        # given: replace
        mat = Material(sm.E if args.E is None else args.E, sm.nu if args.nu is None else args.nu,
                       sm.Jm if args.Jm is None else args.Jm)  # the scene's
    except ValueError as exc:
        raise SystemExit(f"flexsheet experiment fem: {exc}") from None
    _check_table_values(args)
    st = replace(settings_for(args.quick), contact=args.contact)
    t0 = time.perf_counter()
    cache = ArrayCache(args.cache_dir or None)
    _check_table_flags(args)
    if args.node_table:
        if args.quick or args.level is not None:
            raise SystemExit("flexsheet experiment fem: --node-table builds the node's full table; it takes "
                             "neither --quick nor --level")
        return build_node_table(mat, cache, args.cache_dir or None, st.contact, args.azimuth, args.jobs,
                                args.ship,
                                args.out, tuple(args.holdout_azimuth), tuple(args.between_depths),
                                args.mesh_check,
                                plot=plot_node_table)
    rc = run(args, st, mat, cache, t0)
    if rc == 0 and args.quick and not (args.level is not None or args.linear_study or args.mirror_study
                                       or args.holdout_study or args.fold_study or args.material_study
                                       or (args.E, args.nu, args.Jm) != (None, None, None)):
        _judge_cylinder(args)
    return rc


def _judge_cylinder(args) -> None:
    """The paper's cylinder judged as every scene is (:func:`flexsheet.experiments.fem_scene.run_scene`, into
    ``--out``/visible/): its ``scene``, ``visible``, ``contact`` and ``temporal`` blocks and
    ``reference.gci_px`` join the run's summary.json. Only for the scene file's own material (no
    --E/--nu/--Jm)."""
    import json

    s = run_scene(args.scene or DEFAULT_SCENE_FILE, os.path.join(args.out, "visible"), True,
                  args.cache_dir or None, args.jobs)
    path = os.path.join(args.out, "summary.json")
    with open(path) as fh:
        summary = json.load(fh)
    summary.update({k: s[k] for k in ("scene", "visible", "contact", "temporal")})
    summary["realtime"]["update_ms_served"] = s["realtime"]["update_ms"]
    summary["reference"].update({"gci_px": s["reference"]["gci_px"],
                                 "gci_px_by_depth": s["reference"]["gci_px_by_depth"],
                                 "gci_target_px": s["reference"]["target_px"],
                                 "visible_levels": s["reference"]["levels"]})
    with open(path, "w") as fh:
        json.dump(summary, fh, indent=1)


def _check_modes(args) -> None:
    """``SystemExit`` for a study flag with another mode or study, ``--holdout-study`` with ``--quick``, and
    ``--mesh-check`` without a table that takes it."""
    studies = ("--mirror-study", args.mirror_study), ("--holdout-study", args.holdout_study), \
        ("--fold-study", args.fold_study), ("--material-study", args.material_study)
    for flag, on in studies:
        if on and (args.node_table or args.level is not None or args.linear_study or args.scene
                   or sum(o for _, o in studies) > 1):
            raise SystemExit(f"flexsheet experiment fem: {flag} (the paper's cylinder) takes none of "
                             "--node-table, --level, --linear-study, --scene, and runs alone")
    if args.holdout_study and args.quick:
        raise SystemExit("flexsheet experiment fem: --holdout-study is a full-mode study (the quick settings "
                         "hold no azimuth out); leave out --quick")
    if args.mesh_check and not (args.node_table and (args.scene or args.holdout_azimuth)):
        raise SystemExit("flexsheet experiment fem: --mesh-check is for --node-table with --holdout-azimuth "
                         "(the cylinder) or --scene SPHERE.yaml --node-table")


def _scene(args) -> tuple[int | None, Material]:
    """``--scene``: another object than the paper's cylinder runs its own experiment (the path table, the
    sphere's table or :func:`flexsheet.experiments.fem_scene.run_scene`): (its return code, None); the paper's
    cylinder: (None, the scene file's material)."""
    try:
        sc = load_scene_or_paper(args.scene)
    except ValueError as exc:
        raise SystemExit(f"flexsheet experiment fem: {exc}") from None
    if not is_paper_cylinder(sc) and args.between_depths:
        raise SystemExit("flexsheet experiment fem: --between-depths is for the paper's cylinder's table")
    if not is_paper_cylinder(sc) and args.node_table:
        return _scene_table(args, sc), None
    if not is_paper_cylinder(sc):
        run_scene(args.scene, args.out, args.quick, args.cache_dir or None, args.jobs)
        return 0, None
    return None, Material.of_scene(sc.material)


def _scene_table(args, sc) -> int:
    """``--scene`` (not the cylinder) ``--node-table``: the sphere's table where the scene has the sphere's
    symmetry, else the path table."""
    try:
        sphere_frame(sc)
    except ValueError:          # no symmetry to carry one push onto another: the path table

        if args.azimuth is not None or args.holdout_azimuth:
            raise SystemExit("flexsheet experiment fem: --azimuth / --holdout-azimuth are the cylinder's and "
                             "the sphere's; a path table takes --stations and --holdout-fraction") from None
        return build_path_table(args.scene, args.out, args.cache_dir or None, args.stations,
                                tuple(args.holdout_fraction) or None, args.jobs, args.mesh_check, args.ship)

    return build_sphere_table(args.scene, args.out, args.cache_dir or None, args.azimuth,
                              tuple(args.holdout_azimuth), args.jobs, args.mesh_check, args.ship)


def _check_table_values(args) -> None:
    """``SystemExit`` for a ``--holdout-azimuth`` or ``--between-depths`` value the node table cannot be
    judged at, ``--between-depths`` without ``--node-table`` (or with ``--azimuth``), and ``--ship`` of
    another contact law than the node's."""
    if args.holdout_azimuth:
        inner = DEFAULT_GRID.angles_deg
        for a in args.holdout_azimuth:
            if not (math.isfinite(a) and inner[0] < a < inner[-1]) or a in inner:
                raise SystemExit("flexsheet experiment fem: --holdout-azimuth must lie strictly between the "
                                 f"node table's azimuths {[f'{x:g}' for x in inner]} deg and off them, got "
                                 f"{a:g}")
    for a in args.between_depths:
        if a not in DEFAULT_GRID.angles_deg:
            raise SystemExit("flexsheet experiment fem: --between-depths must be one of the node table's "
                             f"azimuths {[f'{x:g}' for x in DEFAULT_GRID.angles_deg]} deg, got {a:g}")
    if args.between_depths and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --between-depths is for --node-table without --azimuth")


def _node_law() -> str:
    """The contact law of the default scene (launch/scenes/cylinder.yaml): the node's table is looked up under
    it."""
    return load_scene(DEFAULT_SCENE_FILE).finger.contact


def _check_table_flags(args) -> None:
    """``SystemExit`` for ``--holdout-azimuth``, ``--ship`` or ``--azimuth`` without the ``--node-table`` run
    that takes it, and an ``--azimuth`` the node table does not have."""
    if args.holdout_azimuth and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --holdout-azimuth is for --node-table without --azimuth")
    if args.ship and (not args.node_table or args.azimuth is not None):
        raise SystemExit("flexsheet experiment fem: --ship is for --node-table without --azimuth (it ships "
                         "the assembled table)")
    if args.ship and not args.scene and args.contact != (law := _node_law()):
        raise SystemExit(f"flexsheet experiment fem: --ship ships the table the node looks up (the default "
                         f"scene's {law} contact); got --contact {args.contact}")
    if args.azimuth is not None:
        if not args.node_table:
            raise SystemExit("flexsheet experiment fem: --azimuth is for --node-table")
        check_azimuth(args.azimuth)
