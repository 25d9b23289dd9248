"""``flexsheet bench arm``: IK speed, bridge cycle timing against the twin (Modbus TCP or MXT/UDP), tracking.

Prints one flat JSON object (``--json``) or a table. Figures (PNG + JSON of the same numbers) go to ``--out``.

- ``ik_median_us`` / ``ik_p99_us``: IK seeded from the previous solution along a stroke of the paper's
  cylinder (tilt −60°…+60°, one target per 48 Hz camera frame), both arms' kinematics, tolerance 1e-9.
- ``ik_cold_median_us``: IK from the home joints to random reachable sheet poses (tilt ±60°, stretch 0…0.1).
- ``motion_cycle_median_us`` / ``motion_cycle_p99_us``: the bridge's work each cycle while it follows the
  sheet's motion (:mod:`flexsheet.arm.sheet_motion`): the clamp's pose and twist on the segment, IK seeded
  from the last cycle, the Jacobian solve (:meth:`TargetTracker.reference`); the planner's segments along the
  same stroke, a new one every 48 Hz frame, the bridge cycling at 7.1 ms; ``motion_plan_median_us``: the
  planner's segment (ruckig and the joint-rate check of both arms).
- ``cycle_period_ms``, ``cycle_jitter_p99_ms`` (p99 of |interval − 7.1 ms|), ``cycle_late_p99_ms``
  (p99 of start − deadline): the bridge's :class:`~flexsheet.arm.stream.ArmStream` streaming over its Modbus
  link to a twin running in a separate process, over ``--cycles`` cycles (default 10 000).
- ``track_*``: the twin (servo model) following a stroke in simulated time: clamp position error
  (max, rms, mm) and the lag (ms) minimising the error, for 10 s and 30 s strokes (the paper's Table I) and
  a 2 s stroke (where the speed limits start to bite).

``--protocol mxt`` measures the MELFA real-time external control link instead (nothing else): the bridge's
:class:`~flexsheet.arm.stream.ArmStream` + the MXT link streaming MOVE packets to the MXT twin
(:class:`~flexsheet.twin.mxt_server.MxtTwin`) in another process over UDP on loopback, following a ±60°
stroke, for ``--cycles`` cycles at ``--period`` (7.11 ms):

- ``mxt_send_period_ms``, ``mxt_jitter_p50_ms`` / ``mxt_jitter_p99_ms`` / ``mxt_jitter_max_ms``: interval
  between consecutive MOVE packets and its deviation |Δt − period| (the bridge is paced by the replies, so
  this includes the twin's own scheduling);
- ``mxt_rtt_p50_ms`` / ``mxt_rtt_p99_ms``: packet → reply round trip (the reply leaves at the twin's next
  cycle, so up to one period is by design);
- ``mxt_react_p50_ms`` / ``mxt_react_p99_ms``: the bridge's own part: from the reply's arrival (the
  controller ready for the next command) to the next MOVE leaving;
- ``mxt_lost`` (never answered), ``mxt_late`` (answered after the next packet left), ``mxt_repeats``
  (cycles that repeated the last command for want of a reply), ``mxt_refused``, ``mxt_sent``,
  ``mxt_replies``; twin side: ``twin_tick_jitter_p50_ms`` / ``p99``, ``twin_missed_cycles`` (control cycles
  without a packet), ``twin_refused``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing as mp
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.chain import bridge_chain
from flexsheet.arm.controller_port import controller_source
from flexsheet.arm.joint_rates import JointRates
from flexsheet.arm.kinematics import QD_MAX, ArmKinematics, home_joints
from flexsheet.arm.sheet_motion import SheetShaper
from flexsheet.arm.stream import ArmStream
from flexsheet.arm.tracking import TargetTracker
from flexsheet.model import geometry
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses, sheet_rotation
from flexsheet.twin.controller import ControllerCore
from flexsheet.twin.modbus_server import ControllerTwin
from flexsheet.twin.mxt_server import MxtCore, MxtTwin
from messages.registers import encode_joints

PERIOD = 0.0071
#: the bridge's links come from the controller port's source of a controller over the network, as the
#: lab's arm PCs reach theirs (:meth:`~flexsheet.arm.controller_port.ControllerSource.link`)
SOURCE = "tcp"
MXT_PERIOD = 0.00711
EPILOG = ("example: flexsheet bench arm --json --cycles 2000 --out docs/figures/arm\n"
          "example: flexsheet bench arm --protocol mxt --json --cycles 10000 --out docs/figures/arm")


def _clamp(side: str, theta: float, stretch: float = 0.05) -> np.ndarray:
    R = geometry.CYLINDER_RADIUS
    c, s = math.cos(theta), math.sin(theta)
    L, Rr = clamp_poses(np.array([-R + R * c, 0.0, R * s]), np.array([c, 0.0, s]),
                              np.array([0.0, 1.0, 0.0]), stretch)
    return L if side == "left" else Rr


def bench_ik(n_stroke: int = 480) -> dict:
    """IK timings (µs) along strokes and from cold seeds; plus the tolerance/time trade-off."""
    out: dict = {}
    warm, tol_curve = [], {}
    for side, base in (("left", LEFT_BASE), ("right", RIGHT_BASE)):
        kin = ArmKinematics(side, base)
        thetas = np.radians(60.0) * np.sin(np.linspace(-math.pi / 2, 3 * math.pi / 2, n_stroke))
        poses = [_clamp(side, th) for th in thetas]
        for tol in (1e-5, 1e-7, 1e-9, 1e-11):
            q = home_joints(side)
            times = []
            for T in poses:
                t0 = time.perf_counter()
                r = kin.ik(T, q, tol_pos=tol, tol_rot=tol)
                times.append(time.perf_counter() - t0)
                if r.ok:
                    q = r.q
            tol_curve.setdefault(tol, []).extend(times)
            if tol == 1e-9:
                warm.extend(times)
    out["ik_median_us"] = float(np.median(warm) * 1e6)
    out["ik_p99_us"] = float(np.percentile(warm, 99) * 1e6)
    out["ik_tolerance_curve"] = {f"{k:.0e}": float(np.median(v) * 1e6) for k, v in tol_curve.items()}
    rng = np.random.default_rng(0)
    cold, ok = [], 0
    kin = ArmKinematics("left", LEFT_BASE)
    for _ in range(200):
        T = _clamp("left", rng.uniform(-1.0, 1.0) * math.radians(60), rng.uniform(0.0, 0.1))
        t0 = time.perf_counter()
        r = kin.ik(T, home_joints("left"), max_jump=10.0)
        cold.append(time.perf_counter() - t0)
        ok += r.ok
    out["ik_cold_median_us"] = float(np.median(cold) * 1e6)
    out["ik_cold_success"] = ok / 200.0
    out.update(bench_motion(n_stroke))
    return out


def bench_motion(n_stroke: int = 480) -> dict:
    """The bridge's per-cycle work following the sheet's motion, and the planner's per-segment work (µs)."""
    kin = {s: ArmKinematics(s, b) for s, b in (("left", LEFT_BASE), ("right", RIGHT_BASE))}
    qd = QD_MAX * 0.5
    shaper = SheetShaper(rates=JointRates({"left": LEFT_BASE, "right": RIGHT_BASE}, qd,
                                          BridgeConfig().accel_scale * qd))
    tracker = TargetTracker(kin["left"])
    q = {s: kin[s].ik(_clamp(s, -math.radians(60.0)), home_joints(s), max_jump=10.0).q for s in kin}
    tracker.seed(q["left"])
    R = geometry.CYLINDER_RADIUS
    thetas = np.radians(60.0) * np.sin(np.linspace(-math.pi / 2, 3 * math.pi / 2, n_stroke))
    plan_t, cycle_t, t = [], [], 0.0
    for th in thetas:
        c, s_ = math.cos(th), math.sin(th)
        Rm = sheet_rotation(np.array([c, 0.0, s_]), np.array([0.0, 1.0, 0.0]))
        T = {side: _clamp(side, th) for side in kin}
        for side in kin:
            r = kin[side].ik(T[side], q[side])
            q[side] = r.q if r.ok else q[side]
        shaper.rates.at({side: [q[side]] for side in kin})
        t0 = time.perf_counter()
        seg = shaper.update(t, np.array([-R + R * c, 0.0, R * s_]), Rm, 0.05)
        plan_t.append(time.perf_counter() - t0)
        tracker.set_target(T["left"], t, t, motion=seg)
        for k in range(3):                               # a 7.1 ms cycle, about three per 48 Hz frame
            t0 = time.perf_counter()
            tracker.reference(t + k * PERIOD, tracker.goal)
            cycle_t.append(time.perf_counter() - t0)
        t += 1.0 / 48.0
    return {"motion_cycle_median_us": float(np.median(cycle_t) * 1e6),
            "motion_cycle_p99_us": float(np.percentile(cycle_t, 99) * 1e6),
            "motion_plan_median_us": float(np.median(plan_t) * 1e6)}


