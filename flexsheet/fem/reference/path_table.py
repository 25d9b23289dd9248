"""A scene's nonlinear path table: ``flexsheet experiment fem --scene launch/scenes/NAME.yaml
--node-table [--stations K] [--holdout-fraction F ...] [--jobs N] [--ship] --out DIR`` for any scene but the
paper's cylinder and the sphere (wired by :mod:`flexsheet.experiments.fem`; the runtime is
:mod:`flexsheet.fem.path_snapshots`).

1. **Stations**: K fractions of the stroke's arc length, evenly spaced, start and end included
   (``--stations``, default :data:`DEFAULT_STATIONS`, 13). At each, the scene's hyperelastic reference
   (:func:`flexsheet.fem.reference.scene_reference.scene_reference`: the scene's law and finger contact, full
   body, its support and inclusions) is pushed along the inward normal 0 → :data:`GRID` ``depth_max`` in 2.5
   mm steps on a mesh refined along the whole push path (``h_fine`` 6 mm within 15 mm of it: the scene FULL
   run's first level), sampled on the real-time model's rendered vertices; each push is cached on its own,
   ``--jobs`` solves the missing ones in worker processes.
2. **The table**: per station and depth the reference minus the real-time linear model's solve of the same
   push, and the force and dF/dd ratios (module doc of :mod:`flexsheet.fem.path_snapshots`); stored under the
   key the FEM node looks up (:func:`table_key`); ``--ship`` also writes it into ``flexsheet/fem/data/``.
3. **Held out** (``--holdout-fraction``, default the midpoints of every second interval): a push between
   stations solved on its own mesh (refined along *its* path), against what the node serves there (the
   stations' states moved and turned with the contact, blended) and against the linear model alone: the
   largest visible shape error, px (:func:`flexsheet.fem.eye_judge.shape_px_by_depth`: what either eye sees,
   the finger occluding) at every depth. This judges the interpolation along the stroke and in depth (and the
   two meshes' difference); it is not a judgement of the reference against physics, which is one mesh level
   here (``--mesh-check``: the same push at the middle station on a mesh refined to 4 mm, the next level,
   gives its change). Look-up time: the updating thread's CPU per update with the table attached.

Outputs: ``DIR/path_table.json`` + ``path_table.png``: stations (DOF, CPU, Newton, force), held-out errors
(px) per depth, the look-up time (ms), the shipped file. Units in keys (px, mm, ms, N), else SI.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time

import numpy as np

__all__ = ["build_path_table", "table_key", "DEFAULT_STATIONS", "assemble_path_table"]

from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
from flexsheet.fem.eye_judge import shape_px_by_depth
from flexsheet.fem.path_snapshots import GRID, REACH, path_table_key, stiffness_from_force
from flexsheet.fem.reference.scene_reference import FULL, scene_reference
from flexsheet.fem.reference.workers import parallel, run_workers, set_scheduler
from flexsheet.fem.scene_model import SceneModel, finger_on_scene
from flexsheet.fem.served import scene_update_ms
from flexsheet.model.scenes import load_scene
from flexsheet.runtime.console import LIBRARY, show_lines

log = logging.getLogger(__name__)

TARGET_PX = 1.0      #: a table's largest visible shape error, projector px
DEFAULT_STATIONS = 13          #: the shipped rounded box table's (7 missed by 4.7 mm over the edge)
#: ``--mesh-check``'s finer level (h_fine, m): the scene FULL run's second level
CHECK_H_FINE = 0.004
#: the depths (m) the look-up is timed at, 5 stroke points each
LOOKUP_DEPTHS = (0.005, 0.02, 0.045)


def _st() -> dict:
    """The stations' settings for :func:`flexsheet.fem.reference.scene_reference.scene_reference`: the scene
    full run's (:data:`flexsheet.fem.reference.scene_reference.FULL`, whose first level is :data:`GRID`'s), so
    its pushes are shared."""
    return {k: FULL[k] for k in ("depths", "step", "h", "refine_radius", "path_depth")}


def table_key(sc, rt) -> str:
    """The key the FEM node looks a scene's path table up by
    (:func:`flexsheet.fem.path_snapshots.path_table_key`) for the scene ``sc`` and the real-time model ``rt``
    it corrects."""
    return path_table_key(sc.key(), rt.cache_key)


def _push(sc, f: float, h_fine: float, probes, cache) -> dict:
    q, n = sc.stroke_at([f])
    return scene_reference(sc, q[0], n[0], h_fine, _st(), probes, cache)


def _job(args) -> tuple[float, float, str | None]:
    """Worker: one push into the cache (fraction, h_fine); returns (fraction, seconds, error or None)."""
    scene_file, f, h_fine, cache_dir = args
    t = time.perf_counter()
    try:
        sc = load_scene(scene_file)
        rt = SceneModel(sc, cache_dir=cache_dir)
        _push(sc, f, h_fine, rt.rest_vertices.astype(float), ArrayCache(cache_dir))
        return f, time.perf_counter() - t, None
    except Exception as exc:  # noqa: BLE001 - reported by the parent, which solves it again in-process
        return f, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"


def _prefetch(scene_file, jobs_list, cache_dir, n_jobs: int) -> None:
    if not parallel(n_jobs) or len(jobs_list) <= 1:
        return

    log.info(f"solving {len(jobs_list)} pushes in {n_jobs} worker processes ...")
    for f, sec, err in run_workers(_job, [(scene_file, f, h, cache_dir) for f, h in jobs_list], n_jobs):
        log.info(f"  push at fraction {f:.4g}: {'failed: ' + err if err else 'done'} ({sec:.0f} s wall)")


def _linear(rt, sc, q, n, depths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The real-time linear model's surface displacement (D, S, 3), force (D,), stiffness (D,) at the push."""
    out = [rt.surface_displacement(finger_on_scene(q, n, float(d), sc.finger.radius)) for d in depths]
    return (np.stack([o[0] for o in out]), np.array([o[1] for o in out]), np.array([o[2] for o in out]))


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num/den over (D,) with d = 0 (index 0) taking the first depth's ratio."""
    r = np.ones_like(num, dtype=float)
    ok = np.abs(den) > 1e-12
    r[ok] = num[ok] / den[ok]
    r[0] = r[1]
    return r


