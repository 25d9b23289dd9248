"""``flexsheet experiment stroke_model``: the paper's Table I in-process, on the honest twin, with a latency
model of the real loop and the arms' own chain (IK, command stream, servo, true kinematics).

The scripted finger (:class:`flexsheet.twin.finger.FingerScript`) follows the target mark from 0° to 60°
around the paper's cylinder. A camera samples it at 48 Hz (BumbleBee2) with the triangulation noise of the
stereo geometry (:meth:`flexsheet.vision.stereo.StereoModel.covariance` of the *true* camera at the fingertip
for a marker-centre noise ``marker_px`` per image coordinate) and drops frames at rate ``dropout``; the
triangulator's own constant-velocity Kalman filter (:class:`flexsheet.vision.predict.ConstantVelocityKF`, fed
the covariance the triangulator computes for its ``sigma_px``) predicts the fingertip ``horizon`` s ahead; the
:class:`flexsheet.planning.surface_planner.SurfacePlanner` plans (a lost frame holds the last plan, as the
planner node does). The plan reaches the arm PCs after processing + network delay; each bridge solves IK with
the *estimator's* model (the nominal RV-1A URDF at the calibrated base pose, ``display.yaml``), streams it
through its limiter (:class:`flexsheet.arm.limiter.StreamLimiter`), the controller twin executes it one 7.1 ms
tick later through its servo (:class:`flexsheet.twin.servo.JointServo`), and the *true* sheet is where the
truth's kinematics (:meth:`flexsheet.twin.truth.TwinTruth.clamp_pose`) put the clamps at each exposure. The
Table I row (Fig. 9, :func:`flexsheet.analysis.table1.table1_row`, the report's metric) is computed over the
moving phase from the valid measurements.

Twins (:mod:`flexsheet.twin.truth`): ``realistic`` (default; truth drawn per seed, ``marker_px`` = 0.1 px)
and ``ideal`` (nominal truth, ``marker_px`` = 0.025 px), three truth seeds each; the finger and noise seeds
follow the truth seed. The triangulator's filter and the planner's ``use_prediction`` are read from
``launch/sim.yaml`` (:class:`flexsheet.vision.tracker.TrackerConfig`'s defaults where it sets none): the
in-process rows and the full graph use one filter.

Outputs in ``--out DIR``: ``summary.json`` (Table I rows keyed by moving time "10", "30" — the realistic
twin, mean of the seeds, with ``per_seed``, Δd on R and in the paper's 2R convention — ``ideal`` (the same
for the ideal twin), the 10 s variant rows ``10_no_prediction``, ``10_truth_D``, ``10_filtered_D``,
``10_no_camera_noise``, ``10_q_tracking_index_0.1`` (the filter tuned for the realistic noise), the
``noise_floor``, the paper's values, the latency budget, the filter and the estimator's source), and
``stroke_errors.png``/``.json`` (Δθ and Δd against moving time and loop latency, realistic twin seed 0).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from flexsheet.analysis.table1 import DD_CONVENTION, PAPER_TABLE1, table1_row, target
from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.chain import bridge_chain
from flexsheet.arm.kinematics import QD_MAX, home_joints
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.dirs import launch_dir
from flexsheet.experiments.stroke_model_chart import plot as plot_chart
from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder
from flexsheet.model.sheet import frame_from_clamps
from flexsheet.planning.plan import Hold
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.shape import planner_shape
from flexsheet.planning.surface_planner import SurfacePlanner
from flexsheet.twin.finger import FingerScript
from flexsheet.twin.servo import JointServo, ServoParams
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.predict import Predictor, q_for_tracking_index
from flexsheet.vision.stereo import StereoModel
from flexsheet.vision.tracker import TrackerConfig

__all__ = ["LatencyModel", "ArmChain", "Twin", "launch_kf", "make_twin",
           "simulate", "run", "main", "MARKER_PX"]

#: the launch file whose triangulator/planner settings the in-process rows use
SIM_LAUNCH = launch_dir() / "sim.yaml"
#: marker-centre noise per image coordinate, px, by twin: realistic = the level the vision bench assumes for
#: a real camera (0.1 px → ≈ 0.38 mm rms at 0.5 m, ``docs/figures/vision``); ideal = the old camera twin
#: (0.02–0.03 px). Replace the realistic value by the camera twin's measured one when it is known.
MARKER_PX = {"realistic": 0.1, "ideal": 0.025}


@dataclass(frozen=True)
class LatencyModel:
    """Loop latency parts, s.

    ``camera_period`` 1/48 s (BumbleBee2 at 48 Hz). ``exposure_to_host``: mid-exposure to frame in host
    memory — half a ~2 ms shutter plus the IEEE-1394b transfer of a 2×640×480 8-bit pair (614 kB at
    ~80 MB/s ≈ 7.7 ms): 8 ms. ``processing``: marker detection, triangulation and planning: 3 ms (see
    ``flexsheet bench vision`` / ``bench planner``). ``network``: one LAN hop main PC → arm PC: 1 ms.
    ``servo_period``: RV-1A external-control period 7.1 ms; a target waits for the next tick (mean half a
    period), executes one tick later (``pipeline_ticks``), and the joint servo lags it by ``servo_tau``
    (0.015 s, the controller twin's first-order lag, ``nodes/arm_controller_sim``; in the simulation the
    servo also obeys the datasheet speed and acceleration limits, :class:`ArmChain`). ``scale`` multiplies
    every software/transport delay (latency sweep).
    """

    camera_period: float = 1.0 / 48.0
    exposure_to_host: float = 0.008
    processing: float = 0.003
    network: float = 0.001
    servo_period: float = 0.0071
    pipeline_ticks: int = 1
    servo_tau: float = 0.015
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


@dataclass(frozen=True)
class ArmChain:
    """The arm side as the bridge (defaults: :class:`~flexsheet.arm.bridge_config.BridgeConfig`'s, their one
    owner) and the controller twin run it: the stream's ``speed_scale``/``accel_scale`` (× the URDF's speeds;
    accel = scale × speed per s), ``limit_margin``, ``max_ik_jump`` rad, ``target_timeout`` s; the twin's
    ``ctrl_speed_scale`` and ``ctrl_accel_factor`` (servo limits)."""

    speed_scale: float = BridgeConfig.speed_scale
    accel_scale: float = BridgeConfig.accel_scale
    limit_margin: float = BridgeConfig.limit_margin
    max_ik_jump: float = BridgeConfig.max_ik_jump
    target_timeout: float = BridgeConfig.target_timeout
    ctrl_speed_scale: float = 1.0
    ctrl_accel_factor: float = 4.0


@dataclass
class Twin:
    """One twin the stroke runs on: ``truth`` (hidden; only the arms' true FK and the true camera's noise
    geometry are taken from it), ``bases`` side → (4, 4) the *estimator's* base poses, ``bases_source``
    (where they came from), ``marker_px`` px, ``dropout`` (probability a frame is lost), ``label``."""

    truth: TwinTruth
    bases: dict[str, np.ndarray]
    bases_source: str
    marker_px: float
    dropout: float = 0.0
    label: str = ""
    _stereo: StereoModel | None = field(default=None, repr=False)

    def stereo(self) -> StereoModel:
        """The true stereo camera (for the measurement noise)."""
        if self._stereo is None:
            self._stereo = StereoModel.from_calib(self.truth.camera_calib)
        return self._stereo


def make_twin(realism: str, seed: int, display_calib: str | None = None, marker_px: float | None = None,
              dropout: float = 0.0) -> Twin:
    """The twin of ``realism`` and truth ``seed``. Estimator bases: the ``arms`` entries of ``display_calib``
    (a path; ``{seed}`` is replaced by the seed) when given and present, else the nominal bases
    (:func:`flexsheet.calibration.display_calib.nominal_display_calib`). ``marker_px`` defaults to
    :data:`MARKER_PX` of the realism. Raises ``ValueError`` for a file that is given but unreadable."""
    truth = TwinTruth.draw(int(seed), realism)
    if display_calib:
        path = display_calib.replace("{seed}", str(seed))
        dc = load_display_calib(path, require=("arms.left", "arms.right"))
        bases = {s: dc.arms[s].T_display_base.copy() for s in ("left", "right")}
        src = f"display.yaml ({path})"
    else:
        nom = nominal_display_calib()
        bases = {s: nom.arms[s].T_display_base.copy() for s in ("left", "right")}
        src = "nominal (no display.yaml: the estimator uses the design bases; the truth differs from them)"
    px = MARKER_PX[realism] if marker_px is None else float(marker_px)
    return Twin(truth, bases, src, px, float(dropout), f"{realism} seed {seed}")


def launch_kf(path: Path = SIM_LAUNCH) -> dict:
    """The triangulator's ``tracking_index``, ``horizon_s``, ``sigma_px`` and the planner's ``use_prediction``
    in launch file ``path`` (the nodes' defaults for keys it does not set; all defaults when the file or node
    is missing), plus ``file`` (the file name, or ``None``)."""
    d = TrackerConfig()
    out = {"tracking_index": d.tracking_index, "horizon_s": d.horizon_s, "sigma_px": d.sigma_px,
           "use_prediction": False, "file": None}
    try:
        nodes = yaml.safe_load(path.read_text())["nodes"]
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        return out
    tri = ((nodes.get("triangulator") or {}).get("params") or {})
    pl = ((nodes.get("planner") or {}).get("params") or {})
    out.update(tracking_index=float(tri.get("tracking_index", d.tracking_index)),
               horizon_s=float(tri.get("horizon_s", d.horizon_s)),
               sigma_px=float(tri.get("sigma_px", d.sigma_px)),
               use_prediction=bool(pl.get("use_prediction", False)),
               file=path.name)
    return out


def _camera_cov(twin: Twin, X_display: np.ndarray, sigma_px: float) -> np.ndarray:
    """(N, 3, 3) m² triangulation covariance of display-frame points for pixel noise σ, true camera."""
    T = twin.truth.T_display_camera
    R = T[:3, :3]
    Xc = (X_display - T[:3, 3]) @ R
    C = twin.stereo().covariance(Xc, sigma_px)
    return np.einsum("ij,njk,lk->nil", R, C, R)


def _measure(twin: Twin, finger, rng, Tc: float):
    """The camera's exposures: times tk (s), the true fingertip, its measurement (the triangulation's noise
    for the twin's marker σ) and which measurements are valid (the twin's dropout; the first always)."""
    tk = np.arange(0.0, finger.duration, Tc) + rng.uniform(0, Tc)
    true_p = finger.positions(tk)
    if twin.marker_px > 0.0:
        C = _camera_cov(twin, true_p, twin.marker_px)
        meas = true_p + np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.normal(size=true_p.shape))
    else:
        meas = true_p.copy()
    valid = rng.uniform(size=len(tk)) >= twin.dropout
    valid[0] = True
    return tk, true_p, meas, valid


def _plan_stroke(tk, true_p, meas, valid, Rf, kf: Predictor, planner, h: float, use_prediction: bool,
                 delay_to_arm: float, record: list | None):
    """The planner over the exposures (the Kalman prediction ``h`` s ahead, or the measurement): the plans'
    arrival times at the arms, their clamp matrices, and the filtered positions."""
    arrivals, clamps = [], []
    filt = meas.copy()
    for i, t in enumerate(tk):
        if valid[i]:
            kf.update(t, meas[i], Rf[i])
            filt[i] = kf.predict(0.0)
            p = kf.predict(h) if use_prediction else meas[i]
            plan = planner.update(t, p)
        else:
            plan = planner.hold(Hold.MARKER_LOST, t)
        if plan is None:
            continue
        if record is not None:
            record.append((float(t), true_p[i], plan))
        arrivals.append(t + delay_to_arm)
        clamps.append(plan.clamp_matrices())
    return np.asarray(arrivals), clamps, filt


def _arm_chains(twin: Twin, chain: ArmChain, latency: LatencyModel, first_clamps, Ts: float) -> dict:
    """Per side (target tracker on the estimator's kinematics, stream limiter, servo), at rest on the first
    plan."""
    chains = {}
    sp = ServoParams(tau=latency.servo_tau, qd_max=QD_MAX * chain.ctrl_speed_scale,
                     qdd_max=QD_MAX * chain.ctrl_speed_scale * chain.ctrl_accel_factor)
    cfg = replace(BridgeConfig(), span_band=None, **{k: getattr(chain, k) for k in (
        "speed_scale", "accel_scale", "limit_margin", "max_ik_jump", "target_timeout")})
    for k, side in enumerate(("left", "right")):
        arm = bridge_chain(side, twin.bases[side], Ts, cfg)
        tracker, lim = arm.tracker, arm.limiter
        tracker.seed(home_joints(side))
        res = tracker.set_target(first_clamps[k], 0.0, 0.0)       # start at rest on the first plan
        q0 = res.q if res.ok else home_joints(side)
        lim.reset(q0)
        chains[side] = (tracker, lim, JointServo(q0, sp))
    return chains


def _drive_arms(chains: dict, ticks, eff, clamps, Ts: float) -> tuple[dict, float]:
    """The servos over the controller ticks (IK of the newest arrived plan): joints per tick and side, and the
    largest |q̇| / datasheet speed."""
    Q = {side: np.empty((len(ticks), 6)) for side in chains}
    vmax = 0.0
    last = -1
    for j, tj in enumerate(ticks):
        if eff[j] > last:                       # new target(s) since the last tick: IK of the newest
            last = eff[j]
            for k, side in enumerate(("left", "right")):
                chains[side][0].set_target(clamps[last][k], 0.0, tj)
        for side, (tracker, lim, servo) in chains.items():
            Q[side][j] = servo.q
            ref = tracker.reference(tj, lim.c) if last >= 0 else (lim.c, None)
            servo.step(lim.step(*ref), Ts)
            vmax = max(vmax, float(np.max(np.abs(servo.v) / QD_MAX)))
    return Q, vmax


def _true_sheet(twin: Twin, tk, idx, ticks, Q: dict, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The true sheet (origin, normal) at the exposures ``tk[idx]``: joints interpolated between ticks, the
    truth's forward kinematics."""
    so = np.empty((idx.size, 3))
    sn = np.empty((idx.size, 3))
    for n, i in enumerate(idx):
        j = int(np.clip(np.searchsorted(ticks, tk[i], side="right") - 1, 0, len(ticks) - 2))
        w = (tk[i] - ticks[j]) / Ts
        Tl = twin.truth.clamp_pose("left", (1 - w) * Q["left"][j] + w * Q["left"][j + 1])
        Tr = twin.truth.clamp_pose("right", (1 - w) * Q["right"][j] + w * Q["right"][j + 1])
        so[n], sn[n], _, _ = frame_from_clamps(Tl, Tr)
    return so, sn


def simulate(moving_time: float, twin: Twin, latency: LatencyModel | None = None, seed: int = 0, *,
             use_prediction: bool = True, finger_kw: dict | None = None, horizon: float | None = None,
             q: float | None = None, sigma_px_filter: float | None = None, d_source: str = "measured",
             chain: ArmChain | None = None, stats: dict | None = None, scene=None, compliance=None,
             planner_config: PlannerConfig | None = None, record: list | None = None) -> dict[str, float]:
    """Run one stroke on ``twin`` and return the Table I row (:func:`flexsheet.analysis.table1.table1_row`)
    over the moving phase, from the valid measurements. ``horizon`` (s, default: the latency budget plus the
    mean target hold), ``q`` (m²/s³, default: the launch file's) and ``sigma_px_filter`` (the covariance the
    triangulator assumes, default: the launch file's) set the filter. ``d_source``: D is the ``measured``
    fingertip (the paper's definition, default), the ``truth`` or the Kalman-``filtered`` position (variants
    that show what the measurement noise in D costs). ``stats``: if a dict, gets ``peak_joint_speed_ratio``
    (largest |q̇| / datasheet speed of either servo), ``ik_refused`` and ``dropped``. ``scene`` (a
    :class:`flexsheet.model.scenes.Scene`; ``None``: the paper's cylinder as before): the object, the finger's
    path (:class:`~flexsheet.twin.finger.FingerScript` on the scene) and the metric's section
    (:func:`flexsheet.analysis.table1.scene_table1_row`). ``compliance``: the planner's stiffness model (e.g.
    :class:`flexsheet.planning.compliance.SceneCompliance`; ``None``: the config's ``object_stiffness``);
    ``planner_config``: the planner's :class:`PlannerConfig`; ``record``: if a list, gets one
    ``(t s, true fingertip (3,) m, Plan)`` per planned sample. Raises ``ValueError`` for an unknown
    ``d_source``."""
    if d_source not in ("measured", "truth", "filtered"):
        raise ValueError(f"d_source must be measured, truth or filtered, got {d_source!r}")
    latency = latency or LatencyModel()
    chain = chain or ArmChain()
    lk = launch_kf()
    if scene is None:
        shape = paper_cylinder()
    else:
        shape = planner_shape(scene)
    finger = FingerScript(moving_time=moving_time, seed=seed, scene=scene, **(finger_kw or {}))
    rng = np.random.default_rng(1000 + seed)
    tk, true_p, meas, valid = _measure(twin, finger, rng, latency.camera_period)
    bud = latency.budget()
    h = (bud["total"] + bud["target_hold_mean"]) if horizon is None else horizon
    sig_f = lk["sigma_px"] if sigma_px_filter is None else sigma_px_filter
    Rf = _camera_cov(twin, meas, sig_f)  # the covariance the triangulator reports for its sigma_px
    if q is None:   # the tracker's rule (q from its tracking index) on the noise the filter assumes
        q = q_for_tracking_index(lk["tracking_index"], _tangential_noise(twin, sig_f), latency.camera_period)
    kf = Predictor(q, v0_std=TrackerConfig.v0_std)
    planner = SurfacePlanner(shape, planner_config or PlannerConfig(), compliance)
    s = latency.scale
    delay_to_arm = s * (latency.exposure_to_host + latency.processing + latency.network)
    arrivals, clamps, filt = _plan_stroke(tk, true_p, meas, valid, Rf, kf, planner, h, use_prediction,
                                          delay_to_arm,
                                          record)
    # arms: IK at arrival (estimator model), limiter + servo per controller tick, true FK
    Ts = latency.servo_period
    ticks = np.arange(rng.uniform(0, Ts), finger.duration + Ts, Ts)
    eff = np.searchsorted(arrivals, ticks - latency.pipeline_ticks * Ts, side="right") - 1
    chains = _arm_chains(twin, chain, latency, clamps[0], Ts)
    Q, vmax = _drive_arms(chains, ticks, eff, clamps, Ts)
    # true sheet at each exposure: joints interpolated between ticks, the truth's forward kinematics
    moving = (tk >= finger.t_move) & (tk < finger.t_move + moving_time) & valid
    idx = np.flatnonzero(moving)
    so, sn = _true_sheet(twin, tk, idx, ticks, Q, Ts)
    if stats is not None:
        stats.update(peak_joint_speed_ratio=vmax, ik_refused=int(sum(c[0].refused for c in chains.values())),
                     dropped=int((~valid).sum()))
    D = {"measured": meas, "truth": true_p, "filtered": filt}[d_source]
    if scene is not None:
        return table1_row(shape, D[idx], so, sn, scene)
    return table1_row(shape, D[idx], so, sn)


def _mean_rows(rows: list[dict[str, float]]) -> dict:
    keys = [k for k in rows[0] if k != "n"]
    r: dict = {k: float(np.mean([x[k] for x in rows])) for k in keys}
    r["n"] = int(sum(x["n"] for x in rows))
    r["seeds"] = len(rows)
    return r


def table_rows(realism: str, seeds: int, display_calib: str | None = None,
               latency: LatencyModel | None = None,
               times=(10.0, 30.0), **kw) -> dict:
    """Table I rows of ``realism`` over truth seeds 0…``seeds``−1: ``{"10": mean row with per_seed, …}``.
    ``kw`` go to :func:`simulate` (``marker_px``/``dropout`` go to :func:`make_twin`)."""
    tw_kw = {k: kw.pop(k) for k in ("marker_px", "dropout") if k in kw}
    out: dict = {}
    for T in times:
        rows = []
        for s in range(seeds):
            tw = make_twin(realism, s, display_calib, **tw_kw)
            st: dict = {}
            row = simulate(T, tw, latency, s, stats=st, **kw)
            row.update({k: float(v) for k, v in st.items()})
            rows.append(row)
        mean = _mean_rows(rows)
        mean["per_seed"] = [{"truth_seed": s, "dtheta_mean_deg": r["dtheta_mean_deg"],
                             "dd_mean_mm": r["dd_mean_mm"],
                             "dd_2r_mean_mm": r["dd_2r_mean_mm"],
                             "peak_joint_speed_ratio": r["peak_joint_speed_ratio"]}
                            for s, r in enumerate(rows)]
        out[f"{T:g}"] = mean
    return out


def run(out: Path, seeds: int = 3, quick: bool = False, display_calib: str | None = None) -> dict:
    """Table I on both twins, the variants, the sweeps and the chart; writes summary.json,
    stroke_errors.json/png under ``out``."""
    lat = LatencyModel()
    bud = lat.budget()
    lk = launch_kf()
    use_pred = bool(lk["use_prediction"])
    real = table_rows("realistic", seeds, display_calib, lat, use_prediction=use_pred)
    ideal = table_rows("ideal", seeds, None, lat, use_prediction=use_pred)
    tw0 = make_twin("realistic", 0, display_calib)
    summary: dict = {"paper": PAPER_TABLE1, "dd_convention": DD_CONVENTION, "latency_model": asdict(lat),
                     "arm_chain": asdict(ArmChain()), "latency_budget_ms": round(bud["total"] * 1e3, 3),
                     "latency_parts_ms": {k: round(v * 1e3, 3) for k, v in bud.items()},
                     "targets": {"10": target("10"), "30": target("30")},
                     "filter": {**lk, "note": "the launch file's triangulator/planner settings, as the full "
                                              "graph"},
                     "twin": {"realism": "realistic", "truth_seeds": list(range(seeds)),
                              "estimator_bases": tw0.bases_source, "marker_px": MARKER_PX},
                     **real, "ideal": ideal}
    q_tuned = q_for_tracking_index(0.1, _tangential_noise(tw0, MARKER_PX["realistic"]), lat.camera_period)
    variants = {"no_prediction": {"use_prediction": False},
                "truth_D": {"d_source": "truth", "use_prediction": use_pred},
                "filtered_D": {"d_source": "filtered", "use_prediction": use_pred},
                "no_camera_noise": {"marker_px": 0.0, "use_prediction": use_pred},
                "q_tracking_index_0.1": {"q": q_tuned, "use_prediction": use_pred}}
    summary["filter"]["q_tracking_index_0.1"] = q_tuned
    vs = 1 if quick else seeds
    if quick:
        variants = {k: v for k, v in variants.items() if k == "no_prediction"}
    for name, kw in variants.items():
        for k, row in table_rows("realistic", vs, display_calib, lat, times=(10.0,), **kw).items():
            summary[f"{k}_{name}"] = row
    for key in ("10", "30"):
        tg = target(key)
        summary[f"meets_target_{key}s"] = bool(summary[key]["dtheta_mean_deg"] <= tg["dtheta_mean_deg"])
    sig_t = _tangential_noise(tw0, MARKER_PX["realistic"])
    summary["noise_floor"] = {
        "tangential_noise_mm": sig_t * 1e3,
        "dtheta_floor_deg": math.degrees(math.sqrt(2.0 / math.pi) * sig_t / paper_cylinder().R),
        "note": "mean |Δθ| from the measured D's own noise alone: √(2/π)·σ_t/R (σ_t: the rms measurement "
                "noise tangent to the cylinder in the stroke plane); the sheet cannot follow white noise"}

    times = [5.0, 10.0] if quick else [5.0, 10.0, 20.0, 30.0, 60.0]
    scales = [0.5, 4.0] if quick else [0.25, 0.5, 1.0, 2.0, 4.0]
    chart: dict = {"moving_time_s": times, "latency_scale": scales, "latency_ms": [], "by_time": {},
                   "by_latency": {}}
    for pred in (True, False):
        key = "prediction" if pred else "no_prediction"
        chart["by_time"][key] = [simulate(T, tw0, lat, 0, use_prediction=pred) for T in times]
        chart["by_latency"][key] = [simulate(10.0, tw0, replace(lat, scale=sc), 0, use_prediction=pred)
                                    for sc in scales]
    chart["latency_ms"] = [replace(lat, scale=sc).budget()["total"] * 1e3 for sc in scales]
    summary["sweeps"] = "stroke_errors.json (realistic twin, truth seed 0)"

    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "stroke_errors.json").write_text(json.dumps(chart, indent=2))
    plot_chart(chart, summary, out / "stroke_errors.png")
    return summary