def track_stroke(duration: float, side: str = "left") -> dict:
    """Simulated-time run of tracker → limiter → controller core for one ±60° stroke of ``duration`` s."""
    base = LEFT_BASE if side == "left" else RIGHT_BASE
    th0 = math.radians(-60.0)
    chain = bridge_chain(side, base, PERIOD, replace(BridgeConfig(), target_timeout=1.0))
    fk, tr, lim = chain.fk, chain.tracker, chain.limiter
    q0 = chain.kin.ik(_clamp(side, th0), home_joints(side), max_jump=10.0).q
    lim.reset(q0)
    core = ControllerCore(q0, period=PERIOD)
    core.write_holding(0, [1], 0.0)
    tr.seed(q0)
    n = int(duration / PERIOD) + int(0.5 / PERIOD)
    t_cam = 1.0 / 48.0
    next_cam = 0.0
    ts, pos_meas = [], []
    theta_of = lambda t: th0 + math.radians(120.0) * 0.5 * (1  # noqa: E731
                                                            - math.cos(math.pi * min(t, duration) / duration))
    refused = 0
    for k in range(n):
        t = k * PERIOD
        if t >= next_cam:
            r = tr.set_target(_clamp(side, theta_of(t)), t, t)
            refused += not r.ok
            next_cam += t_cam
        cmd = lim.step(*tr.reference(t, lim.c))
        core.write_holding(1, [(k + 1) & 0xFFFF, *encode_joints(cmd)], t)
        core.advance(t + PERIOD)
        ts.append(t + PERIOD)
        pos_meas.append(fk.fk(core.servo.q)[:3, 3])
    ts = np.array(ts)
    pm = np.array(pos_meas)
    err_now = np.array([np.linalg.norm(pm[i] - _clamp(side, theta_of(ts[i]))[:3, 3]) for i in range(len(ts))])
    best = (math.inf, 0.0)
    for lag in np.arange(0.0, 0.15, 0.0025):
        e = np.array([np.linalg.norm(pm[i] - _clamp(side, theta_of(max(0.0, ts[i] - lag)))[:3, 3])
                      for i in range(0, len(ts), 4)])
        rms = float(np.sqrt(np.mean(e ** 2)))
        if rms < best[0]:
            best = (rms, lag)
    return {"duration_s": duration, "err_max_mm": float(err_now.max() * 1e3),
            "err_rms_mm": float(np.sqrt(np.mean(err_now ** 2)) * 1e3), "lag_ms": best[1] * 1e3,
            "err_rms_after_lag_mm": best[0] * 1e3, "refused": refused,
            "t": ts[::10].tolist(), "err_mm": (err_now[::10] * 1e3).tolist()}


