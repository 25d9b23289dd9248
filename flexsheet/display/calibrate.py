"""``flexsheet calibrate camera-pose | projector | arms | eye | display | noise`` (argparse mains).

Each procedure command reads its frames from the twin (``--sim --truth-seed N``) or from a folder of captured
lab images (``--images DIR``, layout in :mod:`flexsheet.calibration.sources`), and writes/updates its entry in
``DIR/display.yaml`` (``--out DIR``; the other entries are kept). ``display --sim`` runs them all in lab order
and writes ``summary.json`` with each estimate's error against the twin's hidden truth; ``--sweep`` charts the
errors against the number of poses (Agg PNG + JSON). See docs/calibration.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
from dataclasses import replace

from flexsheet.calibration import procedures as P
from flexsheet.calibration.display_calib import DisplayCalib
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.calibration.eye import fixed_eye, tracked_eye_entry
from flexsheet.calibration.sheet import TERMS, plan_presses
from flexsheet.calibration.sources import ImageDirSource, PressFileSource
from flexsheet.display.live import LiveError, check_plan, register_live
from flexsheet.runtime.launch import LaunchError
from flexsheet.runtime.launch_sets import apply_toplevel_sets
from flexsheet.twin.registration import TwinSource, run_display_sim, score_sheet, verdicts
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.registration_draws import draw_seeds, run_draws
from flexsheet.twin.registration_sweep import run_sweep
from flexsheet.twin.sensor_noise import measure_ximea_noise
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

__all__ = ["camera_pose_main", "projector_main", "arms_main", "eye_main", "display_main", "noise_main"]


def _common(p: argparse.ArgumentParser, what: str) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", action="store_true", help="frames from the twin (needs --truth-seed)")
    src.add_argument("--images", metavar="DIR", help="captured lab frames (layout: docs/calibration.md)")
    _twin_and_out(p)
    p.add_argument("--quick", action="store_true", help="fewer poses (4 projector poses, 12 configurations "
                                                        "per arm): faster, but the projector target can be "
                                                        "missed")


def _twin_and_out(p: argparse.ArgumentParser) -> None:
    """``--truth-seed``, ``--realism`` (with ``--sim``) and ``--out`` (the folder of display.yaml)."""
    p.add_argument("--truth-seed", type=int, default=None, help="twin truth seed (with --sim)")
    p.add_argument("--realism", choices=("realistic", "ideal"), default="realistic", help="twin realism")
    p.add_argument("--out", required=True, metavar="DIR", help="folder of display.yaml (entry "
                                                               "added/replaced)")


def _opts(a) -> P.Options:
    o = P.QUICK if getattr(a, "quick", False) else P.FULL
    kw = {}
    for k in ("board", "square", "board_offset", "views", "board_frames", "projector_poses",
              "pattern_spacing",
              "arm_configs", "prior"):
        v = getattr(a, k, None)
        if v is not None:
            kw[k] = v
    return replace(o, **kw)


def _source(a, p: argparse.ArgumentParser, opts: P.Options):
    if a.sim:
        if a.truth_seed is None:
            p.error("--sim needs --truth-seed N")
        truth = TwinTruth.draw(a.truth_seed, a.realism)
        return TwinSource(CalibrationTwin(truth, seed=a.truth_seed), opts.board_frames, opts.pattern_frames,
                          opts.marker_frames), truth
    return ImageDirSource(a.images), None


def _load_out(out: str) -> DisplayCalib:
    path = os.path.join(out, "display.yaml")
    return load_display_calib(path) if os.path.isfile(path) else DisplayCalib(path=path)


def _write(out: str, calib: DisplayCalib) -> str:
    path = os.path.join(out, "display.yaml")
    write_display_calib(path, calib)
    return path


def _run(p: argparse.ArgumentParser, fn):
    try:
        return fn()
    except ValueError as e:
        print(f"{p.prog}: error: {e}", file=sys.stderr)
        return 2


def camera_pose_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate camera-pose``: the stereo camera's pose from a board on the sheet."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate camera-pose", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Stereo camera pose in the display frame from a board on the sheet at home (+ tilted "
                    "views).",
        epilog="example:\n  flexsheet calibrate camera-pose --sim --truth-seed 1 --quick --out /tmp/disp\n"
               "  flexsheet calibrate camera-pose --images lab/frames --out lab/")
    _common(p, "camera")
    p.add_argument("--board", default=None, help="chessboard:COLSxROWS or charuco:NXxNY:SQ:MK:DICT (default "
                                                 "9x8)")
    p.add_argument("--square", type=float, default=None, help="square side, m (default 0.022)")
    p.add_argument("--board-offset", type=float, default=None, help="printed face above the sheet mid-plane, "
                                                                    "m")
    p.add_argument("--views", type=int, default=None, help="board views incl. home (twin; default 21, quick "
                                                           "12)")
    p.add_argument("--prior", default=None, help="stereo bootstrap JSON for the prior, or 'none'")
    a = p.parse_args(argv)

    def go():
        opts = _opts(a)
        src, truth = _source(a, p, opts)
        calib = _load_out(a.out)
        entry, r = P.run_camera_pose(src, opts)
        calib.camera = entry
        path = _write(a.out, calib)
        msg = (f"camera pose: {r.n_views} views, RMS {r.rms_px:.3f} px, home corners residual "
               f"{r.residual_mm:.3f} mm (flatness {r.flatness_mm:.3f} mm)")
        if truth is not None:
            et, er = truth.camera_pose_error(entry.T_display_camera)
            msg += f"; error vs truth {et * 1e3:.3f} mm, {math.degrees(er):.4f} deg"
        log.info(msg)
        log.info(f"wrote {path}")
        return 0

    return _run(p, go)


def projector_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate projector``: K_p, distortion and pose by structured light."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate projector", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Projector intrinsics and pose from Gray-code patterns on the sheet at >= 3 poses "
                    "(needs the camera entry in OUT/display.yaml).",
        epilog="example:\n  flexsheet calibrate camera-pose --sim --truth-seed 1 --quick --out /tmp/disp\n"
               "  flexsheet calibrate projector --sim --truth-seed 1 --quick --out /tmp/disp")
    _common(p, "projector")
    p.add_argument("--poses", dest="projector_poses", type=int, default=None,
                   help="sheet poses (twin; default 6)")
    p.add_argument("--spacing", dest="pattern_spacing", type=int, default=None,
                   help="grid spacing, projector px")
    a = p.parse_args(argv)

    def go():
        opts = _opts(a)
        src, truth = _source(a, p, opts)
        calib = _load_out(a.out)
        entry, r = P.run_projector(src, opts, calib)
        calib.projector = entry
        path = _write(a.out, calib)
        msg = (f"projector: {r.n_poses} poses, {r.n_points} correspondences ({r.n_inliers} used), "
               f"reprojection {r.reprojection_px:.3f} px")
        if truth is not None:
            et, er = truth.projector_pose_error(entry.T_display_projector)
            msg += f"; error vs truth {et * 1e3:.2f} mm, {math.degrees(er):.3f} deg"
        log.info(msg)
        log.info(f"wrote {path}")
        return 0

    return _run(p, go)


def arms_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate arms``: each arm's base pose from its clamp marker."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate arms", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Arm base poses from a clamp marker at N >= 8 joint configurations (needs the camera "
                    "entry).",
        epilog="example:\n  flexsheet calibrate arms --sim --truth-seed 1 --quick --out /tmp/disp")
    _common(p, "arms")
    p.add_argument("--configs", dest="arm_configs", type=int, default=None,
                   help=f"configurations per arm (default {P.FULL.arm_configs}; "
                                                             f"--quick {P.QUICK.arm_configs})")
    p.add_argument("--side", choices=("left", "right", "both"), default="both")
    a = p.parse_args(argv)

    def go():
        opts = _opts(a)
        src, truth = _source(a, p, opts)
        calib = _load_out(a.out)
        sides = ("left", "right") if a.side == "both" else (a.side,)
        res = P.run_arms(src, opts, calib, sides)
        for side, (entry, r) in res.items():
            calib.arms[side] = entry
            msg = f"arm {side}: {r.n_configs} configurations, residual {r.residual_mm:.3f} mm"
            if truth is not None:
                et, er = truth.base_error(side, entry.T_display_base)
                msg += f"; base error vs truth {et * 1e3:.3f} mm, {math.degrees(er):.3f} deg"
            log.info(msg)
        log.info(f"wrote {_write(a.out, calib)}")
        return 0

    return _run(p, go)


def eye_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate eye``: the viewer's eye entry (fixed V, or tracked glasses)."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate eye", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Write the eye entry: the paper's fixed viewpoint V, or 'tracked' glasses with a "
                    "fallback V.",
        epilog="example:\n  flexsheet calibrate eye --V 0.4,0,0 --ipd 0.064 --out /tmp/disp\n"
               "  flexsheet calibrate eye --mode tracked --eye-offset 0,-0.03,-0.02 --out /tmp/disp")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--mode", choices=("fixed", "tracked"), default="fixed")
    p.add_argument("--V", default="0.4,0,0", help="cyclopean eye x,y,z in m (display frame)")
    p.add_argument("--ipd", type=float, default=0.064, help="interpupillary distance, m")
    p.add_argument("--eye-offset", default="0,0,0", help="tracked: cyclopean eye in the glasses frame, m")
    a = p.parse_args(argv)

    def go():
        try:
            V = [float(v) for v in a.V.split(",")]
            off = [float(v) for v in a.eye_offset.split(",")]
        except ValueError:
            raise ValueError(f"--V and --eye-offset must be x,y,z numbers, got {a.V!r}, "
                             f"{a.eye_offset!r}") from None
        calib = _load_out(a.out)
        calib.eye = fixed_eye(V, a.ipd) if a.mode == "fixed" else tracked_eye_entry(V, a.ipd, off)
        log.info(f"eye: {a.mode}, V = {calib.eye.V.tolist()} m, ipd {calib.eye.ipd} m; wrote "
                 f"{_write(a.out, calib)}")
        return 0

    return _run(p, go)


def sheet_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate sheet``: the sheet's force under a fingertip, identified from probe presses."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate sheet", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Identify the planner's sheet model (docs/calibration.md, 'Sheet') from a probe pressed "
                    "on a load cell into the tensioned sheet at several points and clamp strains: --sim "
                    "presses the twin's true sheet, --presses reads a lab's readings (CSV with a header: "
                    "stretch, u_m, v_m, depth_m, force_n). Writes the sheet entry into OUT/display.yaml, "
                    "OUT/sheet.json (the fit, the readings, and in the twin the model's error against the "
                    "true force) and the readings as OUT/presses.csv (the --presses format).",
        epilog="example:\n  flexsheet calibrate sheet --sim --truth-seed 0 --out /tmp/disp\n"
               "  flexsheet calibrate sheet --presses docs/figures/calibration/sheet/presses.csv --out "
               "/tmp/disp")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", action="store_true", help="press the twin's true sheet (needs --truth-seed)")
    src.add_argument("--presses", metavar="CSV", help="a lab's readings: stretch,u_m,v_m,depth_m,force_n per "
                                                      "row")
    _twin_and_out(p)
    a = p.parse_args(argv)

    def go():
        import csv
        import json

        plan, truth = plan_presses(), None
        if a.sim:
            if a.truth_seed is None:
                p.error("--sim needs --truth-seed N")

            truth = TwinTruth.draw(a.truth_seed, a.realism)
            source = TwinSource(CalibrationTwin(truth, seed=a.truth_seed))
        else:
            source = PressFileSource(a.presses)
            plan = source.plan()
        readings = source.sheet_presses(plan)
        os.makedirs(a.out, exist_ok=True)
        calib = _load_out(a.out)
        calib.sheet = P.sheet_entry(readings, plan, source.label)
        doc = {"fit": {k: getattr(calib.sheet, k) for k in TERMS},
               "residuals": calib.sheet.provenance.residuals, "source": source.label,
               "readings": [r.__dict__ for r in readings]}
        if truth is not None:               # scored against the hidden truth only now, the fit being fixed

            doc["truth"] = score_sheet(truth, calib.sheet)
            log.info(f"sheet: against the true force {doc['truth']['model_error_pct']:.1f} % (median; the "
                     f"nominal string band {doc['truth']['nominal_error_pct']:.0f} %; target "
                     f"{doc['truth']['target_pct']:g} %)")
        with open(os.path.join(a.out, "sheet.json"), "w") as fh:
            json.dump(doc, fh, indent=1)
        with open(os.path.join(a.out, "presses.csv"), "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(PressFileSource.COLUMNS)
            w.writerows([r.stretch, r.offset_u, r.offset_v, r.depth, r.force] for r in readings)
        log.info(f"wrote {_write(a.out, calib)}, {os.path.join(a.out, 'sheet.json')}")
        return 0

    return _run(p, go)


def display_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate display``: every procedure in lab order — in the twin (``--sim``) or driven
    through the live graph (``--live``) — or the error-vs-poses sweep."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate display", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run camera-pose, projector, arms and eye in lab order; write OUT/display.yaml and "
                    "OUT/summary.json. --sim: in the twin against a hidden truth (errors vs truth; cached "
                    "per seed). --live: through the running graph of --launch — the arms moved by their "
                    "bridges, the patterns shown by the renderer, the camera's frames averaged; captures "
                    "kept under OUT/frames (an interrupted run resumes); with the camera twin, scored "
                    "against its truth. --sweep charts each estimate's error against the number of poses. "
                    "--draws N registers N truths drawn at random and says how often each target is met "
                    "(OUT/draws.json, draws.png).",
        epilog="example:\n  flexsheet calibrate display --sim --truth-seed 1 --quick --out /tmp/disp1\n"
               "  flexsheet calibrate display --live --launch launch/lab.yaml --host main --dry-run --out "
               "/tmp/live\n  flexsheet calibrate display --live --launch launch/lab_sim.yaml --host main "
               "--truth-seed 0 --out /tmp/live\n"
               "  flexsheet calibrate display --sweep --seeds 1,2,3 --out docs/figures/calibration\n"
               "  flexsheet calibrate display --draws 40 --out docs/figures/calibration/draws")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--sim", action="store_true", help="run in the offline twin (needs --truth-seed)")
    mode.add_argument("--live", action="store_true", help="drive the running graph of --launch")
    p.add_argument("--sweep", action="store_true", help="in the twin: error vs number of poses over --seeds "
                                                        "(PNG + JSON)")
    p.add_argument("--draws", type=int, default=None, metavar="N",
                   help="in the twin: the full registration on N truth seeds drawn with --draw-seed (or on "
                        "--seeds), each scored; per target the median, the worst and the seeds that miss it")
    p.add_argument("--draw-seed", type=int, default=20261126, help="--draws: the seed that draws the truths")
    p.add_argument("--truth-seed", type=int, default=None,
                   help="twin truth seed (--sim; with --live, a check that the camera twin renders this one)")
    p.add_argument("--realism", choices=("realistic", "ideal"), default="realistic")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--quick", action="store_true", help="fewer poses (4 projector poses, 12 configurations "
                                                        "per arm): faster, but the projector target can be "
                                                        "missed")
    p.add_argument("--force", action="store_true", help="ignore the cache (--sim)")
    p.add_argument("--seeds", default=None, help="truth seeds for --sweep (default 1,2,3) or --draws")
    p.add_argument("--launch", default=os.environ.get("FLEXSHEET_LAUNCH", "launch/lab.yaml"),
                   help="--live: the running graph's launch file (default $FLEXSHEET_LAUNCH or "
                        "launch/lab.yaml)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="--live: a graph-wide setting the launch was started with, repeatable: the same "
                        "--set hosts.NAME.address=ADDRESS as the lab on one machine (docs/deploy.md)")
    p.add_argument("--host", default=None, help="--live: the host this runs on (the renderer's: it reads the "
                                                "pattern files)")
    p.add_argument("--dry-run", action="store_true",
                   help="--live: print every commanded pose with its joints, check them against the joint "
                        "limits, move nothing (exit 1 on a pose out of reach)")
    p.add_argument("--settle", type=float, default=0.3, metavar="S",
                   help="--live: seconds after the arms arrive or a pattern is shown before frames count")
    a = p.parse_args(argv)
    opts = P.QUICK if a.quick else P.FULL

    def go():
        if a.sweep:
            if a.live:
                p.error("--sweep runs in the twin, not with --live")

            seeds = [int(s) for s in (a.seeds or "1,2,3").split(",") if s.strip()]
            run_sweep(seeds, a.out, quick=a.quick, realism=a.realism)
            return 0
        if a.draws is not None or (a.seeds is not None and not a.live):
            return _draws(a, p)
        if a.live:
            return _live(a, opts)
        if not a.sim:
            p.error("say where the frames come from: --sim (the twin), --live (the running graph) or --sweep")
        if a.truth_seed is None:
            p.error("--sim needs --truth-seed N")

        s = run_display_sim(a.truth_seed, a.out, opts, a.realism, a.force)
        ok = all(verdicts(s).values())
        log.info(f"{'all within target' if ok else 'TARGET MISSED'}; wrote {a.out}/display.yaml, "
                 f"{a.out}/summary.json")
        return 0

    return _run(p, go)


def _draws(a, p: argparse.ArgumentParser) -> int:
    """``--draws N`` (or ``--seeds``): the registration on many truths, each target's misses counted."""
    if a.live:
        p.error("--draws runs in the twin, not with --live")

    if a.seeds is not None:
        seeds, draw = [int(s) for s in a.seeds.split(",") if s.strip()], None
    else:
        if a.draws < 1:
            p.error(f"--draws must be >= 1, got {a.draws}")
        seeds, draw = draw_seeds(a.draws, a.draw_seed), a.draw_seed
    doc = run_draws(seeds, a.out, quick=a.quick, realism=a.realism, draw=draw)
    missed = {k: f["verdict"] for k, f in doc["figures"].items() if f["misses"]}
    log.info("every target met on every draw" if not missed else
             "TARGET MISSED: " + "; ".join(f"{k} {v}" for k, v in missed.items()))
    return 0


