"""The charts of ``flexsheet experiment triangulation`` (:mod:`flexsheet.experiments.triangulation`): accuracy
against speed, the stability sweeps, the honest (registered, rendered) errors and the noise sweep; matplotlib
Agg PNGs, mm in labels."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from flexsheet.vision.stereo import METHODS  # noqa: E402

__all__ = ["plot_honest", "plot_noise", "plot_accuracy", "plot_stability"]


def plot_honest(h: dict, st: dict | None, path: str, target_mm: float) -> None:
    """The honest errors (registered camera, rendered views) per seed and their stability sweeps ``st``,
    against ``target_mm`` (mm), to ``path`` (PNG)."""
    fig, ax = plt.subplots(2, 3, figsize=(16, 9))
    seeds = h["seeds"]
    keys = [k for k in h["headline_rms_mm"]["realistic"] if k != "static_perfect_registration"]
    w = 0.8 / (len(keys) + 1)
    x = np.arange(len(seeds))
    for i, k in enumerate(keys):
        ax[0, 0].bar(x + i * w, h["headline_rms_mm"]["realistic"][k], w, label=f"realistic {k}")
    ax[0, 0].bar(x + len(keys) * w, h["headline_rms_mm"]["ideal"]["static"], w, color="0.7",
                 label="ideal static")
    ax[0, 0].plot(x + 0 * w, h["headline_rms_mm"]["realistic"]["static_perfect_registration"], "k_", ms=18,
                  mew=2,
                  label="static, perfect registration (diagnostic)")
    ax[0, 0].axhline(target_mm, color="r", ls="--", lw=1, label=f"target {target_mm} mm")
    ax[0, 0].set_xticks(x + 0.4 - w / 2, [f"truth seed {s}" for s in seeds])
    ax[0, 0].set_ylabel("fingertip RMS error vs truth, mm")
    ax[0, 0].set_title("honest twin: registered camera, images → detector")
    ax[0, 0].legend(fontsize=7)
    if st:
        def panel(a, sw, xlabel, title, logx=False, logy=False, x2=None):
            a.plot(sw["values"], sw["rms_mm"], "o-", label="RMS error, mm")
            a.axhline(target_mm, color="r", ls="--", lw=1)
            b = a.twinx()
            b.plot(sw["values"], sw["valid_rate"], "s:", color="tab:green", label="valid rate")
            b.plot(sw["values"], sw["wrong_rate"], "x:", color="tab:red", label="wrong rate (> 5 mm off)")
            b.legend(fontsize=7, loc="upper right")
            b.set_ylim(0, 1.05)
            b.set_ylabel("valid rate")
            if x2 is not None:
                a.plot(x2["values"], x2["rms_mm"], "^--", color="tab:orange",
                       label="not registered (nominal)")
            bp = sw["breaking"]["first_failing"]
            if bp is not None:
                a.axvline(bp, color="0.5", lw=0.8)
            a.set_xlabel(xlabel)
            a.set_ylabel("RMS error, mm")
            fl = sw["breaking"]["failing"]
            a.set_title(f"{title}\nfails at {fl if len(fl) < 5 else f'{fl[0]}…{fl[-1]}'}" if fl
                        else f"{title}\n"
                        "no failure in the sweep")
            if logx:
                a.set_xscale("log")
                a.set_xticks(sw["values"], [f"{v:g}" for v in sw["values"]])
                a.minorticks_off()
            if logy:
                a.set_yscale("log")
            a.legend(fontsize=7, loc="upper left")
            return b
        panel(ax[0, 1], st["noise_scale"], "camera noise × measured σ (read 2.5 DN, shot 0.31 DN/DN)",
              "camera noise", logx=True, logy=True)
        panel(ax[0, 2], st["calibration_scale"], "truth camera spreads × (stereo bootstrap σ, mount 10 mm / "
                                                 "1°)",
              "calibration error (registered again)", logx=True, logy=True,
              x2=st["calibration_scale_unregistered"])
        b = panel(ax[1, 0], st["finger_azimuth_deg"], "finger azimuth about +z, deg (elevation 40°; camera "
                                                      "at −36°)",
                  "self-occlusion by the finger", logy=True)
        vis = [float(np.mean([d.get("visibility", np.nan) for d in det]))
               for det in st["finger_azimuth_deg"]["detail"]]
        b.plot(st["finger_azimuth_deg"]["values"], vis, "d-.", color="tab:purple",
               label="marker visible fraction")
        b.legend(fontsize=7, loc="center right")
        panel(ax[1, 1], st["background_gain"], "background brightness × (sheet up to ~190 DN at 1)",
              "marker contrast", logy=True)
    ps = h["realistic"]["per_seed"]
    txt = ["registration (camera entry) vs truth:"]
    for s in seeds:
        r = ps[str(s)]["registration"]
        txt.append(f"  seed {s}: {r['translation_error_mm']:.2f} mm, {r['rotation_error_deg']:.3f} deg; "
                   f"static bias {np.linalg.norm(ps[str(s)]['static']['bias_mm']):.2f} mm")
    ax[1, 2].axis("off")
    ax[1, 2].text(0.0, 1.0, "\n".join(txt), va="top", family="monospace", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_noise(sn: dict, path: str) -> None:
    """The fingertip error against the sensor noise ``sn`` to ``path`` (PNG)."""
    B = np.array(sn["bins"])
    lv = np.linspace(0, 240, 100)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.scatter(B[:, 0], B[:, 1], s=12 + 40 * B[:, 2] / B[:, 2].max(),
               label="flat patches, binned (area ∝ count)")
    ax.plot(lv, np.sqrt(sn["read_dn"] ** 2 + sn["shot_gain"] * lv), "k-",
            label=f"this fit: read {sn['read_dn']:.2f} DN, gain {sn['shot_gain']:.3f}")
    rf = sn["registration_fit"]
    ax.plot(lv, np.sqrt(rf["read_dn"] ** 2 + rf["shot_gain"] * lv), "r--",
            label=f"twin (registration's board fit): read {rf['read_dn']} DN, gain {rf['shot_gain']}")
    ax.set_xlabel("level, DN")
    ax.set_ylabel("noise σ, DN")
    ax.set_title(f"real XIMEA images ({sn['images']}): noise vs level; corner jitter "
                 f"{sn['corner_jitter_px']:.3f} px")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_accuracy(acc: dict, path: str, sigmas: tuple[float, ...]) -> None:
    """Accuracy (mm) against time per pair (µs) of each triangulation method at the pixel noises ``sigmas``
    (px), to ``path`` (PNG)."""
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8))
    marks = {"dlt": "o", "optimal": "s", "midpoint": "^"}
    zi = acc["depths"].index(0.5)
    for meth in METHODS:
        t = acc["time_us"][meth]
        for s in sigmas:
            ax[0].scatter(t, acc["rms_mm"][meth][f"{s}"][zi], marker=marks[meth], s=40,
                          c=[plt.cm.viridis(sigmas.index(s) / (len(sigmas) - 1))],
                          label=f"{meth}" if s == sigmas[0] else None, edgecolors="k")
    for s in sigmas:
        ax[0].axhline(acc["floor_mm"][f"{s}"][zi], color=plt.cm.viridis(sigmas.index(s) / (len(sigmas) - 1)),
                      ls=":",
                      lw=1)
        ax[0].text(ax[0].get_xlim()[1] if False else 0.5, acc["floor_mm"][f"{s}"][zi], f" floor σ={s} px",
                   fontsize=7, va="bottom", transform=ax[0].get_yaxis_transform())
    ax[0].set_yscale("log")
    ax[0].set_xlabel("time per stereo pair, µs (triangulation + covariance)")
    ax[0].set_ylabel("RMS 3-D error at 0.5 m, mm")
    ax[0].set_title("accuracy vs speed (colour: σ; dotted: floor Z²√2σ/fB)")
    ax[0].legend()
    for meth in METHODS:
        ax[1].plot(acc["depths"], acc["rms_mm"][meth]["0.1"], marker=marks[meth], label=meth)
    ax[1].plot(acc["depths"], acc["floor_mm"]["0.1"], "k:", label="depth floor")
    ax[1].axhline(0.3, color="r", lw=0.8, ls="--", label="target 0.3 mm")
    ax[1].set_xlabel("depth Z, m")
    ax[1].set_ylabel("RMS 3-D error, mm (σ = 0.1 px)")
    ax[1].set_yscale("log")
    ax[1].set_title("BumbleBee2 1024×768 reference (f 817 px, B 0.12 m)")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_stability(st: dict, path: str) -> None:
    """Each stability case of :func:`flexsheet.experiments.triangulation.stability` to ``path`` (PNG)."""
    fig, ax = plt.subplots(2, 3, figsize=(15, 8.5))
    f = st["fov"]
    im = ax[0, 0].imshow(np.array(f["error_mm"], float), origin="upper", aspect="auto", cmap="magma",
                         extent=[f["u_px"][0], f["u_px"][-1], f["v_px"][-1], f["v_px"][0]], vmin=0, vmax=1.0)
    fig.colorbar(im, ax=ax[0, 0], label="error, mm (white = invalid)")
    ax[0, 0].set_title(f"field of view at 0.5 m (XIMEA twin): valid {f['valid_fraction'] * 100:.0f} %")
    ax[0, 0].set_xlabel("u, px")
    ax[0, 0].set_ylabel("v, px")
    d = st["degenerate"]
    for meth in METHODS:
        ax[0, 1].plot(d["angle_deg"], d["rms_mm"][meth], marker="o", label=meth)
    ax[0, 1].set_yscale("log")
    ax[0, 1].set_xscale("log")
    ax[0, 1].set_xlabel("angle between the marker direction and the baseline, deg (0.5 m range, σ 0.1 px/f "
                        "rad)")
    ax[0, 1].set_ylabel("RMS error, mm")
    ax[0, 1].set_title("near-degenerate rays: toward the baseline")
    ax[0, 1].legend()
    for meth in METHODS:
        ax[0, 2].plot(d["depth_m"], d["depth_rms_mm"][meth], marker="o", label=meth)
    ax[0, 2].set_xlabel("depth, m (σ 0.1 px)")
    ax[0, 2].set_ylabel("RMS error, mm")
    ax[0, 2].set_yscale("log")
    ax[0, 2].set_title("near-degenerate rays: far marker")
    ax[0, 2].legend()
    o = st["occlusion"]
    ax[1, 0].plot(o["fraction"], o["error_mm"], "o-")
    for x, r in zip(o["fraction"], o["reason"], strict=False):
        if r != "ok":
            ax[1, 0].axvspan(x - 0.05, x + 0.05, color="0.85")
    ax[1, 0].set_xlabel("fraction of the marker hidden in the left image")
    ax[1, 0].set_ylabel("error, mm (grey: invalid)")
    ax[1, 0].set_title("partial occlusion")
    r = st["reflection"]
    code = {"correct": 2, "invalid": 1, "wrong": 0}
    for mode, mk in (("no_track", "o"), ("track", "s")):
        ax[1, 1].plot(np.array(r["distance_m"]) * 1e3, [code[e["outcome"]] for e in r[mode]], mk + "-",
                      label=mode)
    ax[1, 1].set_yticks([0, 1, 2], ["wrong", "invalid", "correct"])
    ax[1, 1].set_xscale("log")
    ax[1, 1].set_xticks([x * 1e3 for x in r["distance_m"]], [f"{x * 1e3:g}" for x in r["distance_m"]])
    ax[1, 1].minorticks_off()
    ax[1, 1].set_xlabel("distance of the second bright blob, mm")
    ax[1, 1].set_title("reflection (equal-brightness second dot)")
    ax[1, 1].legend()
    b = st["motion_blur"]
    ax[1, 2].plot(b["speed_mps"], b["rms_error_mm"], "o-", label="RMS error, mm")
    ax[1, 2].plot(b["speed_mps"], b["valid_rate"], "s--", label="valid rate")
    ax2 = ax[1, 2].twiny()
    ax2.set_xlim(ax[1, 2].get_xlim())
    ax2.set_xticks(b["speed_mps"][::2], [f"{s:.0f}" for s in b["streak_px"][::2]])
    ax2.set_xlabel("streak length, px")
    ax[1, 2].set_xlabel("finger speed, m/s (4 ms exposure)")
    ax[1, 2].set_title("motion blur")
    ax[1, 2].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