def assemble_path_table(sc, rt, fractions, refs: list[dict]) -> dict:
    """The path table (:data:`flexsheet.fem.path_snapshots.TABLE_FIELDS`) from the stations' reference pushes
    ``refs`` (one :func:`flexsheet.fem.reference.scene_reference.scene_reference` result per fraction, sampled
    on ``rt``'s rendered vertices at :data:`GRID`'s depths) and the real-time model ``rt``'s linear solves.
    The table reaches the deepest depth to which every station's Newton solve converged at every load step (so
    a scene whose reference stalls gets a shallower table, the linear model beyond it). Raises ``ValueError``
    when no station converged at the first depth."""
    depths = np.concatenate([[0.0], np.asarray(_st()["depths"])])
    ok = np.all([np.asarray(r["converged"], bool) for r in refs], axis=0)  # (D-1,) every station converged
    n_ok = int(np.argmin(ok)) if not ok.all() else len(ok)
    if n_ok < 1:
        raise ValueError("path table: Newton did not converge at the first depth of every station")
    depths = depths[:n_ok + 1]                  # the table stops before the first depth a station failed at
    refs = [{k: (np.asarray(v)[:n_ok] if k in ("u", "force", "converged", "inverted", "max_strain") else v)
             for k, v in r.items()} for r in refs]
    K, S = len(fractions), len(rt.rest_vertices)
    corr = np.zeros((K, len(depths), S, 3), np.float32)
    fr, kr = np.ones((K, len(depths))), np.ones((K, len(depths)))
    inv, strain = np.zeros((K, len(depths))), np.zeros((K, len(depths)))
    pts, nrm = sc.stroke_at(np.asarray(fractions, float))
    for i, (q, n, ref) in enumerate(zip(pts, nrm, refs, strict=True)):
        u_lin, f_lin, k_lin = _linear(rt, sc, q, n, depths[1:])
        corr[i, 1:] = (np.asarray(ref["u"]) - u_lin).astype(np.float32)
        f_ref = np.concatenate([[0.0], np.asarray(ref["force"], float)])
        k_ref = stiffness_from_force(f_ref, depths)
        fr[i] = _ratio(f_ref, np.concatenate([[0.0], f_lin]))
        kr[i] = _ratio(k_ref, np.concatenate([[k_lin[0]], k_lin]))
        inv[i, 1:] = np.asarray(ref["inverted"], float)
        strain[i, 1:] = np.asarray(ref["max_strain"], float)
    corr[:, :, rt.held] = 0.0
    return {"fractions": np.asarray(fractions, float), "depths": depths, "points": pts, "normals": nrm,
            "rest_vertices": rt.rest_vertices.astype(np.float64), "correction": corr, "force_ratio": fr,
            "stiffness_ratio": kr, "inverted": inv, "max_strain": strain, "reach": np.array(REACH)}


