"""The experiment's figures: ``convergence.png``, ``mirror_study.png``, ``accuracy_speed.png`` and
``failure_map.png``, each study's figure, ``node_table.png`` and the linear study's figures."""

from __future__ import annotations

import os

import numpy as np

from flexsheet.fem.reference.settings import TARGET


def plot_convergence(out: str, conv: dict, law: str = "neo-Hookean") -> None:
    """convergence.png: visible-surface difference to the finest mesh against depth, and against h at 3
    depths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.array(conv["depths_m"]) * 1e3
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for lv in conv["levels"][:-1]:
        a1.plot(d, lv["error_vs_finest_mm"], "o-", ms=3, label=f"h_fine {lv['h_fine_m'] * 1e3:.1f} mm "
                                                               f"({lv['dofs']} DOF)")
    a1.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm")
    a1.set_xlabel("push depth (mm)")
    a1.set_ylabel("max visible-surface difference to finest (mm)")
    a1.legend(fontsize=8)
    h = np.array([lv["h_fine_m"] for lv in conv["levels"][:-1]]) * 1e3
    for dd in (10.0, 30.0, 50.0):
        j = int(np.argmin(np.abs(d - dd)))
        a2.loglog(h, [lv["error_vs_finest_mm"][j] for lv in conv["levels"][:-1]], "o-",
                  label=f"{d[j]:.0f} mm push")
    a2.set_xlabel("element size under the finger, h_fine (mm)")
    a2.set_ylabel("difference to finest (mm)")
    a2.legend(fontsize=8)
    fig.suptitle(f"{law} reference, mesh convergence (finest h_fine = "
                 f"{conv['levels'][-1]['h_fine_m'] * 1e3:.1f} mm): converged = "
                 f"{conv['converged']}", fontsize=10)
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
        a2.plot(dm, row["diff_vs_finest_quarter_mm"], "o-", ms=3, color=c,
                label=f"{lab}: from finest quarter")
        a2.plot(dm, row["asymmetry_mm"], "s--", ms=3, color=c, label=f"h_fine {row['h_fine_m'] * 1e3:.1f} "
                "mm: own asymmetry")
    a1.set_xlabel("push depth (mm)")
    a1.set_ylabel("finger force (N)")
    a1.legend(fontsize=7)
    a2.axhline(TARGET * 1e3, color="k", ls=":", lw=0.8, label="target 0.7 mm")
    a2.set_xlabel("push depth (mm)")
    a2.set_ylabel("max visible-surface distance (mm)")
    a2.legend(fontsize=7)
    for row in ms.get("stability", []):
        a3.plot(np.array(row["depths_m"]) * 1e3, row["anti_over_sym"], "o-", ms=3,
                color=col.get(round(row["h_fine_m"], 9)), label=f"quarter, h_fine {row['h_fine_m'] * 1e3:.1f}"
                                                                " mm")
    a3.axhline(0.0, color="k", lw=0.8)
    a3.set_xlabel("push depth (mm)")
    a3.set_ylabel("lowest antisymmetric / symmetric\ntangent eigenvalue (< 0: unstable)")
    a3.legend(fontsize=7)
    fig.suptitle("azimuth-0 push: quarter models (z mirror plane) against cut half models (nodes on that "
                 "plane, no BC), and the symmetric solution's stability against asymmetric "
                 "modes", fontsize=10)
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


def plot_fold_study(out: str, fs: dict) -> None:
    """fold_study.png: per level, the largest winding number (off the footprint, and with it) and the smallest
    surface stretch against depth, beside the visible-surface difference to the finest level
    (:func:`fold_study`, the numbers in ``fold_study.json``)."""
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
        ax[1].plot(d, r["min_stretch_ratio"], "o-", color=col, ms=3, label=lab)
        if "difference_to_finest_mm" in r:
            ax[2].plot(d, r["difference_to_finest_mm"], "o-", color=col, ms=3, label=f"{lab} vs finest")
    ax[0].axhline(0.5, color="k", lw=0.6, ls=":")
    ax[0].axhline(1.0, color="r", lw=0.8, ls="--", label="w = 1: surface inside the body")
    ax[0].set_ylabel("largest winding number w of the surface")
    ax[1].axhline(fs["crease_stretch_ratio"], color="r", lw=0.8, ls="--", label="neo-Hookean crease onset")
    ax[1].set_ylabel("smallest in-plane surface stretch off the footprint")
    ax[2].axhline(0.35, color="k", lw=0.8, ls="--", label="half the 0.7 mm target")
    ax[2].set_ylabel("visible-surface difference to the finest (mm)")
    tip = fs["tip_sequence"]
    for k, r in enumerate(tip["levels"][:-1]):
        ax[3].plot(d, r["difference_to_finest_mm"], "o-", color=f"C{k + 3}", ms=3,
                   label=f"tube {r['h_fine_mm']:g} mm + tip {r['tip_h_mm']:g} mm ({r['dofs']} DOF) vs finest")
    fin = tip["levels"][-1]
    ax[3].plot(d, fin["difference_to_finest_plain_level_mm"], "s--", color="k", ms=3, lw=0.8,
               label=f"finest (tube {fin['h_fine_mm']:g} + tip {fin['tip_h_mm']:g} mm) vs the finest plain "
                     "level")
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


def plot_material_study(out: str, ms: dict) -> None:
    """material_study.png: per material, each level's visible-surface difference to its finest level (left)
    and the azimuth-0 snapshot table's error (right), against depth."""
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


