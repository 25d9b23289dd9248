"""The stability figure (``stability.png``): the pushed error against the true tension ratio and pre-strain,
and both figures' errors against the projector's screen → pixel mapping error."""

from __future__ import annotations

from pathlib import Path


def _fmt(x, unit: str = "", nd: int = 2) -> str:
    return "not within the sweep" if x is None else f"{x:.{nd}f}{unit}"


def stability_chart(path: Path, stab: dict) -> None:
    """Draw ``stability.png`` (module doc) at ``path`` from the stability sweeps ``stab``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, NullLocator, ScalarFormatter

    floor = 0.01
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.6))
    for a, key, xlabel in ((ax[0], "tension_ratio", "true tension ratio T_v/T_u (estimator assumes 1)"),
                           (ax[1], "prestrain", "true pre-strain (estimator assumes 0)")):
        t = stab[key]
        xs = [r["value"] for r in t["rows"]]
        for k in [k for k in t["rows"][0] if k.endswith("_mm") and k != "corrected_mm"]:
            a.plot(xs, [max(r[k], floor) for r in t["rows"]], "-o", label=k[:-3])
        a.plot(xs, [max(r["corrected_mm"], floor) for r in t["rows"]], "k-", lw=4, alpha=0.25,
               label="picked by the renderer")
        a.axhline(0.7, color="grey", lw=0.8, ls="--", label="1 projector pixel (0.7 mm)")
        b = t["corrected_breaks_at"]
        if key == "tension_ratio":
            a.set_xscale("log")
            a.xaxis.set_major_locator(FixedLocator([x for x in xs if x in (0.3, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0)]
                                                   or xs))
            a.xaxis.set_minor_locator(NullLocator())
            a.xaxis.set_major_formatter(ScalarFormatter())
            title = (f"wrong tension ratio: picked model > 0.7 mm below β = {_fmt(b['below'])}, above β = "
                     f"{_fmt(b['above'])}")
        else:
            title = f"wrong pre-strain: picked model > 0.7 mm above {_fmt(b['above'])}"
        a.set_title(title, fontsize=8)
        a.set_xlabel(xlabel, fontsize=8)
        a.set_ylabel(f"pushed S = {t['depth_mm']:g} mm: mean size error [mm]", fontsize=8)
        a.set_yscale("log")
        a.set_ylim(floor, 30)
        a.legend(fontsize=7)
    p = stab["projector"]
    for name, mk in (("calibrated", "o"), ("random", "^")):
        rows = sorted(p[name], key=lambda r: r["mapping_px"])
        xs = [max(r["mapping_px"], 1e-3) for r in rows]
        ax[2].plot(xs, [max(r["inclined_corrected_mm"], floor) for r in rows], "-" + mk,
                   label=f"inclined θ={p['theta_deg']:g}°, {name} error")
        ax[2].plot(xs, [max(r["pushed_corrected_mm"], floor) for r in rows], "--" + mk, mfc="none",
                   label=f"pushed S={p['depth_mm']:g} mm, {name} error")
    reg = [r for r in p["calibrated"] if r["scale"] == 1.0]
    if reg:
        ax[2].axvline(max(reg[0]["mapping_px"], 1e-3), color="green", lw=0.8, ls=":", label="as registered")
    ax[2].axhline(0.7, color="grey", lw=0.8, ls="--", label="1 projector pixel (0.7 mm)")
    ax[2].set_xscale("log")
    ax[2].set_yscale("log")
    ax[2].set_ylim(floor, 30)
    ax[2].set_xlabel("projector screen→pixel mapping error, RMS [projector px] (0.001 = exact)", fontsize=8)
    ax[2].set_ylabel("mean size error [mm]", fontsize=8)
    ax[2].set_title("projector error: inclined > 0.7 mm from "
                    f"{_fmt(p['calibrated_inclined_breaks_at_px'], ' px')}\n(registration error scaled), "
                    f"{_fmt(p['random_inclined_breaks_at_px'], ' px')} (random directions)",
                    fontsize=8)
    ax[2].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