def _twin_process(q, port_queue, stop_event) -> None:
    async def main():
        twin = ControllerTwin(ControllerCore(np.array(q), period=PERIOD, now=time.monotonic()))
        port_queue.put(await twin.start())
        while not stop_event.is_set():
            await asyncio.sleep(0.05)
        await twin.stop()
    asyncio.run(main())


def bench_cycle(n_cycles: int) -> dict:
    """Stream ``n_cycles`` cycles to a twin in another process; interval statistics (ms)."""
    ctx = mp.get_context("spawn")
    port_q, stop = ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=_twin_process, args=(home_joints("left").tolist(), port_q, stop), daemon=True)
    proc.start()
    try:
        port = port_q.get(timeout=30)
        chain = bridge_chain("left", LEFT_BASE, PERIOD, replace(BridgeConfig(), target_timeout=1e9),
                             home_joints("left"))
        tr, lim = chain.tracker, chain.limiter
        stream = ArmStream(tr, lim, controller_source(SOURCE).link("modbus", "127.0.0.1", port,
                                                                     request_timeout=0.5))
        stream.cycle_times = []
        deadlines: list[float] = []
        stream.on_cycle = lambda rep: deadlines.append(rep.t_deadline)

        asyncio.run(_drive(tr, stream, n_cycles + 50))
    finally:
        stop.set()
        proc.join(timeout=5)
        if proc.is_alive():
            proc.terminate()
    t = np.array(stream.cycle_times[50:])
    d = np.array(deadlines[50:])
    iv = np.diff(t)
    return {"cycle_period_ms": float(iv.mean() * 1e3),
            "cycle_jitter_p99_ms": float(np.percentile(np.abs(iv - PERIOD), 99) * 1e3),
            "cycle_jitter_max_ms": float(np.max(np.abs(iv - PERIOD)) * 1e3),
            "cycle_late_p99_ms": float(np.percentile(t - d, 99) * 1e3), "cycles": int(len(t)),
            "reconnects": stream.reconnects, "intervals_ms": (iv * 1e3).tolist()}


