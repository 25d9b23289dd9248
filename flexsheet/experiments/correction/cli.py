"""``flexsheet experiment correction``: the paper's Figs. 11 and 13 measured on the honest twin.

The renderer corrects with **calibrated values only** and the twin's measurement camera photographs where that
light lands on the **true** sheet, lit by the **true** projector:

* *Estimator side* (:class:`DisplayEstimator`, built from :class:`CalibratedDisplay` — ``display.yaml`` of the
  registration procedures run in the twin, :func:`flexsheet.twin.registration.sim_display_calib`): the
  bridges' IK/FK at the calibrated arm bases (nominal URDF), the renderer's sheet
  (:class:`flexsheet.rendering.state.RendererState` from those clamp poses and the tracked fingertip), its
  model choice (:class:`flexsheet.rendering.state.ErrorTable`, ``auto``) and its drawing through the
  calibrated projector (K_p, distortion, pose) for the calibrated eye
  (:class:`flexsheet.rendering.stereo_renderer.StereoRenderer`).
* *Twin side* (:class:`TwinWorld`, built from :class:`flexsheet.twin.truth.TwinTruth`): the true clamp poses
  (true forward kinematics of the commanded joints: true bases, link lengths, joint zeros), the true pushed
  shape (the nonlinear membrane FEM of :mod:`flexsheet.model.sheet_fem` with the truth's E, pre-strain and
  tension ratio), the true projector (K, distortion, pose). Only the measurement uses it.
* *Commanded inputs* (known to both): the sheet pose the planner commands (inclined tangent plane at θ, or
  the home pose), the clamp stretch, and the finger's position (the scripted finger of the world, tracked
  perfectly: fingertip tracking error is not part of this experiment).

Sizes (h, u, d on the inclined sheet; h, w on the pushed sheet) are measured on the imaginary screen from the
eye (:mod:`flexsheet.experiments.measurement`) and compared with the proper image (the object's perspective
image on the imaginary screen, paper §VI). ``corrected_mm`` is the mean absolute size error of the model the
renderer picks (``auto``); every model's error is reported beside it.

Stability (``--stability``, "test stability where methods fail"): the pushed error against the size of the
tension-ratio error (true β / assumed β), and both figures' errors against a scaled projector calibration
error; the breaking point is where the corrected error passes one projector pixel (0.7 mm).

Writes DIR/summary.json, DIR/fig11_inclined.png, DIR/fig13_pushed.png, DIR/photos.png and, with
``--stability``, DIR/stability.png + DIR/stability.json.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from flexsheet.experiments.correction.experiment import run
from flexsheet.experiments.correction.seeds import aggregate
from flexsheet.experiments.correction.settings import PIXEL
from flexsheet.experiments.correction.sheet_model import pushed_sheet_model
from flexsheet.experiments.correction.speed import model_speed


def _parser() -> argparse.ArgumentParser:
    """The command line of ``flexsheet experiment correction``."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment correction", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  flexsheet experiment correction --twin realistic --truth-seed 0 --quick --out "
               "/tmp/corr\n  flexsheet experiment correction --twin both --seeds 0 1 2 --stability --speed "
               "--out docs/figures/renderer")
    ap.add_argument("--out", required=True, type=Path, help="output directory")
    ap.add_argument("--twin", choices=("realistic", "ideal", "both"), default="realistic",
                    help="the truth's realism (both: realistic and ideal columns)")
    ap.add_argument("--truth-seed", type=int, default=None, help="hidden truth seed (>= 0; default 0)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="several truth seeds: each run goes to OUT/<realism>-<seed>/, the table to "
                         "OUT/seeds.json")
    ap.add_argument("--display-calib", default=None,
                    help="display.yaml for the estimators (default: run the registration in the twin, cached "
                         "per seed)")
    ap.add_argument("--quick", action="store_true", help="θ = 10, 50°, S = 10, 50 mm, quick registration")
    ap.add_argument("--thetas", type=float, nargs="+", default=None,
                    help="inclinations, deg (default 10..50)")
    ap.add_argument("--depths", type=float, nargs="+", default=None, help="push depths, mm (default 10..50)")
    ap.add_argument("--pixel", type=float, default=0.35, help="measurement camera pixel on the screen, mm")
    ap.add_argument("--sheet-model", choices=("auto", "fem"), default="auto",
                    help="renderer's pushed-sheet model (the gripped FEM depth table; the old series model "
                         "is the comparison column 'fine')")
    ap.add_argument("--stability", action="store_true",
                    help="also sweep tension-ratio, pre-strain and projector errors (first realistic run)")
    ap.add_argument("--speed", action="store_true", help="time a stereo pair per model (OUT/seeds.json)")
    return ap