def plot_holdout_study(out: str, hs: dict) -> None:
    """holdout_study.png: worst visible error against depth per azimuth (:func:`holdout_study`, the numbers in
    ``holdout_study.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in hs["azimuths"]:
        ax.semilogy(r["depths_mm"], r["error_mm"], "o-" if r["held_out"] else "s--", ms=3,
                    label=f"azimuth {r['azimuth_deg']:g}° ({'held out' if r['held_out'] else 'on the grid'}"
                          f"), against {r['against']}")
    ax.axhline(hs["target_mm"], color="k", ls="--", lw=0.8, label="target 0.7 mm (1 projector px)")
    ax.set_xlabel("push depth (mm)")
    ax.set_ylabel("worst visible-surface error (mm)")
    ax.set_title(f"Nonlinear snapshots at azimuths {hs['snapshot_azimuths_deg']} deg, every "
                 f"{hs['snapshot_depth_step_mm']:g} mm", fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "holdout_study.png"), dpi=110)
    plt.close(fig)


def plot_node_table(out: str, rep: dict) -> None:
    """node_table.png: finger force against depth per azimuth, and the apex check (:func:`node_table_report`),
    with the held-out azimuths' and the between-depths checks' errors."""
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
        b.plot(h["depths_mm"], h["shape_px"], ".-", color=("k", "0.45", "0.7")[i % 3], ms=4, lw=1.5,
               label=f"held out {h['azimuth_deg']:g}°: visible shape error (px)")
        if h.get("twin"):
            b.plot(h["depths_mm"], h["twin"]["noise_px"], "v:", color=("k", "0.45", "0.7")[i % 3], ms=3,
                   lw=1.2,
                   label=f"{h['azimuth_deg']:g}°: the mesh's noise (twin mesh, px)")
    for h in rep.get("between_depths", []):
        b.plot(h["depths_mm"], h["shape_px"], "rx-", ms=4, lw=1,
               label=f"{h['azimuth_deg']:g}°, every {h['depths_mm'][0]:g} mm: visible shape error (px)")
    if rep.get("held_out") or rep.get("between_depths"):
        b.axhline(1.0, color="k", ls="--", lw=0.8, label="target 1 px")
    b.set_xlabel("push depth (mm)")
    b.set_ylabel("apex: mm; errors: projector px")
    b.set_title("apex displacement − depth per azimuth; held-out shape error", fontsize=10)
    b.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "node_table.png"), dpi=110)
    plt.close(fig)


def plot_linear_study(out: str, rows: list, hz: dict, stab: dict) -> None:
    """linear_accuracy_speed.png, hertz.png and stability.png of
    :func:`flexsheet.experiments.fem.studies.linear.linear_study`."""
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