async def _drive(tr, stream, cycles: int) -> None:
    """Feed the left arm's tracker a ±60° sinusoid on joint 1 at the planner's 48 Hz while ``stream`` runs
    ``cycles`` control cycles; then stop the stream (:meth:`ArmStream.stop`, which ends the session)."""
    tr.seed(home_joints("left"))
    k = 0

    async def feeder():
        nonlocal k
        while True:
            th = math.radians(60.0) * math.sin(2 * math.pi * k / 480.0)
            tr.set_target(_clamp("left", th), float(k), time.time())
            k += 1
            await asyncio.sleep(1.0 / 48.0)
    f = asyncio.get_running_loop().create_task(feeder())
    try:
        await stream.run(cycles)
    finally:
        f.cancel()
    await stream.stop()


def _mxt_twin_process(q, period, port_queue, stop_event, result_queue) -> None:
    async def main():
        core = MxtCore(np.array(q), period=period, timeout=0.0, now=time.monotonic())
        twin = MxtTwin(core, "127.0.0.1", 0)
        twin.tick_times = []
        port_queue.put(await twin.start())
        while not stop_event.is_set():
            await asyncio.sleep(0.05)
        await twin.stop()
        iv = np.diff(np.array(twin.tick_times[100:]))
        result_queue.put({"twin_tick_jitter_p50_ms": float(np.median(np.abs(iv - period)) * 1e3),
                          "twin_tick_jitter_p99_ms": float(np.percentile(np.abs(iv - period), 99) * 1e3),
                          "twin_missed_cycles": core.missed_cycles, "twin_refused": core.refused,
                          "twin_moves": core.moves, "twin_replied": twin.replied})
    asyncio.run(main())


