"""One run of the experiment for one truth (:func:`run`): the twin and the estimators set up, Fig. 11's and
Fig. 13's sweeps, the live path, the headline numbers, optionally the stability sweeps, and
``summary.json`` with the figures."""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from flexsheet.experiments.correction.calibrated_display import CalibratedDisplay, display_calib_for
from flexsheet.experiments.correction.estimator import DisplayEstimator
from flexsheet.experiments.correction.live_path import live_path
from flexsheet.experiments.correction.measurer import Measurer
from flexsheet.experiments.correction.plots import run_charts
from flexsheet.experiments.correction.projector_errors import sweep_projector
from flexsheet.experiments.correction.settings import ASSUMPTIONS, PAPER, PIXEL, STRETCH
from flexsheet.experiments.correction.sheet_model import pushed_sheet_model, sheet_model_info
from flexsheet.experiments.correction.stability import sweep_sheet
from flexsheet.experiments.correction.stability_plots import stability_chart
from flexsheet.experiments.correction.sweeps import sweep_inclined, sweep_pushed
from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)


def run(out: Path, truth_seed: int = 0, realism: str = "realistic", *, thetas=(10, 20, 30, 40, 50),
        depths=(10, 20, 30, 40, 50), display_calib: str | None = None, quick: bool = False,
        pixel: float = 0.00035, sheet_model: str = "auto", stability: bool = False,
        charts: bool = True) -> dict:
    """Run the experiment for one truth and write ``out/summary.json`` (+ charts); returns the summary."""
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    truth = TwinTruth.draw(int(truth_seed), realism)
    cal, cal_info = display_calib_for(truth_seed, realism, display_calib, quick)
    model_obj = pushed_sheet_model(sheet_model, quick=quick, strain_offset=cal.strain_offset)
    est = DisplayEstimator(cal, sheet_model=model_obj)
    world = TwinWorld(truth)
    meas = Measurer(pixel)
    photos: dict = {}
    s = _header(realism, truth_seed, truth, cal, cal_info, model_obj, meas, quick, pixel)
    tag = f"[correction] seed {truth_seed} {realism}"
    s["inclined"] = sweep_inclined(est, world, meas, thetas, photos, tag)
    s["pushed"] = sweep_pushed(est, world, meas, depths, photos, tag)
    s["live_path"] = {"note": "the renderer node's code path (RendererState, ErrorTable, auto) on the true "
                              "FEM sheet, ray-traced, same eye/projector both sides; max/mean over the "
                              "silhouette, mm",
                      "rows": live_path(truth, (0, 10, 30, 50), strain_offset=cal.strain_offset)}
    s["models_picked"] = {"inclined": sorted({r["model"] for r in s["inclined"].values()}),
                          "pushed": sorted({r["model"] for r in s["pushed"].values()})}
    s["choice_table_m"] = est.table.rows
    s["headline"] = _headline(s, thetas, depths)
    if stability:
        s["stability"] = _stability(out, est, cal, truth, meas, model_obj, quick, charts)
    est.release()
    s["elapsed_s"] = time.perf_counter() - t0
    (out / "summary.json").write_text(json.dumps(s, indent=1))
    if charts:
        run_charts(out, s, thetas, depths, photos)
    return s


def _header(realism: str, truth_seed: int, truth: TwinTruth, cal: CalibratedDisplay, cal_info: dict,
            model_obj,
            meas: Measurer, quick: bool, pixel: float) -> dict:
    """The summary's first keys: the truth's sheet, the estimator's sources, the target and the settings."""
    return {"twin": {"realism": realism, "truth_seed": int(truth_seed),
                     "truth_sheet": {"young_Pa": truth.sheet_young, "prestrain": truth.sheet_prestrain,
                                     "thickness_m": truth.sheet_thickness, "grip_slip": truth.grip_slip}},
            "estimator": {"source": cal.source, **cal_info, "sheet_model": sheet_model_info(model_obj)},
            "target_mm": PIXEL * 1e3, "proper_mm": meas.proper, "paper": PAPER, "assumptions": ASSUMPTIONS,
            "stretch": STRETCH, "quick": bool(quick), "measurement_pixel_mm": pixel * 1e3}


def _headline(s: dict, thetas, depths) -> dict:
    """The largest corrected errors of both figures, those at the largest θ and S, and whether they meet the
    one-pixel target."""
    tmax, dmax = f"{max(thetas):g}", f"{max(depths):g}"
    h = {"inclined_max_corrected_mm": max(r["corrected_mm"] for r in s["inclined"].values()),
         "pushed_max_corrected_mm": max(r["corrected_mm"] for r in s["pushed"].values()),
         f"inclined_{tmax}_corrected_mm": s["inclined"][tmax]["corrected_mm"],
         f"pushed_{dmax}_corrected_mm": s["pushed"][dmax]["corrected_mm"]}
    h["meets_target"] = {"inclined": h["inclined_max_corrected_mm"] <= PIXEL * 1e3,
                         "pushed": h["pushed_max_corrected_mm"] <= PIXEL * 1e3}
    return h


def _stability(out: Path, est: DisplayEstimator, cal: CalibratedDisplay, truth: TwinTruth, meas: Measurer,
               model_obj, quick: bool, charts: bool) -> dict:
    """The stability sweeps (tension ratio, pre-strain, projector), written to ``out/stability.json`` (+
    chart)."""
    stab = {
        "tension_ratio": sweep_sheet(est, truth, meas, "tension_ratio", quick=quick),
        "prestrain": sweep_sheet(est, truth, meas, "prestrain", quick=quick),
        "projector": sweep_projector(cal, truth, meas, sheet_model=model_obj, quick=quick)}
    (out / "stability.json").write_text(json.dumps(stab, indent=1))
    if charts:
        stability_chart(out / "stability.png", stab)
    return stab
