"""``flexsheet bench arm``: IK speed, bridge cycle timing against the twin over Modbus TCP, twin tracking.

Prints one flat JSON object (``--json``) or a table. Figures (PNG + JSON of the same numbers) go to ``--out``.

- ``ik_median_us`` / ``ik_p99_us``: IK seeded from the previous solution along a stroke of the paper's
  cylinder (tilt −60°…+60°, one target per 48 Hz camera frame), both arms' kinematics, tolerance 1e-9.
- ``ik_cold_median_us``: IK from the home joints to random reachable sheet poses (tilt ±60°, stretch 0…0.1).
- ``cycle_period_ms``, ``cycle_jitter_p99_ms`` (p99 of |interval − 7.1 ms|), ``cycle_late_p99_ms``
  (p99 of start − deadline): the bridge's :class:`~nodes.arm_bridge.link.ArmStream` streaming to a twin
  running in a separate process, over ``--cycles`` cycles (default 10 000).
- ``track_*``: the twin (servo model) following a stroke in simulated time: clamp position error
  (max, rms, mm) and the lag (ms) minimising the error, for 10 s and 30 s strokes (the paper's Table I) and
  a 2 s stroke (where the speed limits start to bite).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

from flexsheet.model import scene
from flexsheet.model.kinematics import (
    LEFT_BASE,
    Q_LOWER,
    Q_UPPER,
    QD_MAX,
    RIGHT_BASE,
    ArmKinematics,
    home_joints,
)
from messages.registers import encode_joints
from nodes.arm_bridge.interp import StreamLimiter
from nodes.arm_bridge.tracking import TargetTracker
from nodes.arm_controller_sim.controller import ControllerCore

PERIOD = 0.0071
EPILOG = "example: flexsheet bench arm --json --cycles 2000 --out docs/figures/arm"


def _clamp(side: str, theta: float, stretch: float = 0.05) -> np.ndarray:
    R = scene.CYLINDER_RADIUS
    c, s = math.cos(theta), math.sin(theta)
    L, Rr = scene.clamp_poses(np.array([-R + R * c, 0.0, R * s]), np.array([c, 0.0, s]),
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
    return out


def track_stroke(duration: float, side: str = "left") -> dict:
    """Simulated-time run of tracker → limiter → controller core for one ±60° stroke of ``duration`` s."""
    base = LEFT_BASE if side == "left" else RIGHT_BASE
    kin = ArmKinematics(side, base, Q_LOWER + 0.02, Q_UPPER - 0.02)
    fk = ArmKinematics(side, base)
    th0 = math.radians(-60.0)
    tr = TargetTracker(kin, target_timeout=1.0)
    q0 = kin.ik(_clamp(side, th0), home_joints(side), max_jump=10.0).q
    core = ControllerCore(q0, period=PERIOD)
    core.write_holding(0, [1], 0.0)
    lim = StreamLimiter(q0, PERIOD, 0.5 * QD_MAX, QD_MAX, Q_LOWER, Q_UPPER, 0.02)
    tr.seed(q0)
    n = int(duration / PERIOD) + int(0.5 / PERIOD)
    t_cam = 1.0 / 48.0
    next_cam = 0.0
    ts, pos_meas = [], []
    theta_of = lambda t: th0 + math.radians(120.0) * 0.5 * (1 - math.cos(math.pi * min(t, duration) / duration))  # noqa: E731
    refused = 0
    for k in range(n):
        t = k * PERIOD
        if t >= next_cam:
            r = tr.set_target(_clamp(side, theta_of(t)), t, t)
            refused += not r.ok
            next_cam += t_cam
        cmd = lim.step(tr.goal_for(t, lim.c))
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
    from nodes.arm_controller_sim.node import ControllerTwin

    async def main():
        twin = ControllerTwin(ControllerCore(np.array(q), period=PERIOD, now=time.monotonic()))
        port_queue.put(await twin.start())
        while not stop_event.is_set():
            await asyncio.sleep(0.05)
        await twin.stop()
    asyncio.run(main())


def bench_cycle(n_cycles: int) -> dict:
    """Stream ``n_cycles`` cycles to a twin in another process; interval statistics (ms)."""
    from nodes.arm_bridge.link import ArmStream

    ctx = mp.get_context("spawn")
    port_q, stop = ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=_twin_process, args=(home_joints("left").tolist(), port_q, stop), daemon=True)
    proc.start()
    try:
        port = port_q.get(timeout=30)
        kin = ArmKinematics("left", LEFT_BASE, Q_LOWER + 0.02, Q_UPPER - 0.02)
        tr = TargetTracker(kin, target_timeout=1e9)
        lim = StreamLimiter(home_joints("left"), PERIOD, 0.5 * QD_MAX, QD_MAX, Q_LOWER, Q_UPPER, 0.02)
        stream = ArmStream(tr, lim, "127.0.0.1", port, request_timeout=0.5)
        stream.cycle_times = []
        deadlines: list[float] = []
        stream.on_cycle = lambda rep: deadlines.append(rep.t_deadline)

        async def run():
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
            await stream.run(n_cycles + 50)
            f.cancel()
            await stream.stop()
        asyncio.run(run())
    finally:
        stop.set()
        proc.join(timeout=5)
        if proc.is_alive():
            proc.terminate()
    t = np.array(stream.cycle_times[50:])
    d = np.array(deadlines[50:])
    iv = np.diff(t)
    return {"cycle_period_ms": float(iv.mean() * 1e3), "cycle_jitter_p99_ms": float(np.percentile(np.abs(iv - PERIOD), 99) * 1e3),
            "cycle_jitter_max_ms": float(np.max(np.abs(iv - PERIOD)) * 1e3),
            "cycle_late_p99_ms": float(np.percentile(t - d, 99) * 1e3), "cycles": int(len(t)),
            "reconnects": stream.reconnects, "intervals_ms": (iv * 1e3).tolist()}


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
    """CLI entry: ``flexsheet bench arm [--json] [--cycles N] [--out DIR]``."""
    ap = argparse.ArgumentParser(prog="flexsheet bench arm", description=__doc__.splitlines()[0], epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true", help="print one flat JSON object")
    ap.add_argument("--cycles", type=int, default=10000, help="bridge cycles to time (default 10000)")
    ap.add_argument("--out", type=Path, default=None, help="write arm_bench.png/.json here")
    args = ap.parse_args(argv)
    if args.cycles < 10:
        ap.error(f"--cycles must be >= 10, got {args.cycles}")
    res: dict = {}
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
    flat = {k: v for k, v in res.items() if not isinstance(v, dict)}
    if args.json:
        print(json.dumps(flat))
    else:
        for k, v in flat.items():
            print(f"{k:36s} {v:.4g}" if isinstance(v, float) else f"{k:36s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