def _path_fractions(stations, holdout) -> tuple[np.ndarray, tuple[float, ...]]:
    """The stations' fractions and the held-out ones (``holdout`` None or empty: the midpoints of every second
    interval), after the arguments are checked (``SystemExit`` naming the argument)."""
    if int(stations) < 2:
        raise SystemExit(f"flexsheet experiment fem: --stations must be >= 2, got {stations}")
    fractions = np.linspace(0.0, 1.0, int(stations))
    if holdout is None or len(holdout) == 0:
        holdout = tuple(float((fractions[i] + fractions[i + 1]) / 2) for i in range(0, len(fractions) - 1, 2))
    for h in holdout:
        if not (0.0 < h < 1.0) or np.min(np.abs(fractions - h)) < 1e-6:
            raise SystemExit(f"flexsheet experiment fem: --holdout-fraction {h} must lie in (0, 1) between "
                             f"the stations {np.round(fractions, 4).tolist()}")
    return fractions, holdout


def _ship_path_table(cache, key: str, table: dict, fractions, refs) -> dict:
    """The table written into the shipped store (``SystemExit`` when a station did not converge): its path,
    MB."""
    bad = [float(f) for f, r in zip(fractions, refs, strict=True) if not np.all(r["converged"])]
    if bad:
        raise SystemExit(f"flexsheet experiment fem: not shipping the path table: Newton did not converge at "
                         f"every depth of the stations at fractions {bad}")
    sp = cache.ship("pathsnap", key, table)
    shipped = {"path": os.path.relpath(sp, os.getcwd()), "MB": os.path.getsize(sp) / 1e6}
    log.info(f"path table shipped: {sp} ({shipped['MB']:.2f} MB)")
    return shipped


def _held_out_pushes(sc, rt, verts, cache, holdout, depths) -> list[dict]:
    """Per held-out fraction: its own push against what the node serves (table attached) and the linear
    model."""
    nd = len(depths)
    held_out = []
    for h in holdout:
        ref = _push(sc, float(h), GRID["h_fine"], verts, cache)
        q, n = sc.stroke_at([h])
        q, n = q[0], n[0]
        ups = [rt.update_finger(finger_on_scene(q, n, float(d), sc.finger.radius)) for d in depths]
        u_tab = np.stack([up.vertices.astype(float) - verts for up in ups])
        u_lin = _linear(rt, sc, q, n, depths)[0]
        u_ref = np.asarray(ref["u"])[:nd]
        fingers = [finger_on_scene(q, n, float(d), sc.finger.radius) for d in depths]
        faces = np.asarray(rt.faces)
        e_tab = shape_px_by_depth(u_tab, u_ref, verts, faces, fingers)
        e_lin = shape_px_by_depth(u_lin, u_ref, verts, faces, fingers)
        over = [float(d * 1e3) for d, e in zip(depths, e_tab, strict=True) if e > TARGET_PX]
        held_out.append({"fraction": float(h), "point_m": q.tolist(), "dofs": int(ref["dofs"]),
                         "newton_converged": bool(np.all(np.asarray(ref["converged"])[:nd])),
                         "methods": sorted({up.method for up in ups}),
                         "table_shape_px": e_tab, "linear_shape_px": e_lin,
                         "table_max_px": max(e_tab), "linear_max_px": max(e_lin),
                         "force_N": np.asarray(ref["force"])[:nd].tolist(),
                         "served_force_N": [up.force for up in ups],
                         "depths_over_target_mm": over})
        log.info(f"held out at {h:.4g}: table {max(e_tab):.2f} px (over the target at {over} mm), linear "
             f"{max(e_lin):.2f} px")
    return held_out


