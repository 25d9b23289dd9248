"""One-off (session 30): how fine must a scene's reference mesh be for the 0.7 mm target, and what would that
cost on this machine? The middle station of ``docs/figures/scenes/NAME/path_table/path_table.json`` pushed at
four mesh levels (h_fine 6, 5, 4, 3 mm along the push path; 6 mm is the shipped table's, 4 mm session 29's
``mesh_check.py``, 5 and 3 mm new), compared over the visible rendered vertices (not held, outside the finger's
footprint) with the finest, depth by depth, and split three ways (the funnel the finger makes, < 20 mm from the
push axis; a band one coarse element wide beside the support; the rest).

From those numbers, an **estimate**, not a measurement: at each depth the differences to the finest level are
fitted by D(h) = C (h^p − h_min^p) (the leading error term e(h) = C h^p, assumed in its asymptotic range and of
one sign on the worst vertex), least squares over p in [0.25, 4]; the finest level's own remaining error is then
C h_min^p and the size that would meet the target h* = (0.7 mm / C)^(1/p). With three or four levels and a
sticking contact that fit is fragile (it lands on p's bounds at several depths), so at 50 mm the same is also
given for a fixed order p = 1 and p = 2 (P2 elements on a smooth solution would do at least 2; the edge of a
sticking contact patch is not smooth). Cost: DOF and CPU seconds per push fitted as power laws of h_fine over
the levels (log-log least squares) and evaluated at h*; CPU seconds as measured, with whatever ran beside.

Run from the repository root: ``python3 docs/figures/scenes/mesh_levels.py organ`` (cold: the 5 and 3 mm pushes
in two worker processes, about an hour of one core for the 3 mm one; seconds cached), or with the levels in mm
after the name, coarse to fine (``python3 docs/figures/scenes/mesh_levels.py rounded_box 6 5 4``: with three
levels the fit of C and p is exact, its rms 0 says nothing). ``--gent JM``: the same scene with a Gent solid
of limit JM (E and ν kept; the cylinder's remedy for a neo-Hookean push with no mesh limit, session 17), written
to ``mesh_levels_gentJM.json``. Writes ``docs/figures/scenes/NAME/mesh_levels/mesh_levels.json``."""

import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, ".")

DEFAULT_LEVELS = (0.006, 0.005, 0.004, 0.003)     #: h_fine, m, coarse to fine


def fit_fixed(h_mm: np.ndarray, d_mm: np.ndarray, p: float) -> float:
    """Least-squares C of d = C (h^p − h_min^p) for a given order ``p`` over the levels coarser than the finest:
    ``h_mm`` (L,) coarse to fine; ``d_mm`` (L,) differences to the finest (last 0)."""
    g = h_mm[:-1] ** p - h_mm[-1] ** p
    return float(g @ d_mm[:-1] / (g @ g))


def fit_order(h_mm: np.ndarray, d_mm: np.ndarray) -> tuple[float, float, float]:
    """Least-squares fit of d = C (h^p − h_min^p) over p in [0.25, 4] (:func:`fit_fixed` at each p): returns
    (C, p, rms residual mm) of the best p. Arrays as :func:`fit_fixed`."""
    best = (math.nan, math.nan, math.inf)
    for p in np.linspace(0.25, 4.0, 376):
        c = fit_fixed(h_mm, d_mm, p)
        r = float(np.sqrt(np.mean((c * (h_mm[:-1] ** p - h_mm[-1] ** p) - d_mm[:-1]) ** 2)))
        if r < best[2]:
            best = (c, float(p), r)
    return best


def _zones(u_ref, verts, held, q, n, depths, r) -> dict:
    """Per depth, the visible rendered vertices (those :func:`flexsheet.experiments.fem_scene.visible_errors` judges) split
    three ways: ``funnel`` (deformed position < 20 mm from the push axis), ``support_band`` (the rest whose rest
    position lies < 12 mm — one coarse element — from a held rendered vertex) and ``rest``. Dict of lists of
    (S,) bool masks."""
    from scipy.spatial import cKDTree

    from nodes.fem.choose import visible_mask
    from nodes.fem.scene_model import finger_on_scene

    dsup = cKDTree(verts[held]).query(verts)[0]
    out = {"funnel": [], "support_band": [], "rest": []}
    for j, d in enumerate(depths):
        vis = visible_mask(verts + u_ref[j], finger_on_scene(q, n, float(d), r)) & ~held
        x = verts + u_ref[j] - q
        rax = np.linalg.norm(x - (x @ n)[:, None] * n, axis=1)
        out["funnel"].append(vis & (rax < 0.02))
        out["support_band"].append(vis & (rax >= 0.02) & (dsup < 0.012))
        out["rest"].append(vis & (rax >= 0.02) & (dsup >= 0.012))
    return out