def bench_mxt(n_cycles: int, period: float = MXT_PERIOD) -> dict:
    """Stream ``n_cycles`` MXT cycles to a twin in another process (see module doc); statistics in ms."""
    ctx = mp.get_context("spawn")
    port_q, stop, res_q = ctx.Queue(), ctx.Event(), ctx.Queue()
    proc = ctx.Process(target=_mxt_twin_process,
                       args=(home_joints("left").tolist(), period, port_q, stop, res_q),
                       daemon=True)
    proc.start()
    twin_res: dict = {}
    try:
        port = port_q.get(timeout=60)
        chain = bridge_chain("left", LEFT_BASE, period, replace(BridgeConfig(), target_timeout=1e9),
                             home_joints("left"))
        tr, lim = chain.tracker, chain.limiter
        link = controller_source(SOURCE).link("mxt", "127.0.0.1", port, period=period, lost_cycles=10 ** 9,
                                              record=True)
        stream = ArmStream(tr, lim, link)
        done = [0]

        def progress(rep) -> None:
            done[0] += 1
            if done[0] % 1000 == 0:
                print(f"  mxt: {done[0]}/{n_cycles} cycles, lost {link.lost}, late "
                      f"{link.late}", file=sys.stderr)
        stream.on_cycle = progress

        asyncio.run(_drive(tr, stream, n_cycles + 100))
    finally:
        stop.set()
        try:
            twin_res = res_q.get(timeout=30)
        except Exception:  # noqa: BLE001 - the twin's numbers are optional
            twin_res = {}
        proc.join(timeout=5)
        if proc.is_alive():
            proc.terminate()
    t = np.array(link.send_times[101:])          # MOVE packets after the first 100 (warm-up)
    iv = np.diff(t)
    rtt = np.array(link.rtts[100:])
    react = np.array(link.reactions[101:])
    react = react[np.isfinite(react)]
    dev = np.abs(iv - period)
    out = {"mxt_period_ms": period * 1e3, "mxt_cycles": int(len(iv)),
           "mxt_send_period_ms": float(iv.mean() * 1e3),
           "mxt_jitter_p50_ms": float(np.median(dev) * 1e3),
           "mxt_jitter_p99_ms": float(np.percentile(dev, 99) * 1e3),
           "mxt_jitter_max_ms": float(dev.max() * 1e3),
           "mxt_rtt_p50_ms": float(np.median(rtt) * 1e3),
           "mxt_rtt_p99_ms": float(np.percentile(rtt, 99) * 1e3),
           "mxt_react_p50_ms": float(np.median(react) * 1e3),
           "mxt_react_p99_ms": float(np.percentile(react, 99) * 1e3)}
    out.update({f"mxt_{k}": v for k, v in link.counters().items() if k in ("sent", "replies", "lost", "late",
                                                                            "repeats", "refused",
                                                                           "unmatched")})
    out.update(twin_res)
    out["intervals_ms"] = (iv * 1e3).tolist()
    return out


def _mxt_figure(out: Path, res: dict, iv: list) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].hist(iv, bins=120, log=True)
    ax[0].axvline(res["mxt_period_ms"], color="k", ls="--")
    ax[0].set_xlabel("interval between MOVE packets [ms]")
    ax[0].set_ylabel("count")
    ax[0].set_title(f"MXT stream, jitter p50 {res['mxt_jitter_p50_ms']:.2f} / p99 "
                    f"{res['mxt_jitter_p99_ms']:.2f} ms")
    ax[1].plot(np.arange(len(iv)), iv, ",")
    ax[1].set_xlabel("cycle")
    ax[1].set_ylabel("interval [ms]")
    ax[1].set_title(f"{res['mxt_cycles']} cycles: lost {res['mxt_lost']}, late {res['mxt_late']}, "
                    f"repeats {res['mxt_repeats']}")
    fig.tight_layout()
    fig.savefig(out / "arm_bench_mxt.png", dpi=110)
    plt.close(fig)
    (out / "arm_bench_mxt.json").write_text(json.dumps(res, indent=2))


