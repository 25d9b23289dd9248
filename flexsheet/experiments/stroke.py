"""``flexsheet experiment stroke``: the paper's Table I in-process, with a latency model of the real loop.

The scripted finger (:class:`flexsheet.model.finger.FingerScript`) follows the target mark from 0° to 60°
around the paper's cylinder. A camera samples it at 48 Hz (BumbleBee2) with white noise; the triangulator's
own constant-velocity Kalman filter (:class:`nodes.triangulator.predict.ConstantVelocityKF`, fed the
measurement covariance as the triangulator feeds it) optionally predicts the fingertip ``horizon`` s ahead;
the :class:`nodes.planner.stroke.SurfacePlanner` plans; the plan reaches the arm PCs after processing +
network delay, is written at the next RV-1A external-control tick (7.1 ms), executes one tick later and the
servo follows it as a first-order lag. The actual sheet pose is sampled at each exposure and the Table I row
(Fig. 9, :func:`flexsheet.experiments.table1.table1_row`, the same metric as the report of a recorded run) is
computed over the moving phase.

Filter tuning: the process noise ``q`` (m²/s³) is set from a tracking index λ = √(q T³)/σ_m (T the camera
period, σ_m the measurement noise; Kalata, IEEE T-AES 20(2), 1984, and Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, ch. 6), λ = 0.1 by default: a smooth
stroke, tremor not tracked. The rows ``*_launch_kf`` use the triangulator's ``q`` and ``horizon_s`` from
``launch/sim.yaml`` instead, for comparison with the full process graph.

Outputs in ``--out DIR``: ``summary.json`` (Table I rows keyed by moving time "10", "30", the paper's
values, the latency budget and its parts, sweeps), ``stroke_errors.png`` (Δd and Δθ against moving time
with/without prediction, and against loop latency) and ``stroke_errors.json`` (the chart's numbers).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from flexsheet.experiments.table1 import PAPER_TABLE1, TARGET_FACTOR, table1_row, target
from flexsheet.model.finger import FingerScript
from flexsheet.model.shapes import paper_cylinder
from nodes.planner.stroke import PlannerConfig, SurfacePlanner
from nodes.triangulator.pipeline import TrackerConfig
from nodes.triangulator.predict import ConstantVelocityKF

__all__ = ["LatencyModel", "Predictor", "q_for_tracking_index", "launch_kf", "simulate", "main"]

#: the launch file whose triangulator settings the ``*_launch_kf`` rows use
SIM_LAUNCH = Path(__file__).resolve().parents[2] / "launch" / "sim.yaml"


@dataclass(frozen=True)
class LatencyModel:
    """Loop latency parts, s.

    ``camera_period`` 1/48 s (BumbleBee2 at 48 Hz). ``exposure_to_host``: mid-exposure to frame in host
    memory — half a ~2 ms shutter plus the IEEE-1394b transfer of a 2×640×480 8-bit pair (614 kB at
    ~80 MB/s ≈ 7.7 ms): 8 ms. ``processing``: marker detection, triangulation and planning: 3 ms (see
    ``flexsheet bench vision`` / ``bench planner``). ``network``: one LAN hop main PC → arm PC: 1 ms.
    ``servo_period``: RV-1A external-control period 7.1 ms; a target waits for the next tick (mean half a
    period), executes one tick later (``pipeline_ticks``), and the joint servo lags it by a first-order
    ``servo_tau`` (0.015 s, the controller twin's first-order lag, ``nodes/arm_controller_sim/node.py``).
    ``camera_noise`` m rms per axis: 0.1 mm, measured in the full simulated graph (XIMEA-calibrated camera
    twin at ~0.5 m, marker triangulation; per-axis rms 0.08–0.12 mm); a constant calibration bias cancels
    in Δd. Both match the full-graph run, so the two can be compared "under the same latency budget".
    ``scale`` multiplies every delay (latency sweep).
    """

    camera_period: float = 1.0 / 48.0
    exposure_to_host: float = 0.008
    processing: float = 0.003
    network: float = 0.001
    servo_period: float = 0.0071
    pipeline_ticks: int = 1
    servo_tau: float = 0.015
    camera_noise: float = 1e-4
    scale: float = 1.0

    def budget(self) -> dict[str, float]:
        """Mean delay from exposure to the sheet reaching the plan, s, by part and in total (``total``).
        The mean hold of a 48 Hz target between updates (half a camera period) is listed separately."""
        s = self.scale
        parts = {"exposure_to_host": s * self.exposure_to_host, "processing": s * self.processing,
                 "network": s * self.network, "servo_tick_wait": 0.5 * self.servo_period,
                 "servo_pipeline": self.pipeline_ticks * self.servo_period, "servo_lag": self.servo_tau}
        parts["total"] = sum(parts.values())
        parts["target_hold_mean"] = 0.5 * self.camera_period
        return parts


def q_for_tracking_index(tracking_index: float, sigma_m: float, period: float) -> float:
    """Process noise q (m²/s³) of the continuous white-noise-acceleration model for tracking index
    λ = √(q T³)/σ_m, i.e. q = (λ σ_m)² / T³, from ``sigma_m`` (m) and ``period`` T (s). Its steady-state
    Kalman filter is the α-β filter of Kalata's index λ. Raises ``ValueError`` for non-positive inputs."""
    for name, v in (("tracking_index", tracking_index), ("sigma_m", sigma_m), ("period", period)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    return (tracking_index * sigma_m) ** 2 / period ** 3


class Predictor:
    """The triangulator's fingertip prediction, in-process: :class:`ConstantVelocityKF` updated with each
    measurement z (3,) m and covariance ``R`` (3, 3) m², predicting ``position_at(t + h)`` as
    :class:`nodes.triangulator.pipeline.FingertipTracker` does. ``q`` m²/s³; ``v0_std`` m/s (default: the
    tracker's)."""

    def __init__(self, q: float, R: np.ndarray, v0_std: float = TrackerConfig.v0_std):
        self.kf = ConstantVelocityKF(q=q, v0_std=v0_std)
        self.R = np.asarray(R, dtype=float)
        self.t = 0.0

    def update(self, t: float, z: np.ndarray) -> None:
        """Fuse the measurement z (3,) m taken at ``t`` s."""
        self.kf.update(z, self.R, t)
        self.t = t

    def predict(self, h: float) -> np.ndarray:
        """Position (3,) m ``h`` s after the last measurement."""
        return self.kf.position_at(self.t + h)


def launch_kf(path: Path = SIM_LAUNCH) -> dict[str, float] | None:
    """The triangulator's ``q`` and ``horizon_s`` in launch file ``path`` (defaults from
    :class:`TrackerConfig` for keys it does not set), or ``None`` if the file or the node is missing."""
    try:
        node = yaml.safe_load(path.read_text())["nodes"]["triangulator"]
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        return None
    prm = node.get("params") or {}
    return {"q": float(prm.get("q", TrackerConfig.q)), "horizon_s": float(prm.get("horizon_s", TrackerConfig.horizon_s))}


def simulate(moving_time: float, use_prediction: bool, latency: LatencyModel, seed: int = 0,
             finger_kw: dict | None = None, horizon: float | None = None, tracking_index: float = 0.1,
             truth: bool = False, q: float | None = None) -> dict[str, float]:
    """Run one stroke and return the Table I row (:func:`flexsheet.experiments.table1.table1_row`) over the
    moving phase. ``horizon`` (s) defaults to the latency budget plus the mean target hold; the filter's
    ``q`` (m²/s³) defaults to :func:`q_for_tracking_index` (``tracking_index``, camera noise, camera period).
    ``truth``: measure D from the true finger instead of the camera measurement (the paper's D is the
    measurement)."""
    shape = paper_cylinder()
    finger = FingerScript(moving_time=moving_time, seed=seed, **(finger_kw or {}))
    rng = np.random.default_rng(1000 + seed)
    Tc = latency.camera_period
    tk = np.arange(0.0, finger.duration, Tc) + rng.uniform(0, Tc)
    true_p = finger.positions(tk)
    meas = true_p + rng.normal(0.0, latency.camera_noise, true_p.shape)
    bud = latency.budget()
    h = (bud["total"] + bud["target_hold_mean"]) if horizon is None else horizon
    if q is None:
        q = q_for_tracking_index(tracking_index, latency.camera_noise, Tc)
    kf = Predictor(q, latency.camera_noise ** 2 * np.eye(3))
    planner = SurfacePlanner(shape, PlannerConfig())
    s = latency.scale
    delay_to_arm = s * (latency.exposure_to_host + latency.processing + latency.network)
    arrivals, cmd_o, cmd_n = [], [], []
    for i, t in enumerate(tk):
        z = meas[i]
        kf.update(t, z)
        p = kf.predict(h) if use_prediction else z
        plan = planner.update(t, p)
        if plan is None:
            continue
        arrivals.append(t + delay_to_arm)
        cmd_o.append(plan.origin)
        cmd_n.append(plan.normal)
    arrivals = np.asarray(arrivals)
    cmd_o = np.asarray(cmd_o)
    cmd_n = np.asarray(cmd_n)
    # servo: ticks with a random phase; the command executing in [t_j, t_j+1) is the latest arrival ≤ t_j-pipeline
    Ts = latency.servo_period
    ticks = np.arange(rng.uniform(0, Ts), finger.duration + Ts, Ts)
    idx = np.searchsorted(arrivals, ticks - latency.pipeline_ticks * Ts, side="right") - 1
    xo = np.empty((len(ticks), 3))
    xn = np.empty((len(ticks), 3))
    decay = math.exp(-Ts / latency.servo_tau)
    cur_o = cmd_o[0].copy()
    cur_n = cmd_n[0].copy()
    for j in range(len(ticks)):
        xo[j], xn[j] = cur_o, cur_n
        c = max(idx[j], 0)
        cur_o = cmd_o[c] + (cur_o - cmd_o[c]) * decay
        cur_n = cmd_n[c] + (cur_n - cmd_n[c]) * decay
        cur_n /= np.linalg.norm(cur_n)
    # actual sheet at each exposure: first-order from the last tick toward that tick's command
    jj = np.clip(np.searchsorted(ticks, tk, side="right") - 1, 0, len(ticks) - 1)
    cj = np.clip(idx[jj], 0, None)
    w = np.exp(-(tk - ticks[jj]) / latency.servo_tau)[:, None]
    so = cmd_o[cj] + (xo[jj] - cmd_o[cj]) * w
    sn = cmd_n[cj] + (xn[jj] - cmd_n[cj]) * w
    sn /= np.linalg.norm(sn, axis=1, keepdims=True)
    moving = (tk >= finger.t_move) & (tk < finger.t_move + moving_time)
    D = true_p if truth else meas
    return table1_row(shape, D[moving], so[moving], sn[moving])


def _mean_rows(rows: list[dict[str, float]]) -> dict[str, float]:
    keys = [k for k in rows[0] if k != "n"]
    r = {k: float(np.mean([x[k] for x in rows])) for k in keys}
    r["n"] = int(sum(x["n"] for x in rows))
    r["seeds"] = len(rows)
    return r


def run(out: Path, seeds: int = 3, quick: bool = False) -> dict:
    """Run Table I, the sweeps and the chart; write summary.json, stroke_errors.json/png under ``out``."""
    lat = LatencyModel()
    bud = lat.budget()
    summary: dict = {"paper": PAPER_TABLE1, "latency_model": asdict(lat),
                     "latency_budget_ms": round(bud["total"] * 1e3, 3),
                     "latency_parts_ms": {k: round(v * 1e3, 3) for k, v in bud.items()},
                     "targets": {**target("10"), "at_moving_time_s": 10}}
    lk = launch_kf()
    for T in (10.0, 30.0):
        key = str(int(T))
        summary[key] = _mean_rows([simulate(T, True, lat, s) for s in range(seeds)])
        summary[key]["prediction"] = True
        summary[f"{key}_no_prediction"] = _mean_rows([simulate(T, False, lat, s) for s in range(seeds)])
        summary[f"{key}_truth_D"] = _mean_rows([simulate(T, True, lat, s, truth=True) for s in range(seeds)])
        summary[f"{key}_no_tremor"] = _mean_rows([simulate(T, True, lat, s, finger_kw={"tremor_rms": 0.0})
                                                  for s in range(seeds)])
        if lk is not None:
            summary[f"{key}_launch_kf"] = _mean_rows([simulate(T, True, lat, s, q=lk["q"], horizon=lk["horizon_s"])
                                                      for s in range(seeds)])
    if lk is not None:
        summary["launch_kf"] = {"file": SIM_LAUNCH.name, **lk}
    t10, tg = summary["10"], target("10")
    summary["meets_target_10s"] = bool(t10["dd_mean_mm"] <= tg["dd_mean_mm"] and
                                       t10["dtheta_mean_deg"] <= tg["dtheta_mean_deg"])

    times = [5.0, 10.0, 30.0, 60.0] if quick else [5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0]
    scales = [0.5, 1.0, 2.0, 4.0] if quick else [0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0]
    sweep_s = max(1, seeds - 1) if not quick else 1
    chart: dict = {"moving_time_s": times, "latency_scale": scales, "latency_ms": [], "by_time": {}, "by_latency": {}}
    for pred in (True, False):
        key = "prediction" if pred else "no_prediction"
        chart["by_time"][key] = [_mean_rows([simulate(T, pred, lat, s) for s in range(sweep_s)]) for T in times]
        rows = []
        for sc in scales:
            L = replace(lat, scale=sc)
            rows.append(_mean_rows([simulate(10.0, pred, L, s) for s in range(sweep_s)]))
        chart["by_latency"][key] = rows
    chart["latency_ms"] = [replace(lat, scale=sc).budget()["total"] * 1e3 for sc in scales]
    tremor = [0.0, 2.5e-5, 5e-5, 1e-4, 2e-4]
    chart["tremor_rms_mm"] = [x * 1e3 for x in tremor]
    chart["by_tremor"] = [_mean_rows([simulate(10.0, True, lat, s, finger_kw={"tremor_rms": x}) for s in range(sweep_s)])
                          for x in tremor]
    summary["sweeps"] = "stroke_errors.json"

    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "stroke_errors.json").write_text(json.dumps(chart, indent=2))
    _plot(chart, summary, out / "stroke_errors.png")
    return summary


def _plot(chart: dict, summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    for key, style in (("prediction", "o-"), ("no_prediction", "s--")):
        rows = chart["by_time"][key]
        ax[0, 0].plot(chart["moving_time_s"], [r["dd_mean_mm"] for r in rows], style, label=key.replace("_", " "))
        ax[1, 0].plot(chart["moving_time_s"], [r["dtheta_mean_deg"] for r in rows], style, label=key.replace("_", " "))
        rows = chart["by_latency"][key]
        ax[0, 1].plot(chart["latency_ms"], [r["dd_mean_mm"] for r in rows], style, label=key.replace("_", " "))
        ax[1, 1].plot(chart["latency_ms"], [r["dtheta_mean_deg"] for r in rows], style, label=key.replace("_", " "))
    for T, mk in (("10", "*"), ("30", "P")):
        ax[0, 0].plot(float(T), PAPER_TABLE1[T]["dd_mean_mm"], mk, color="k", ms=12, label=f"paper {T} s")
        ax[1, 0].plot(float(T), PAPER_TABLE1[T]["dtheta_mean_deg"], mk, color="k", ms=12, label=f"paper {T} s")
    tg, lbl = target("10"), f"target (paper 10 s / {TARGET_FACTOR:g})"
    ax[0, 0].axhline(tg["dd_mean_mm"], color="r", lw=0.8, ls=":", label=lbl)
    ax[1, 0].axhline(tg["dtheta_mean_deg"], color="r", lw=0.8, ls=":", label=lbl)
    ax[0, 1].axvline(summary["latency_budget_ms"], color="gray", lw=0.8, ls=":", label="budget")
    ax[1, 1].axvline(summary["latency_budget_ms"], color="gray", lw=0.8, ls=":", label="budget")
    ax[0, 0].set(xlabel="moving time 0→60° [s]", ylabel="mean Δd [mm]", yscale="log", title="Δd vs moving time")
    ax[1, 0].set(xlabel="moving time 0→60° [s]", ylabel="mean Δθ [deg]", yscale="log", title="Δθ vs moving time")
    ax[0, 1].set(xlabel="loop latency exposure→sheet [ms]", ylabel="mean Δd [mm]", title="Δd vs latency (10 s stroke)")
    ax[1, 1].set(xlabel="loop latency exposure→sheet [ms]", ylabel="mean Δθ [deg]", title="Δθ vs latency (10 s stroke)")
    for a in ax.flat:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle("Stroking the paper's cylinder: sheet error (Fig. 9 definitions), in-process latency model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """CLI entry: ``flexsheet experiment stroke --out DIR [--seeds N] [--quick]``. Returns 0."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment stroke", description=__doc__.split("\n")[0],
        epilog="example: flexsheet experiment stroke --out docs/figures/planner",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=Path, help="output folder for summary.json and the chart")
    ap.add_argument("--seeds", type=int, default=3, help="finger/noise seeds averaged per Table I row (default 3)")
    ap.add_argument("--quick", action="store_true", help="fewer sweep points (for tests)")
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error(f"--seeds must be >= 1, got {a.seeds}")
    s = run(a.out, a.seeds, a.quick)
    for k in ("10", "30"):
        r, p = s[k], PAPER_TABLE1[k]
        print(f"{k:>3} s: dd {r['dd_mean_mm']:.4f}±{r['dd_std_mm']:.4f} mm (paper {p['dd_mean_mm']}±{p['dd_std_mm']}), "
              f"dθ {r['dtheta_mean_deg']:.4f}±{r['dtheta_std_deg']:.4f} deg (paper {p['dtheta_mean_deg']}±{p['dtheta_std_deg']})")
    print(f"latency budget {s['latency_budget_ms']:.1f} ms; meets 4x target at 10 s: {s['meets_target_10s']}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