def _gent_copy(scene_file: str, jm: float) -> str:
    """A copy of ``scene_file`` (and the surface mesh it names) in a temporary folder with its material made a
    Gent solid of limit ``jm`` (E and ν kept): the path of the copy."""
    import shutil
    import tempfile

    import yaml

    doc = yaml.safe_load(open(scene_file))
    doc["material"] = {**doc["material"], "model": "gent", "Jm": jm}
    d = tempfile.mkdtemp(prefix="mesh_levels_")
    if doc["object"].get("file"):
        shutil.copy(os.path.join(os.path.dirname(scene_file), doc["object"]["file"]), d)
    out = os.path.join(d, os.path.basename(scene_file))
    with open(out, "w") as fh:
        yaml.safe_dump(doc, fh)
    return out


def main() -> int:
    from flexsheet.experiments import path_table as P
    from flexsheet.model.scenes import load_scene
    from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
    from nodes.fem.scene_model import SceneModel

    args = sys.argv[1:]
    jm = None
    if "--gent" in args:                   # the same scene with a Gent solid (E, nu kept) of limit Jm
        k = args.index("--gent")
        jm = float(args[k + 1])
        del args[k:k + 2]
    name = args[0] if args else "organ"
    levels = tuple(float(a) * 1e-3 for a in args[1:]) or DEFAULT_LEVELS
    if len(levels) < 3 or any(b >= a for a, b in zip(levels, levels[1:], strict=False)):
        raise SystemExit(f"levels must be three or more h_fine in mm, coarse to fine, got {args[1:]}")
    here = os.path.join("docs", "figures", "scenes", name)
    scene = os.path.join("launch", "scenes", f"{name}.yaml")
    if jm is not None:
        scene = _gent_copy(scene, jm)
    rep = json.load(open(os.path.join(here, "path_table", "path_table.json")))
    fr = np.asarray([s["fraction"] for s in rep["stations"]])
    f = float(fr[len(fr) // 2])
    t0 = time.perf_counter()
    P._prefetch(scene, [(f, h) for h in levels], DEFAULT_CACHE_DIR, 2)
    sc = load_scene(scene)
    rt = SceneModel(sc)
    cache = ArrayCache(DEFAULT_CACHE_DIR)
    verts = rt.rest_vertices.astype(float)
    depths = np.asarray(rep["depths_m"])
    nd = len(depths)
    q, n = sc.stroke_at([f])
    pushes = [P._push(sc, f, h, verts, cache) for h in levels]
    u = [np.asarray(z["u"])[:nd] for z in pushes]
    zones = _zones(u[-1], verts, rt.held, q[0], n[0], depths, sc.finger.radius)
    by_zone = [{k: [float(np.linalg.norm(ui[j] - u[-1][j], axis=1)[m].max(initial=0.0) * 1e3)
                    for j, m in enumerate(ms)] for k, ms in zones.items()} for ui in u]
    # the zones split the visible vertices, so the largest visible difference is the largest of the zones'
    # (what flexsheet.experiments.fem_scene.visible_errors gives): (L, D) mm, last row 0
    diff = np.array([np.max([z[k] for k in zones], axis=0) for z in by_zone])
    h_mm = np.asarray(levels) * 1e3
    per_depth = []
    for j, d in enumerate(depths):
        c, p, res = fit_order(h_mm, diff[:, j])
        e_fin = c * h_mm[-1] ** p
        h_star = (P.TARGET_MM / c) ** (1.0 / p) if c > 0 else math.inf
        per_depth.append({"depth_mm": float(d * 1e3), "C": c, "p": p, "fit_rms_mm": res,
                          "p_at_bound": bool(p <= 0.25 + 1e-9 or p >= 4.0 - 1e-9),
                          "finest_error_estimate_mm": e_fin, "h_fine_for_target_mm": h_star})
    dofs = np.array([int(z["dofs"]) for z in pushes], float)
    cpu = np.array([float(z["seconds"]) for z in pushes])
    kd, ld = np.polyfit(np.log(h_mm), np.log(dofs), 1)               # dofs = exp(ld) h^kd
    kc, lc = np.polyfit(np.log(dofs), np.log(cpu), 1)                # cpu = exp(lc) dofs^kc

    def at(h_star_mm: float) -> tuple[float, float]:
        """(DOF, CPU seconds per push) the fits give at h_fine ``h_star_mm``; inf past any mesh."""
        if not math.isfinite(h_star_mm):
            return math.inf, math.inf
        dof = math.exp(ld) * h_star_mm ** kd
        return dof, math.exp(lc) * dof ** kc

    deep = per_depth[-1]
    h_star = deep["h_fine_for_target_mm"]
    dof_star, cpu_star = at(h_star)
    bracket = []
    for p in (1.0, 2.0):
        c = fit_fixed(h_mm, diff[:, -1], p)
        hs = (P.TARGET_MM / c) ** (1.0 / p)
        dof, sec = at(hs)
        bracket.append({"p": p, "C": c, "finest_error_estimate_mm": c * h_mm[-1] ** p, "h_fine_for_target_mm": hs,
                        "dofs": dof, "cpu_seconds_per_push": sec})
    out = {"what": "the middle station's push at several reference mesh levels (``levels``), the largest visible-surface "
                   "difference (mm) of each to the finest per depth, and an asymptotic estimate of the finest "
                   "level's own error and of the mesh (and its CPU cost) the 0.7 mm target would need; the "
                   "estimate assumes e(h) = C h^p on the worst vertex (see the script's docstring)",
           "scene": name, "fraction": f, "depths_m": depths.tolist(), "target_mm": P.TARGET_MM,
           "levels": [{"h_fine_m": h, "dofs": int(z["dofs"]), "cpu_seconds": float(z["seconds"]),
                       "newton_converged": bool(np.all(np.asarray(z["converged"])[:nd])),
                       "force_N": np.asarray(z["force"])[:nd].tolist(),
                       "diff_to_finest_mm": diff[i].tolist(), "diff_to_finest_by_zone_mm": by_zone[i]} for i, (h, z) in enumerate(zip(levels, pushes, strict=True))],
           "per_depth": per_depth,
           "cost_fit": {"dofs_vs_h_fine_mm": {"exponent": float(kd), "prefactor": math.exp(ld)},
                        "cpu_seconds_vs_dofs": {"exponent": float(kc), "prefactor": math.exp(lc)}},
           "at_50mm": {"p_at_bound": deep["p_at_bound"], "h_fine_for_target_mm": h_star, "dofs": dof_star, "cpu_seconds_per_push": cpu_star,
                       "finest_error_estimate_mm": deep["finest_error_estimate_mm"], "p": deep["p"]},
           "at_50mm_fixed_order": bracket,
           "wall_seconds": time.perf_counter() - t0}
    out["material"] = sc.material.model_dump() if hasattr(sc.material, "model_dump") else str(sc.material)
    os.makedirs(os.path.join(here, "mesh_levels"), exist_ok=True)
    stem = "mesh_levels" if jm is None else f"mesh_levels_gent{jm:g}"
    with open(os.path.join(here, "mesh_levels", f"{stem}.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    for i, h in enumerate(levels):
        print(f"{name} h_fine {h * 1e3:g} mm: {int(dofs[i])} DOF, {cpu[i]:.0f} s, to the finest at 50 mm "
              f"{diff[i, -1]:.2f} mm", file=sys.stderr)
    print(f"at 50 mm (free fit{', p at its bound: meaningless' if deep['p_at_bound'] else ''}): p {deep['p']:.2f}, finest's own error ~{deep['finest_error_estimate_mm']:.2f} mm, target "
          f"needs h_fine ~{h_star:.2f} mm, ~{dof_star:.0f} DOF, ~{cpu_star / 3600:.1f} h of one core per push",
          file=sys.stderr)
    for b in bracket:
        print(f"  if p = {b['p']:g}: finest's own error ~{b['finest_error_estimate_mm']:.2f} mm, h_fine "
              f"~{b['h_fine_for_target_mm']:.2f} mm, ~{b['dofs']:.0f} DOF, ~{b['cpu_seconds_per_push'] / 3600:.1f} h "
              "of one core per push", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