def _path_mesh_check(sc, faces, verts, cache, fractions, refs, depths) -> dict:
    """``--mesh-check``: the middle station's push on the finer mesh against the table's, on the visible
    surface."""
    nd = len(depths)
    f = float(fractions[len(fractions) // 2])
    fine = _push(sc, f, CHECK_H_FINE, verts, cache)
    q, n = sc.stroke_at([f])
    fingers = [finger_on_scene(q[0], n[0], float(d), sc.finger.radius) for d in depths]
    ch = shape_px_by_depth(np.asarray(refs[len(fractions) // 2]["u"])[:nd], np.asarray(fine["u"])[:nd], verts,
                           faces, fingers)
    check = {"fraction": f, "h_fine_m": CHECK_H_FINE, "dofs": int(fine["dofs"]),
             "cpu_seconds": float(fine["seconds"]), "newton_converged": bool(np.all(fine["converged"])),
             "change_px": ch, "max_change_px": max(ch)}
    log.info(f"mesh check at {f:.4g}: h_fine {CHECK_H_FINE * 1e3:g} mm moves the visible shape by "
             f"{max(ch):.2f} px at most")
    return check


def _path_report(sc, fractions, table, refs, depths, held_out, look, lin_ms, check, shipped, key, t0) -> dict:
    """The report's JSON (``path_table.json``)."""
    return {"scene": {"name": sc.name, "file": str(sc.source), "key": sc.key(), "contact": sc.finger.contact,
                      "law": sc.material.model},
            "what": "the scene's nonlinear path table (flexsheet/fem/path_snapshots.py): the stations' "
                    "solved states (the real-time linear solve plus the reference-minus-linear correction), "
                    "each moved and turned with the contact and blended along the stroke and in depth; "
                    "held-out pushes between stations on their own meshes, the largest visible shape error "
                    "(px)",
            "grid": GRID, "reach_m": REACH, "stroke_length_m": sc.stroke_length(),
            "stations": [{"fraction": float(f), "point_m": p.tolist(), "dofs": int(r["dofs"]),
                          "seconds": float(r["seconds"]), "newton_converged": bool(np.all(r["converged"])),
                          "inverted_max": int(np.max(r["inverted"])),
                          "max_strain": float(np.max(r["max_strain"])),
                          "force_N": np.asarray(r["force"]).tolist()}
                         for f, p, r in zip(fractions, table["points"], refs, strict=True)],
            "depths_m": depths.tolist(), "table_depth_max_m": float(depths[-1]), "held_out": held_out,
            "max_held_out_shape_px": max((h["table_max_px"] for h in held_out), default=None),
            "max_held_out_linear_shape_px": max((h["linear_max_px"] for h in held_out), default=None),
            "lookup_ms": look["median"], "lookup_ms_p90": look["p90"], "lookup_methods": look["methods"],
            "linear_update_ms": lin_ms["median"],
            "lookup_timing": "the updating thread's CPU (time.thread_time) per update_finger at 5 points x "
                             "5/20/45 mm along the stroke (flexsheet.fem.served.scene_update_ms)",
            "mesh_check": check, "target_px": TARGET_PX, "shipped": shipped, "key": key,
            "seconds": time.perf_counter() - t0}


def build_path_table(scene_file: str, out: str | None, cache_dir: str | None,
                     stations: int = DEFAULT_STATIONS,
                     holdout: tuple[float, ...] | None = None, jobs: int = 1, mesh_check: bool = False,
                     ship: bool = False) -> int:
    """Build (or find in the cache) the scene's path table and report it (module doc). ``holdout`` None: the
    midpoints of every second interval. Returns 0; raises ``SystemExit`` naming the argument for fewer than 2
    stations, a held-out fraction outside (0, 1) or on a station, or an unconverged station with ``ship``."""
    fractions, holdout = _path_fractions(stations, holdout)
    t0 = time.perf_counter()
    cache_dir = cache_dir or DEFAULT_CACHE_DIR
    cache = ArrayCache(cache_dir)
    sc = load_scene(scene_file)
    rt = SceneModel(sc, cache_dir=cache_dir)
    verts = rt.rest_vertices.astype(float)
    todo = [(float(f), GRID["h_fine"]) for f in fractions] + [(float(h), GRID["h_fine"]) for h in holdout]
    if mesh_check:
        todo.append((float(fractions[len(fractions) // 2]), CHECK_H_FINE))
    _prefetch(scene_file, todo, cache_dir, jobs)
    refs = [_push(sc, float(f), GRID["h_fine"], verts, cache) for f in fractions]
    table = assemble_path_table(sc, rt, fractions, refs)
    key = table_key(sc, rt)
    cache.save("pathsnap", key, table)
    shipped = _ship_path_table(cache, key, table, fractions, refs) if ship else None
    lin_ms = scene_update_ms(rt, sc, LOOKUP_DEPTHS, 200)
    rt.attach_path_table(table)
    look = scene_update_ms(rt, sc, LOOKUP_DEPTHS, 200)
    log.info(f"look-up with the table: CPU median {look['median']:.3f} ms (linear alone "
             f"{lin_ms['median']:.3f} ms)")
    depths = np.asarray(table["depths"][1:])            # the table's reach (every station converged to it)
    held_out = _held_out_pushes(sc, rt, verts, cache, holdout, depths)
    check = (_path_mesh_check(sc, np.asarray(rt.faces), verts, cache, fractions, refs, depths) if mesh_check
             else None)
    rep = _path_report(sc, fractions, table, refs, depths, held_out, look, lin_ms, check, shipped, key, t0)
    if out:
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "path_table.json"), "w") as fh:
            json.dump(rep, fh, indent=1)
        _plot(out, rep)
        log.info(f"report: {os.path.join(out, 'path_table.json')}")
    return 0


def _plot(out: str, rep: dict) -> None:
    """``path_table.png``: held-out visible error against depth, table and linear, per held-out fraction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.asarray(rep["depths_m"]) * 1e3
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, h in enumerate(rep["held_out"]):
        c = f"C{i}"
        ax[0].plot(d, h["table_shape_px"], "-o", ms=3, color=c, label="table, held out at "
                                                                      f"{h['fraction']:.3f}")
        ax[0].plot(d, h["linear_shape_px"], "--", color=c, alpha=0.6, label=f"linear, {h['fraction']:.3f}")
    ax[0].axhline(rep["target_px"], color="k", lw=0.8, ls=":", label=f"target {rep['target_px']:g} px")
    ax[0].set_xlabel("push depth (mm)")
    ax[0].set_ylabel("largest visible shape error (projector px)")
    ax[0].set_title(f"{rep['scene']['name']}: held-out pushes between stations")
    ax[0].legend(fontsize=7)
    for s in rep["stations"]:
        ax[1].plot(d, s["force_N"], label=f"station {s['fraction']:.3f}")
    for h in rep["held_out"]:
        ax[1].plot(d, h["force_N"], "k:", lw=1)
        ax[1].plot(d, h["served_force_N"], "r--", lw=1)
    ax[1].set_xlabel("push depth (mm)")
    ax[1].set_ylabel("finger force (N)")
    ax[1].set_title("reference force (held out: dotted; served: red dashed)")
    ax[1].legend(fontsize=7)
    fig.suptitle(f"look-up {rep['lookup_ms']:.2f} ms (CPU median); linear alone {rep['linear_update_ms']:.2f}"
                 " ms",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "path_table.png"), dpi=110)
    plt.close(fig)


def main(argv=None) -> int:  # pragma: no cover - thin CLI for a by-hand run
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="example: python -m flexsheet.fem.reference.path_table --scene "
                                        "launch/scenes/rounded_box.yaml --jobs 2 --out out/rb_table")
    ap.add_argument("--scene", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--stations", type=int, default=DEFAULT_STATIONS)
    ap.add_argument("--holdout-fraction", type=float, action="append", default=[])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--scheduler", default=None, help="a dask scheduler, tcp://HOST:PORT (default: local)")
    ap.add_argument("--mesh-check", action="store_true")
    ap.add_argument("--ship", action="store_true")
    ap.add_argument("--cache-dir", default=None)
    a = ap.parse_args(argv)

    show_lines(LIBRARY)         # the library's progress, the worker pool's included
    try:
        set_scheduler(a.scheduler)
    except ValueError as exc:
        ap.error(str(exc))
    return build_path_table(a.scene, a.out, a.cache_dir, a.stations, tuple(a.holdout_fraction), a.jobs,
                            a.mesh_check, a.ship)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