def _tangential_noise(twin: Twin, marker_px: float) -> float:
    """RMS measurement noise (m) tangent to the cylinder in the stroke plane, averaged over the stroke."""
    f = FingerScript()
    t = np.linspace(f.t_move, f.t_move + f.moving_time, 50)
    X = f.positions(t)
    C = _camera_cov(twin, X, marker_px)
    r = X - geometry.CYLINDER_CENTER
    r[:, 1] = 0.0
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    tang = np.cross(np.array([0.0, 1.0, 0.0]), r)
    return float(np.sqrt(np.mean(np.einsum("ni,nij,nj->n", tang, C, tang))))


def main(argv: list[str] | None = None) -> int:
    """CLI entry: ``flexsheet experiment stroke_model --out DIR [--seeds N] [--quick] [--display-calib
    PATH]``."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment stroke_model", description=__doc__.split("\n")[0],
        epilog="example: flexsheet experiment stroke_model --out docs/figures/planner\n"
               "         flexsheet calibrate display --sim --truth-seed 0 --out out/cal0   # a display.yaml "
               "per seed\n         flexsheet experiment stroke_model --out /tmp/s --seeds 1 "
               "--display-calib 'out/cal{seed}/display.yaml'",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=Path, help="output folder for summary.json and the chart")
    ap.add_argument("--seeds", type=int, default=3, help="truth seeds per twin (default 3)")
    ap.add_argument("--quick", action="store_true", help="fewer sweep points, one variant row (for tests)")
    ap.add_argument("--display-calib", default=None,
                    help="display.yaml with the calibrated arm bases ({seed} → truth seed); default: nominal "
                         "bases")
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error(f"--seeds must be >= 1, got {a.seeds}")
    for seed in range(a.seeds) if a.display_calib else ():
        if not Path(a.display_calib.replace("{seed}", str(seed))).is_file():
            ap.error(f"--display-calib: no {a.display_calib.replace('{seed}', str(seed))} for truth seed "
                     f"{seed} (flexsheet calibrate display --sim --truth-seed {seed} --out DIR writes one)")
    s = run(a.out, a.seeds, a.quick, a.display_calib)
    print(DD_CONVENTION)
    for tw, rows in (("realistic", s), ("ideal", s["ideal"])):
        for k in ("10", "30"):
            r, p = rows[k], PAPER_TABLE1[k]
            print(f"{tw:>9} {k:>3} s: dθ {r['dtheta_mean_deg']:.4f}±{r['dtheta_std_deg']:.4f} deg "
                  f"(paper {p['dtheta_mean_deg']}, target {target(k)['dtheta_mean_deg']:.4f}); dd 2R "
                  f"{r['dd_2r_mean_mm']:.4f} mm (paper {p['dd_mean_mm']}), dd R {r['dd_mean_mm']:.4f} mm; "
                  f"seeds {[round(x['dtheta_mean_deg'], 4) for x in r['per_seed']]}")
    print(f"estimator bases: {s['twin']['estimator_bases']}; filter {s['filter']['file']}: tracking index "
          f"{s['filter']['tracking_index']}, "
          f"horizon {s['filter']['horizon_s']} s; floor {s['noise_floor']['dtheta_floor_deg']:.4f} deg")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