def _live(a, opts: P.Options) -> int:
    if not a.settle >= 0.0:
        print(f"flexsheet calibrate display: error: --settle must be >= 0 s, got {a.settle}", file=sys.stderr)
        return 2
    lines, problems = check_plan(opts)
    if a.dry_run:
        for line in lines:
            print(line)
        for line in problems:
            print(f"UNREACHABLE: {line}", file=sys.stderr)
        print(f"{len(lines)} poses; {len(problems) or 'none'} out of reach"
              + ("" if problems else " (arm configurations are planned again from the measured camera)"))
        return 1 if problems else 0
    if problems:
        print(f"flexsheet calibrate display: {problems[0]} (--dry-run lists every pose)", file=sys.stderr)
        return 1
    try:
        apply_toplevel_sets(a.set, a.launch)
        s = register_live(a.launch, a.out, opts, a.truth_seed, a.host, a.settle)
    except (LiveError, LaunchError) as exc:
        print(f"flexsheet calibrate display: {exc}", file=sys.stderr)
        print(f"(frames captured so far are kept in {a.out}/frames: run the same command again to resume)",
              file=sys.stderr)
        return 1
    if "verdicts" in s:
        ok = all(s["verdicts"].values())
        c, pj = s["camera"], s["projector"]
        log.info(f"camera {c['translation_error_mm']:.3f} mm {c['rotation_error_deg']:.4f}°, projector "
             f"{pj['translation_error_mm']:.2f} mm {pj['rotation_error_deg']:.3f}° "
             f"{pj['reprojection_px']:.3f} px, arms "
             + ", ".join(f"{k} {v['translation_error_mm']:.3f} mm" for k, v in s["arms"].items())
             + f": {'all within target' if ok else 'TARGET MISSED'}")
    log.info(f"wrote {a.out}/display.yaml, {a.out}/summary.json")
    return 0


def noise_main(argv: list[str] | None = None) -> int:
    """``flexsheet calibrate noise``: measure the camera noise model on real chessboard pairs."""
    p = argparse.ArgumentParser(
        prog="flexsheet calibrate noise", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Measure read noise, shot-noise gain, blur and board levels on real chessboard pairs "
                    "(9x6, the twin's image model).",
        epilog="example:\n  flexsheet calibrate noise --images /work/shared/data/stereo_calib_xi "
               "--out docs/figures/calibration/ximea_noise.json")
    p.add_argument("--images", required=True, metavar="DIR", help="folder with left*.jpg / right*.jpg")
    p.add_argument("--square", type=float, default=0.024)
    p.add_argument("--out", required=True, metavar="FILE")
    a = p.parse_args(argv)

    def go():
        log.info(f"measuring {a.images} (render each view through its calibrated pose)…")
        r = measure_ximea_noise(a.images, a.square)
        os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
        with open(a.out, "w") as fh:
            json.dump(r, fh, indent=1)
        log.info(f"model {r['model']}; wrote {a.out}")
        return 0

    return _run(p, go)
