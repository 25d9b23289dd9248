"""The real-time candidates judged against the reference: the validation cases (:func:`validation_set`), the
snapshot table's source (:func:`snapshot_source`), each candidate's visible error and update time
(:func:`candidates`, :func:`update_ms`), and the azimuth-0 table checks of candidate snapshot meshes
(:func:`azimuth0_table_errors`, :func:`snapshot_mesh_study`)."""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.contact import finger_at
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import path_states, push_depths, stable_path
from flexsheet.fem.reference.settings import FINGER_R, TARGET, Settings
from flexsheet.fem.reference.snapshot_build import load_or_build
from flexsheet.fem.visible_error import errors

log = logging.getLogger(__name__)


def validation_set(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                   fine: dict) -> list[dict]:
    """Reference fields at the rendered vertices for the configurations the candidates are judged on: azimuth
    0 from the finest convergence mesh (every depth), and each held-out azimuth on the snapshot mesh."""
    depths = push_depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    snap_d = st.grid.depths()
    out = [{"angle_deg": 0.0, "depth": float(d), "u": fine["u"][j], "source": "finest convergence mesh",
            "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(depths)]
    for a in st.holdout_deg:
        p = stable_path(st.snap_spec, a, depths, mat, cache, verts, st.contact)
        out += [{"angle_deg": float(a), "depth": float(d), "u": p["u"][j], "source": "held-out azimuth",
                 "held_out": True} for j, d in enumerate(depths)]
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
    sd = push_depths(st.fine_step if st.snap_spec == st.levels[-1] else st.depth_step)
    src = stable_path(st.snap_spec, 0.0, sd, mat, cache, verts, st.contact)

    def solved(ang, model, depths):
        if ang == 0.0:
            return path_states(src, sd, depths, model)
        fd = push_depths(st.fine_step)  # other azimuths: the cached path the held-out check also reads
        p = stable_path(st.snap_spec, ang, fd, mat, cache, verts, st.contact)
        return path_states(p, fd, depths, model)

    return solved, src


def update_ms(rm: RealtimeModel, angles_deg, depths, n: int) -> dict:
    """Median and 90th-percentile wall time (ms) of ``rm.update_finger`` over ``n`` calls per
    configuration."""
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
    log.info("linear (capacitance) model: errors against the nonlinear reference ...")
    res["linear"] = {"name": f"linear P2 {st.linear_spec.key()}", "kind": "linear",
                     "errors_m": errors(rm, cases, "linear"),
                     "time_ms": update_ms(rm, [a for a in t_angles if a <= st.linear_spec.arc_deg + 1e-9],
                                          t_depths, st.n_time)}
    rm.snapshots = snap
    res["snapshots"] = {"name": "nonlinear snapshots", "kind": "snapshots",
                        "errors_m": errors(rm, cases, "snapshots"),
                        "errors_rest_footprint_m": errors(rm, cases, "snapshots", rest_footprint=True),
                        "time_ms": update_ms(rm, t_angles, t_depths, st.n_time),
                        "table_MB": snap.nbytes / 1e6}
    for k, v in res.items():
        log.info(f"  {k}: worst visible error {max(v['errors_m']) * 1e3:.2f} mm, update "
                 f"{v['time_ms']['median']:.3f} ms")
    return res


def azimuth0_table_errors(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, spec: RefSpec,
                          cases: list[dict]) -> tuple[dict, list[float]]:
    """(the stable branch of ``spec``'s azimuth-0 push at ``push_depths(st.depth_step)``, :func:`errors` in m
    of an azimuth-0 snapshot table on ``st.grid``'s depths built from it, on ``cases``): how
    :func:`snapshot_mesh_study` and :func:`_tip_snapshots` judge a candidate snapshot mesh. ``rm``'s table is
    left as it was."""
    sd = push_depths(st.depth_step)
    src = stable_path(spec, 0.0, sd, mat, cache, rm.rest_vertices.astype(float), st.contact)  # as every table
    table = load_or_build(cache, replace(st.grid, angles_deg=(0.0,)), spec, mat, FINGER_R, build=True,
                          contact=st.contact,
                          solved=lambda ang, model, depths: path_states(src, sd, depths, model))[0]
    keep = rm.snapshots
    try:
        rm.attach_snapshots(table)
        return src, errors(rm, cases, "snapshots")
    finally:
        rm.snapshots = keep


def snapshot_mesh_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, cases: list[dict]
                        ) -> dict:
    """Which mesh the snapshots need: an azimuth-0 table (``st.grid``'s depths) on the next-to-finest mesh
    (full mode: the snapshot mesh) and on each of its skin-refined variants (``st.skin_sizes``; the
    convergence and skin studies' solves, read from the cache), judged on the azimuth-0 validation cases (the
    finest convergence mesh; depths between snapshots held out). Per mesh: DOF, CPU of its azimuth-0 path and
    the worst visible
    error (mm). ``rm``'s snapshot table is left as it was."""
    az0 = [c for c in cases if c["angle_deg"] == 0.0]
    rows = []
    base = st.levels[-2]  # the skin study's meshes (full mode: the snapshot mesh and its skins)
    for spec in [base] + [replace(base, skin_h=h) for h in st.skin_sizes]:
        src, err = azimuth0_table_errors(st, mat, cache, rm, spec, az0)
        rows.append({"spec": spec.__dict__, "skin_h_m": spec.skin_h, "dofs": int(src["dofs"]),
                     "cpu_seconds_per_azimuth": float(src["cpu_seconds"]),
                     "max_visible_error_mm": max(err) * 1e3,
                     "max_visible_error_mm_held_out_depths": max(
                         (e for c, e in zip(az0, err, strict=True) if c["held_out"]), default=float("nan"))
                     * 1e3})
        log.info(f"snapshot mesh {spec.key()}: {rows[-1]['dofs']} DOF, azimuth 0 worst visible error "
                 f"{rows[-1]['max_visible_error_mm']:.2f} mm")
    return {"azimuth_deg": 0.0, "depth_step_mm": st.grid.depth_step * 1e3, "target_mm": TARGET * 1e3,
            "against": f"the finest convergence mesh (h_fine {st.levels[-1].h_fine * 1e3:g} mm), every "
                       f"{st.fine_step * 1e3:g} mm",
            "meshes": rows}
