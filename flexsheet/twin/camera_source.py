"""The stereo camera port's simulated side (``source: sim``): the camera twin.

It renders the fingertip marker at the world node's ``/world/finger`` position, extrapolated to the exposure
time with its velocity (at most 0.1 s), or along the params' trajectory until a world node first publishes —
never after: a world node that stalls or is respawned leaves the finger where it last was (a real finger does
not jump to another path). The images are formed through the hidden truth (the node's ``twin: {realism,
truth_seed}`` → :meth:`flexsheet.twin.truth.TwinTruth.draw`): the truth's stereo intrinsics and distortion
(``model: ximea``; another model renders with its own calibration), its mount and marker size, the realistic
sensor of :class:`flexsheet.twin.camera_config.SimConfig` (``ideal`` → :meth:`SimConfig.ideal`); a
``drop_rate`` fraction of the frames is lost on the link (never published, counted). The sensing params left
unset (``null``) take the realism's value. ``stereo_skew`` is 0: both views are rendered at one instant.

The registration scenes a lab sets up by hand (:mod:`flexsheet.twin.registration_scene`: the board on the
sheet, the projector's patterns, the dark room for the clamp markers) are switched by the service
``twin/scene``; the sheet follows the arms' joint states and the light ``/projector/image``. See
:mod:`flexsheet.vision.camera_port`.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from dataclasses import replace

import numpy as np

from flexsheet.model.timing import LAB
from flexsheet.runtime.qos import QoS
from flexsheet.twin.camera import default_trajectory, twin_renderer
from flexsheet.twin.camera_config import REALISTIC_DROP_RATE, SimConfig
from flexsheet.vision.camera_port import CameraHost, CameraSource
from messages import FingerTruth, ProjectorImage, topics

__all__ = ["TwinCamera", "sim_config"]


def sim_config(p) -> SimConfig:
    """The twin's :class:`SimConfig` for camera params ``p``: the realism's preset (:class:`SimConfig` or
    :meth:`SimConfig.ideal`) with every sensing param that is set (not ``None``) overriding it."""
    base = SimConfig() if p.twin.realism == "realistic" else SimConfig.ideal()
    over = {k: getattr(p, k)
            for k in ("noise_dn", "shot_gain", "blur_px", "self_occlusion", "background_gain",
                      "finger_dir") if getattr(p, k) is not None}
    cfg = replace(base, exposure_s=p.exposure_s, blur_samples=p.blur_samples, clutter=p.clutter, seed=p.seed,
                  noise_scale=p.noise_scale, **over)
    cfg.validate()
    return cfg


class TwinCamera(CameraSource):
    """The camera twin on its host (module doc)."""

    models_link_delay = True

    def __init__(self, host: CameraHost, truth, calib: dict):
        p = host.params
        self.host = host
        self._drop_rate = (REALISTIC_DROP_RATE if p.twin.realism == "realistic" else 0.0) \
            if p.drop_rate is None else float(p.drop_rate)
        self._drop_rng = np.random.default_rng([p.seed, p.twin.truth_seed, 31])
        # the true cameras: the truth's (drawn around the XIMEA calibration) or, for another model, its own
        self.renderer = twin_renderer(truth, sim_config(p), calib=None if p.model == "ximea" else calib)
        self._truth: FingerTruth | None = None
        self._truth_rx = -math.inf
        self._lock = threading.Lock()
        self._t0 = host.now()
        self.dropped = 0

    @classmethod
    async def open(cls, host: CameraHost, calib: dict) -> TwinCamera:
        """The twin of ``host.params.twin``'s truth; its inputs, services and frame timer on ``host``. Raises
        ``ValueError`` for a ``link_delay_s`` off the simulated clock."""
        p = host.params
        if p.link_delay_s > 0 and not host.clock.simulated:
            raise ValueError(f"link_delay_s {p.link_delay_s:g} is the camera twin's on the simulated clock "
                             "(launch file clock: sim)")
        from flexsheet.twin.truth import TwinTruth  # lazy: pinocchio, the twin only

        truth = TwinTruth.draw(p.twin.truth_seed, p.twin.realism)
        self = cls(host, truth, calib)
        host.subscribe(topics.FINGER_TRUTH, self.on_truth, qos=QoS.LATEST)
        self._registration_twin(truth)
        # simulated clock: the pair leaves readout + transfer after mid-exposure (flexsheet/model/timing.py)
        w, h = (int(v) for v in calib["image_size"])
        host.timer(1.0 / p.rate_hz, self.on_tick, sim_cost=LAB.camera_latency(p.exposure_s, w, h),
                   sim_delay=p.link_delay_s)
        return self

    @classmethod
    def exact_nominal_registration(cls, params) -> bool:
        """The ideal twin's camera is the nominal one exactly."""
        return params.twin.realism == "ideal"

    def _registration_twin(self, truth) -> None:
        """The registration scenes, switched by the service ``twin/scene`` (module doc)."""
        from flexsheet.twin.registration_scene import SCENES, RegistrationScene  # lazy: scipy.optimize

        host = self.host
        self.scene = RegistrationScene(truth, seed=host.params.seed)
        self._scene_lock = threading.Lock()
        self._projected: tuple[int, np.ndarray] | None = None
        self._projected_stamp: float | None = None
        # where the true arms are (the controller twins' readback), read per registration frame (sampled)
        self._arm_states = {side: host.sample(topics.arm_state(side)) for side in ("left", "right")}
        host.subscribe(topics.PROJECTOR_IMAGE, self.on_projector_image, qos=QoS.LATEST)
        host.service("twin/scene", self.srv_scene,
                     f"camera twin only: {{scene: {'|'.join(SCENES)}, board, square (m), offset (m)}}: what "
                     "the operator set up in front of the camera (registration); finger: the display running",
                     commanding=True)
        host.service("twin/state", self.srv_twin_state,
                     "camera twin only: {scene, projector_stamp (s: the /projector/image lighting the sheet "
                     "now, or null), now (s)}; a frame exposed after now shows that image")

    def srv_scene(self, args: dict) -> str:
        unknown = set(args) - {"scene", "board", "square", "offset"}
        if unknown:
            raise ValueError("twin/scene takes scene, board, square, offset; got "
                             f"{', '.join(sorted(unknown))}")
        with self._scene_lock:      # not while a frame of the old scene is being drawn
            return self.scene.set_scene(args.get("scene", ""), args.get("board", "chessboard:9x8"),
                                        args.get("square", 0.022), args.get("offset", 0.0))

    def srv_twin_state(self, args: dict) -> dict:
        with self._lock:
            stamp = self._projected_stamp
        return {"scene": self.scene.scene, "projector_stamp": stamp, "now": self.host.now()}

    def on_projector_image(self, msg: ProjectorImage) -> None:
        """Keep what the projector shows (its seq tells images apart)."""
        with self._lock:
            self._projected = (msg.header.seq, msg.image) if msg.showing else None
            self._projected_stamp = msg.header.stamp if msg.showing else None

    def _registration_frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        msgs = {side: sub.read() for side, sub in self._arm_states.items()}
        q = {side: m.position for side, m in msgs.items() if m is not None}
        with self._lock:
            projected = self._projected
        if len(q) < 2:
            self.host.log_limited(logging.WARNING, "camera twin: the registration scene waits for both arms' "
                                                   "joint states")
            return None
        with self._scene_lock:
            return self.scene.render(q["left"], q["right"], projected)

    def on_truth(self, msg: FingerTruth) -> None:
        """Keep the newest finger truth (position/velocity in the display frame)."""
        with self._lock:
            self._truth = msg
            self._truth_rx = self.host.now()

    def _marker_state(self, t: float) -> tuple[np.ndarray, np.ndarray, bool]:
        p = self.host.params
        with self._lock:
            truth = self._truth
        if truth is not None:       # held however old: falling back to the param path showed a second finger
            dt = min(max(t - truth.header.stamp, 0.0), 0.1)
            return truth.position + truth.velocity * dt, truth.velocity, truth.visible
        pos, vel = default_trajectory(t - self._t0, p.traj_amplitude_rad, p.traj_period_s, p.traj_hover_m)
        return pos, vel, True

    def _frame(self) -> None:
        t = self.host.now()
        if self._drop_rate > 0 and self._drop_rng.random() < self._drop_rate:
            self.dropped += 1            # the frame is lost on the link: nothing rendered, nothing published
            return
        if self.scene.scene != "finger":
            pair = self._registration_frame()
            if pair is not None:
                self.host.publish_pair(pair[0], pair[1], t)
            return
        pos, vel, visible = self._marker_state(t)
        left, right = self.renderer.render(pos, vel, visible)
        self.host.publish_pair(left, right, t)

    async def on_tick(self) -> None:
        """Render and publish one frame (in a worker thread, off the loop; on a simulated clock on the loop:
        the frame is due at its instant)."""
        if self.host.clock.simulated:
            self._frame()
        else:
            await asyncio.to_thread(self._frame)

    def status_line(self) -> str:
        tc = self.host.params.twin
        with self._lock:
            rx = self._truth_rx
        finger = ("finger: param trajectory (no /world/finger yet)" if not math.isfinite(rx)
                  else f"finger: /world/finger, last {self.host.now() - rx:.2f} s ago")
        return (f"sim ({tc.realism} twin, truth seed {tc.truth_seed}; {self.host.registration}): stereo_skew "
                f"0 (the twin renders both views at one instant); dropped {self.dropped} of "
                f"{self.host.frames + self.dropped} frames (drop_rate {self._drop_rate:g}); {finger}")