def _figures(out: Path, res: dict, iv: list, tracks: list) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    ax[0].hist(iv, bins=100, log=True)
    ax[0].axvline(PERIOD * 1e3, color="k", ls="--")
    ax[0].set_xlabel("cycle interval [ms]")
    ax[0].set_ylabel("count")
    ax[0].set_title(f"bridge cycle, p99 jitter {res['cycle_jitter_p99_ms']:.2f} ms")
    for tk in tracks:
        ax[1].plot(tk["t"], tk["err_mm"], label=f"{tk['duration_s']:.0f} s stroke, lag {tk['lag_ms']:.0f} ms")
    ax[1].set_xlabel("time [s]")
    ax[1].set_ylabel("clamp position error vs. current target [mm]")
    ax[1].set_yscale("log")
    ax[1].legend()
    ax[1].set_title("twin tracking a ±60° stroke")
    tc = res["ik_tolerance_curve"]
    ax[2].plot([float(k) * 1e3 for k in tc], list(tc.values()), "o-")
    ax[2].set_xscale("log")
    ax[2].set_xlabel("IK tolerance [mm] (and rad)")
    ax[2].set_ylabel("IK median time [µs]")
    ax[2].set_title("IK accuracy vs. speed (warm seed)")
    fig.tight_layout()
    fig.savefig(out / "arm_bench.png", dpi=110)
    plt.close(fig)
    (out / "arm_bench.json").write_text(json.dumps(res, indent=2))


def main(argv: list[str] | None = None) -> int:
    """CLI entry: ``flexsheet bench arm [--protocol modbus|mxt] [--json] [--cycles N] [--out DIR]``."""
    ap = argparse.ArgumentParser(prog="flexsheet bench arm", description=__doc__.splitlines()[0],
                                 epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true", help="print one flat JSON object")
    ap.add_argument("--cycles", type=int, default=10000, help="bridge cycles to time (default 10000)")
    ap.add_argument("--out", type=Path, default=None, help="write arm_bench.png/.json (arm_bench_mxt.*) here")
    ap.add_argument("--protocol", choices=("modbus", "mxt"), default="modbus",
                    help="modbus: IK, Modbus cycle timing, tracking (default); mxt: the MXT/UDP link only")
    ap.add_argument("--period", type=float, default=MXT_PERIOD,
                    help=f"mxt: controller cycle, s (default {MXT_PERIOD}; 0.0035 for CR800-R/D)")
    args = ap.parse_args(argv)
    if args.cycles < 10:
        ap.error(f"--cycles must be >= 10, got {args.cycles}")
    if not 0.0005 <= args.period <= 0.1:
        ap.error(f"--period must be in 0.0005..0.1 s, got {args.period}")
    res: dict = {}
    if args.protocol == "mxt":
        res = bench_mxt(args.cycles, args.period)
        iv = res.pop("intervals_ms")
        if args.out is not None:
            _mxt_figure(args.out, res, iv)
        _print(res, args.json)
        return 0
    res.update(bench_ik())
    cyc = bench_cycle(args.cycles)
    iv = cyc.pop("intervals_ms")
    res.update(cyc)
    tracks = [track_stroke(d) for d in (2.0, 10.0, 30.0)]
    for tk in tracks:
        key = f"track_{tk['duration_s']:.0f}s"
        for f in ("err_max_mm", "err_rms_mm", "lag_ms", "err_rms_after_lag_mm", "refused"):
            res[f"{key}_{f}"] = tk[f]
    if args.out is not None:
        _figures(args.out, res, iv, tracks)
    _print(res, args.json)
    return 0


def _print(res: dict, as_json: bool) -> None:
    flat = {k: v for k, v in res.items() if not isinstance(v, dict)}
    if as_json:
        print(json.dumps(flat))
    else:
        for k, v in flat.items():
            print(f"{k:36s} {v:.4g}" if isinstance(v, float) else f"{k:36s} {v}")


if __name__ == "__main__":
    sys.exit(main())