def _plan(ap: argparse.ArgumentParser, args: argparse.Namespace) -> tuple[list, list, list, tuple, bool]:
    """(seeds, thetas, depths, realisms, single) of the parsed ``args``; ``ap.error`` on an invalid
    combination."""
    seeds = args.seeds if args.seeds is not None else [0 if args.truth_seed is None else args.truth_seed]
    if args.seeds is not None and args.truth_seed is not None:
        ap.error("give --truth-seed or --seeds, not both")
    if any(x < 0 for x in seeds):
        ap.error("truth seeds must be >= 0")
    thetas = args.thetas or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    depths = args.depths or ([10, 50] if args.quick else [10, 20, 30, 40, 50])
    if any(not (0.0 <= t <= 60.0) for t in thetas) or any(not (0.0 < d <= 60.0) for d in depths):
        ap.error("--thetas must lie in [0, 60] deg and --depths in (0, 60] mm")
    realisms = ("realistic", "ideal") if args.twin == "both" else (args.twin,)
    single = len(seeds) == 1 and len(realisms) == 1
    if args.display_calib and not single:
        ap.error("--display-calib names one display: use it with one seed and one twin")
    return seeds, thetas, depths, realisms, single


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``flexsheet experiment correction``; returns the exit code."""
    ap = _parser()
    args = ap.parse_args(argv)
    seeds, thetas, depths, realisms, single = _plan(ap, args)
    t0 = time.perf_counter()
    runs = _run_all(args, seeds, thetas, depths, realisms, single)
    if not single or args.speed:
        speed = model_speed(pushed_sheet_model(args.sheet_model, args.quick)) if args.speed else None
        aggregate(args.out, runs, speed)
        if speed:
            print("stereo pair ms:",
                  {k: (round(v, 2) if isinstance(v, float) else v) for k, v in speed.items()})
    print(f"wrote {args.out} in {time.perf_counter() - t0:.0f} s")
    return 0


def _run_all(args: argparse.Namespace, seeds, thetas, depths, realisms, single: bool) -> dict:
    """Every (realism, seed) run, keyed ``<realism>-<seed>``; with several runs each goes to
    ``OUT/<realism>-<seed>/`` and the headline run's summary and charts to ``OUT``; the stability sweeps run
    with the first realistic run."""
    runs, stab_done = {}, False
    for realism in realisms:
        for seed in seeds:
            out = args.out if single else args.out / f"{realism}-{seed}"
            stab = args.stability and realism == "realistic" and not stab_done
            head = single or (realism == realisms[0] and seed == seeds[0])
            s = run(out, seed, realism, thetas=thetas, depths=depths, display_calib=args.display_calib,
                    quick=args.quick, pixel=args.pixel * 1e-3, sheet_model=args.sheet_model, stability=stab,
                    charts=head or stab)
            stab_done |= stab
            if head and not single:                            # the headline run's charts go to OUT's top
                (args.out / "summary.json").write_bytes((out / "summary.json").read_bytes())
                names = ["fig11_inclined.png", "fig13_pushed.png", "photos.png"]
                for name in names + (["stability.json", "stability.png"] if stab else []):
                    (out / name).replace(args.out / name)
            runs[f"{realism}-{seed}"] = s
            h = s["headline"]
            print(f"{realism} seed {seed}: inclined max corrected {h['inclined_max_corrected_mm']:.2f} mm, "
                  f"pushed max corrected {h['pushed_max_corrected_mm']:.2f} mm (target {PIXEL * 1e3:.1f} "
                  f"mm); models {s['models_picked']}")
    return runs


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
