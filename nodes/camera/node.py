"""Camera node: publishes synchronised raw stereo pairs (mono8) on ``/camera/stereo`` and the latched stereo
calibration on ``/camera/calibration``.

Sources (param ``source``): ``sim`` — the camera twin (:mod:`flexsheet.twin.camera`) rendering the
fingertip marker at the world node's ``/world/finger`` position (extrapolated to the exposure time with its velocity,
at most 0.1 s), or along a param trajectory until a world node first publishes — never after: a world node that
stalls or is respawned leaves the finger where it last was (a real finger does not jump to another path); ``genicam`` — a
GigE Vision / USB3 Vision pair through Aravis, opened by serial, hardware/software-triggered or PTP-synced,
stamped and paired by device timestamp (:mod:`nodes.camera.genicam`); ``device`` — UVC cameras through
``cv2.VideoCapture`` (:mod:`nodes.camera.device`); ``files`` — a folder of pairs (:mod:`nodes.camera.files`).

``stereo_skew`` in each :class:`messages.StereoFrame` by source (docs/camera.md): ``sim`` 0 (the twin
renders both views at one instant); ``genicam`` measured right − left device stamp (shared clock: PTP) or
the difference of the two mapped stamps (independent clocks); ``device`` 0 by construction for one
side-by-side device, an upper bound of |skew| for two devices; ``files`` 0 (unknown; the recording's).
``/diagnostics`` carries one line saying which, with the measured skew and dropped frames (GenICam).

Honest twin. ``/camera/calibration`` carries what a lab has: the camera's pose in the display frame
``T_display_camera`` from ``display.yaml``'s ``camera`` entry (param ``display_calib``, filled in by the launch
file's top-level ``display_calib:``) with the stereo model that pose was fitted with (the entry's, else the
stereo calibration file's: ``model``/``calib_file``). A missing ``display_calib`` is an error at start-up —
except for the *ideal* twin, whose nominal registration is exact. The sim source forms its images through the
hidden truth instead (param ``twin: {realism, truth_seed}`` → :meth:`flexsheet.twin.truth.TwinTruth.draw`):
the truth's stereo intrinsics and distortion (``model: ximea``; another model renders with its own
calibration), the truth's mount and marker size, the realistic sensor of
:class:`flexsheet.twin.camera_config.SimConfig` (``twin.realism: ideal`` → :meth:`SimConfig.ideal`), and drops
a ``drop_rate`` fraction of its frames (never published, counted in ``/diagnostics``). The sensing params
left unset (``null``) take the realism's value.
"""

from __future__ import annotations

import asyncio
import math
import threading
from dataclasses import replace
from itertools import pairwise

import cv2
import numpy as np
from pydantic import Field, model_validator

from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.timing import LAB
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.node import Node
from flexsheet.runtime.params import config_fields, params_model
from flexsheet.runtime.qos import QoS
from flexsheet.twin.camera import default_trajectory, twin_renderer
from flexsheet.twin.camera_config import REALISTIC_DROP_RATE, SimConfig
from flexsheet.vision.calib_yaml import load_yaml
from flexsheet.vision.camera_config import CameraConfig
from flexsheet.vision.camera_model import camera_model
from flexsheet.vision.stereo_calibration import to_message
from messages import FingerTruth, ProjectorImage, StereoFrame, topics
from nodes.camera.device import DeviceSource
from nodes.camera.files import FileSource
from nodes.camera.genicam import GenICamConfig, GenICamStereo, list_devices, resolve_device

__all__ = ["CameraParams", "CameraNode", "published_registration", "sim_config"]



def _genicam_ids(self):
    if self.source == "genicam":
        for key in ("left_id", "right_id"):
            if not getattr(self, key):
                raise ValueError(f"{key} must name a camera (serial number) when source is genicam")
        if self.left_id == self.right_id:
            raise ValueError(f"left_id and right_id are both {self.left_id!r}: they must name two "
                             "cameras")
    return self


def _split(fields: dict, *at: str) -> list[dict]:
    """``fields`` (ordered) cut before each name of ``at``: consecutive dicts that together hold them all."""
    keys = list(fields)
    cuts = [0, *(keys.index(name) for name in at), len(keys)]
    return [{k: fields[k] for k in keys[a:b]} for a, b in pairwise(cuts)]


_MODEL, _SENSING, _PREVIEW = _split(config_fields(CameraConfig), "noise_dn", "preview_rate")

#: the display registration (display.yaml): the published camera pose comes from its camera entry; twin: the
#: hidden truth it renders through
_REGISTRATION = {
    "display_calib": (str | None, Field(default=None)),
    "twin": (TruthChoice, Field(default_factory=TruthChoice)),
}

#: genicam source (docs/camera.md): the pair by serial number (or Aravis id / IP address)
_GENICAM = {
    "left_id": (str, Field(default="")),
    "right_id": (str, Field(default="")),
    "trigger": (str, Field(default="software", pattern="^(hardware|master|software|free)$")),
    "trigger_line": (str, Field(default="Line1")),
    "master_output_line": (str, Field(default="Line2")),
    "ptp": (str, Field(default="auto", pattern="^(auto|on|off)$")),
    "ptp_timeout_s": (float, Field(default=10.0, ge=0.0, le=120.0)),
    "device_clock": (str, Field(default="auto", pattern="^(auto|shared|independent)$")),
    "timestamp_at": (str, Field(default="exposure_start", pattern="^(exposure_start|exposure_end)$")),
    "pair_tolerance_s": (float, Field(default=0.0, ge=0.0, le=0.5)),
    "offset_x": (int, Field(default=0, ge=0)),
    "offset_y": (int, Field(default=0, ge=0)),
    "gain_db": (float | None, Field(default=None)),
    "packet_size": (int, Field(default=0, ge=0, le=16384)),
    "packet_delay_ns": (int, Field(default=0, ge=0)),
    "n_buffers": (int, Field(default=16, ge=2, le=256)),
    "discover_timeout_s": (float, Field(default=10.0, ge=0.0, le=120.0)),
}

#: device source (V4L2 index or path) and files source
_DEVICE_FILES = {
    "device_left": (int | str, Field(default=0)),
    "device_right": (int | str | None, Field(default=None)),
    "files_left": (str, Field(default="")),
    "files_right": (str, Field(default="")),
    "files_csv": (str, Field(default="")),
    "loop": (bool, Field(default=True)),
}

CameraParams = params_model(
    "CameraParams",
    """Camera node parameters (SI units; see docs/vision.md, and docs/camera.md for the device sources).

    ``display_calib``, ``twin`` and the devices' settings (``left_id`` … ``discover_timeout_s``,
    ``device_left`` … ``loop``) are the node's own; every other param is a field of — defined, defaulted and
    range-checked in — :class:`flexsheet.vision.camera_config.CameraConfig`.
    """,
    _MODEL, _REGISTRATION, _SENSING, _GENICAM, _PREVIEW, _DEVICE_FILES,
    validators={"_genicam_ids": model_validator(mode="after")(_genicam_ids)},
    module=__name__,
)


def sim_config(p: CameraParams) -> SimConfig:
    """The twin's :class:`SimConfig` for params ``p``: the realism's preset (:class:`SimConfig` or
    :meth:`SimConfig.ideal`) with every sensing param that is set (not ``None``) overriding it."""
    base = SimConfig() if p.twin.realism == "realistic" else SimConfig.ideal()
    over = {k: getattr(p, k) for k in ("noise_dn", "shot_gain", "blur_px", "self_occlusion", "background_gain",
                                      "finger_dir") if getattr(p, k) is not None}
    cfg = replace(base, exposure_s=p.exposure_s, blur_samples=p.blur_samples, clutter=p.clutter, seed=p.seed,
                  noise_scale=p.noise_scale, **over)
    cfg.validate()
    return cfg


def _with_rectification(st: dict) -> dict:
    """A stereo dict (image_size, K1, D1, K2, D2, R, T) completed with R1, R2, P1, P2, Q (``cv2.stereoRectify``,
    alpha 0) for :func:`flexsheet.vision.stereo_calibration.to_message`."""
    out = {k: np.asarray(st[k], float) for k in ("K1", "D1", "K2", "D2", "R", "T", "R1", "R2", "P1", "P2", "Q")
           if k in st}
    out["image_size"] = tuple(int(x) for x in st["image_size"])
    out["rms_px"] = float(st.get("rms_px", 0.0))
    if "R1" not in out:
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(out["K1"], out["D1"], out["K2"], out["D2"], out["image_size"],
                                                    out["R"], out["T"].reshape(3, 1), alpha=0)
        out.update(R1=R1, R2=R2, P1=P1, P2=P2, Q=Q)
    return out


def published_registration(p: CameraParams, calib: dict) -> tuple[dict, np.ndarray, str]:
    """What ``/camera/calibration`` carries: (stereo dict, T_display_camera (4, 4), one line saying where they
    come from). The pose from ``display.yaml``'s camera entry (``p.display_calib``), with its stereo model when
    it has one (the pose was fitted with it), else ``calib`` (the stereo file). Without ``display_calib``:
    the ideal twin's nominal registration (exact there). Raises ``ValueError`` naming the fix when
    ``display_calib`` is missing (lab sources, realistic twin), unreadable, lacks the camera entry, or its
    image size differs from the camera's."""
    size = tuple(int(v) for v in calib["image_size"])
    if p.display_calib:
        cam = load_display_calib(p.display_calib, require=("camera",)).camera
        stereo = cam.stereo if cam.stereo is not None else calib
        got = tuple(int(v) for v in stereo["image_size"])
        if got != size:
            raise ValueError(f"{p.display_calib}: camera entry is for {got[0]}x{got[1]} images but the camera "
                             f"delivers {size[0]}x{size[1]} (model {p.model!r}); re-run flexsheet calibrate "
                             "camera-pose with this camera")
        src = "display.yaml stereo" if cam.stereo is not None else "stereo file"
        return (_with_rectification(stereo), np.asarray(cam.T_display_camera, float),
                f"pose from {p.display_calib} ({cam.provenance.source}, {cam.provenance.measured_at}), {src}")
    if p.source == "sim" and p.twin.realism == "ideal":
        return (_with_rectification(calib), nominal_display_calib().camera.T_display_camera.copy(),
                "nominal registration (ideal twin: exact)")
    raise ValueError("display_calib is not set: the camera's pose in the display frame comes from display.yaml's "
                     "camera entry. Lab: run `flexsheet calibrate camera-pose`; twin: `flexsheet calibrate display "
                     "--sim --truth-seed N --out DIR`; then name the file in the launch file (`display_calib: "
                     "DIR/display.yaml`) or in this node's params (docs/calibration.md)")


class CameraNode(Node):
    """Publishes :class:`messages.StereoFrame` (at ``rate_hz``, or as the GenICam pair delivers) and latches
    :class:`messages.StereoCalibration`. Every pair at most ``preview_rate`` Hz is also published on
    ``/camera/stereo_preview`` (the same message; encoded only when a subscriber outside the process wants it),
    so a viewer does not receive the 48 Hz stream it would mostly drop (docs/visualise.md)."""

    Params = CameraParams
    #: a stereo pair of the XIMEA's 640 x 512 mono8 images, with room for its header (sizes the send queue)
    LARGEST_MESSAGE_BYTES = 2 * 640 * 512 + (16 << 10)

    @classmethod
    def probe(cls, params) -> list[str]:
        """The cameras ``params`` name that this machine does not see (``flexsheet launch --check --probe``):
        GenICam serials/ids by Aravis discovery (~1 s), UVC devices by opening them; sim and files: none."""
        p = params
        if p.source == "genicam":
            try:
                devices = list_devices()
            except RuntimeError as exc:
                return [f"camera: cannot discover GenICam cameras here: {exc}"]
            out = []
            for side, key in (("left_id", p.left_id), ("right_id", p.right_id)):
                try:
                    resolve_device(key, devices)
                except ValueError as exc:
                    out.append(f"camera {side}: {exc}")
            return out
        if p.source == "device":
            import cv2

            out = []
            for side, dev in (("device_left", p.device_left), ("device_right", p.device_right)):
                if dev is None:
                    continue
                cap = cv2.VideoCapture(dev)
                try:
                    if not cap.isOpened():
                        out.append(f"camera {side} = {dev!r}: no such video device can be opened here")
                finally:
                    cap.release()
            return out
        return []
    node_type = "camera"

    async def setup(self) -> None:
        p = self.params
        if p.model == "file":
            calib = load_yaml(p.calib_file)
        else:
            calib = camera_model(p.model, width=p.width, height=p.height, focal_mm=p.focal_mm,
                                 pixel_um=p.pixel_um, baseline=p.baseline)
        self.calib = calib
        published, self.T_dc, self.registration = published_registration(p, calib)
        self.stereo_pub = self.publisher(topics.STEREO)
        self.preview_pub = self.publisher(topics.STEREO_PREVIEW)
        self._preview_next = -math.inf
        self.calib_pub = self.publisher(topics.CALIBRATION)
        self.calib_pub.publish(to_message(published, self.calib_pub.header("camera_left"), self.T_dc))
        self._truth: FingerTruth | None = None
        self._truth_rx = -math.inf
        self._lock = threading.Lock()
        self._t0 = self.now()
        self.frames = 0
        self.dropped = 0
        if p.link_delay_s > 0 and (p.source != "sim" or not self.clock.simulated):
            raise ValueError(f"link_delay_s {p.link_delay_s:g} is the camera twin's on the simulated clock (source sim, "
                             f"launch file clock: sim); here source {p.source}")
        if p.source == "sim":
            from flexsheet.twin.truth import TwinTruth  # lazy: pinocchio, sim only

            truth = TwinTruth.draw(p.twin.truth_seed, p.twin.realism)
            self._drop_rate = (REALISTIC_DROP_RATE if p.twin.realism == "realistic" else 0.0) \
                if p.drop_rate is None else float(p.drop_rate)
            self._drop_rng = np.random.default_rng([p.seed, p.twin.truth_seed, 31])
            # the true cameras: the truth's (drawn around the XIMEA calibration) or, for another model, its own
            self.renderer = twin_renderer(truth, sim_config(p), calib=None if p.model == "ximea" else calib)
            self.subscribe(topics.FINGER_TRUTH, self.on_truth, qos=QoS.LATEST)
            self._registration_twin(truth)
            # simulated clock: the pair leaves readout + transfer after mid-exposure (flexsheet/model/timing.py)
            w, h = (int(v) for v in calib["image_size"])
            self.timer(1.0 / p.rate_hz, self.on_sim_tick, sim_cost=LAB.camera_latency(p.exposure_s, w, h),
                       sim_delay=p.link_delay_s)
        elif p.source == "genicam":
            w, h = (int(v) for v in calib["image_size"])
            cfg = GenICamConfig(left_id=p.left_id, right_id=p.right_id, width=w, height=h,
                                offset_x=p.offset_x, offset_y=p.offset_y, exposure_s=p.exposure_s,
                                rate_hz=p.rate_hz, gain_db=p.gain_db, trigger=p.trigger,
                                trigger_line=p.trigger_line, master_output_line=p.master_output_line,
                                ptp=p.ptp, ptp_timeout_s=p.ptp_timeout_s, device_clock=p.device_clock,
                                pair_tolerance_s=p.pair_tolerance_s, packet_size=p.packet_size,
                                packet_delay_ns=p.packet_delay_ns, n_buffers=p.n_buffers,
                                discover_timeout_s=p.discover_timeout_s)
            self.genicam = GenICamStereo(cfg, on_pair=self._on_genicam_pair, logger=self.log)
            try:
                await asyncio.to_thread(self.genicam.start)
            except RuntimeError as exc:  # Aravis missing: an installation problem, respawning cannot help
                raise ValueError(str(exc)) from None
        elif p.source == "device":
            self.device = DeviceSource(p.device_left, p.device_right, tuple(calib["image_size"]),
                                       p.exposure_s, fallback_period_s=1.0 / p.rate_hz)
            self.timer(1.0 / p.rate_hz, self.on_device_tick)
        else:
            self.files = FileSource(p.files_left, p.files_right, p.files_csv, p.rate_hz)
            self._file_task = asyncio.get_running_loop().create_task(self._play_files())

    def _registration_twin(self, truth) -> None:
        """The registration scenes (:mod:`flexsheet.twin.registration_scene`) a lab sets up by hand — the board
        on the sheet, the projector's patterns, the dark room for the clamp markers — switched by the sim-only
        service ``twin/scene``; the sheet follows the arms' joint states, the light ``/projector/image``."""
        from flexsheet.twin.registration_scene import SCENES, RegistrationScene  # lazy: scipy.optimize

        self.scene = RegistrationScene(truth, seed=self.params.seed)
        self._scene_lock = threading.Lock()
        self._projected: tuple[int, np.ndarray] | None = None
        self._projected_stamp: float | None = None
        # where the true arms are (the controller twins' readback), read per registration frame (sampled)
        self._arm_states = {side: self.sample(topics.arm_state(side)) for side in ("left", "right")}
        self.subscribe(topics.PROJECTOR_IMAGE, self.on_projector_image, qos=QoS.LATEST)
        self.service("twin/scene", self.srv_scene,
                     f"camera twin only: {{scene: {'|'.join(SCENES)}, board, square (m), offset (m)}}: what the "
                     "operator set up in front of the camera (registration); finger: the display running",
                     commanding=True)
        self.service("twin/state", self.srv_twin_state,
                     "camera twin only: {scene, projector_stamp (s: the /projector/image lighting the sheet now, or "
                     "null), now (s)}; a frame exposed after now shows that image")

    def srv_scene(self, args: dict) -> str:
        unknown = set(args) - {"scene", "board", "square", "offset"}
        if unknown:
            raise ValueError(f"twin/scene takes scene, board, square, offset; got {', '.join(sorted(unknown))}")
        with self._scene_lock:      # not while a frame of the old scene is being drawn
            return self.scene.set_scene(args.get("scene", ""), args.get("board", "chessboard:9x8"),
                                        args.get("square", 0.022), args.get("offset", 0.0))

    def srv_twin_state(self, args: dict) -> dict:
        with self._lock:
            stamp = self._projected_stamp
        return {"scene": self.scene.scene, "projector_stamp": stamp, "now": self.now()}

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
            self._log_limited(30, "camera twin: the registration scene waits for both arms' joint states")
            return None
        with self._scene_lock:
            return self.scene.render(q["left"], q["right"], projected)

    def on_truth(self, msg: FingerTruth) -> None:
        """Keep the newest finger truth (position/velocity in the display frame)."""
        with self._lock:
            self._truth = msg
            self._truth_rx = self.now()

    def _marker_state(self, t: float) -> tuple[np.ndarray, np.ndarray, bool]:
        p = self.params
        with self._lock:
            truth = self._truth
        if truth is not None:       # held however old: falling back to the param path showed a second finger
            dt = min(max(t - truth.header.stamp, 0.0), 0.1)
            return truth.position + truth.velocity * dt, truth.velocity, truth.visible
        pos, vel = default_trajectory(t - self._t0, p.traj_amplitude_rad, p.traj_period_s, p.traj_hover_m)
        return pos, vel, True

    def _publish(self, left: np.ndarray, right: np.ndarray, stamp: float, skew: float = 0.0) -> None:
        self.stereo_pub.publish(StereoFrame(   # header.stamp: handed to the graph now; exposure: mid-exposure
            header=self.stereo_pub.header("camera_left"), left=left, right=right,
            exposure_stamp=stamp, exposure_time=float(self.params.exposure_s), stereo_skew=float(skew)))
        self.frames += 1
        rate = self.params.preview_rate
        if rate > 0 and stamp >= self._preview_next:
            self._preview_next = stamp + 1.0 / rate - 0.5 / self.params.rate_hz   # half a frame of slack
            self.preview_pub.publish(StereoFrame(
                header=self.preview_pub.header("camera_left"), left=left, right=right, exposure_stamp=stamp,
                exposure_time=float(self.params.exposure_s), stereo_skew=float(skew)))

    def _sim_frame(self) -> None:
        t = self.now()
        if self._drop_rate > 0 and self._drop_rng.random() < self._drop_rate:
            self.dropped += 1            # the frame is lost on the link: nothing rendered, nothing published
            return
        if self.scene.scene != "finger":
            pair = self._registration_frame()
            if pair is not None:
                self._publish(pair[0], pair[1], t)
            return
        pos, vel, visible = self._marker_state(t)
        left, right = self.renderer.render(pos, vel, visible)
        self._publish(left, right, t)

    async def on_sim_tick(self) -> None:
        """Render and publish one twin frame (rendering runs in a worker thread, off the loop; on a simulated
        clock on the loop: the frame is due at its instant)."""
        if self.clock.simulated:
            self._sim_frame()
        else:
            await asyncio.to_thread(self._sim_frame)

    def _device_frame(self) -> None:
        try:
            left, right, stamp, skew = self.device.read()
        except ValueError as exc:
            self._log_limited(30, f"camera device: {exc}")
            return
        self._publish(left, right, stamp, skew)

    def _on_genicam_pair(self, pair) -> None:
        """Publish one GenICam pair (called in a camera thread): exposure stamp = left device stamp mapped to
        host time, moved to mid-exposure; skew = measured right − left (``pair.skew_basis``)."""
        half = 0.5 * self.params.exposure_s
        stamp = pair.stamp_s + (half if self.params.timestamp_at == "exposure_start" else -half)
        self._publish(pair.left.image, pair.right.image, stamp, pair.skew_s)

    def status_line(self) -> str:
        """One line for ``/diagnostics``: what ``stereo_skew`` means for this source, with the GenICam
        pair's measured skew, rate and dropped frames."""
        p = self.params
        if p.source == "genicam" and getattr(self, "genicam", None) is not None:
            return self.genicam.summary_line()
        if p.source == "device" and getattr(self, "device", None) is not None:
            if self.device.skew_kind == "zero_by_construction":
                return "device (one side-by-side UVC device): stereo_skew 0 by construction, not measured"
            return ("device (two UVC devices, unsynchronised): exposure skew unknown; stereo_skew is an "
                    "upper bound = |grab interval| + frame period "
                    f"({self.device.frame_period() * 1e3:.1f} ms)")
        if p.source == "sim":
            return (f"sim ({p.twin.realism} twin, truth seed {p.twin.truth_seed}; {self.registration}): "
                    f"stereo_skew 0 (the twin renders both views at one instant); dropped {self.dropped} of "
                    f"{self.frames + self.dropped} frames (drop_rate {self._drop_rate:g}); {self._truth_line()}")
        return "files: stereo_skew 0 (not recorded)"

    def _truth_line(self) -> str:
        with self._lock:
            rx = self._truth_rx
        if not math.isfinite(rx):
            return "finger: param trajectory (no /world/finger yet)"
        return f"finger: /world/finger, last {self.now() - rx:.2f} s ago"

    def heartbeat(self):
        """The base heartbeat with :meth:`status_line` in ``message`` (before any warning line). GenICam:
        state ``warn`` when frames were dropped or left unpaired since the last heartbeat or no pair came for
        1 s, ``error`` when a camera lost its control channel."""
        hb = super().heartbeat()
        line = self.status_line()
        state = hb.state
        if getattr(self, "genicam", None) is not None:
            s = self.genicam.stats()
            lost = sum(s.get(k, 0) for k in ("left_dropped", "right_dropped", "left_unpaired",
                                             "right_unpaired"))
            stale = s.get("last_pair_age_s", 0.0) > 1.0
            if (lost > getattr(self, "_lost_seen", 0) or stale) and state == "ok":
                state = "warn"
            if s.get("control_lost"):
                state = "error"
            self._lost_seen = lost
        return hb.model_copy(update={"message": f"{line}; {hb.message}" if hb.message else line,
                                     "state": state})

    async def on_device_tick(self) -> None:
        """Grab and publish one device pair (in a worker thread)."""
        await asyncio.to_thread(self._device_frame)

    async def _play_files(self) -> None:
        stamps = self.files.stamps()
        while True:
            start = self.now()
            for i in range(len(self.files)):
                target = start + stamps[i] - stamps[0]
                await asyncio.sleep(max(0.0, target - self.now()))
                try:
                    left, right = await asyncio.to_thread(self.files.read, i)
                except ValueError as exc:
                    self._log_limited(30, f"camera files: {exc}")
                    continue
                self._publish(left, right, target)
            if not self.params.loop:
                return
            gap = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 1.0 / self.params.rate_hz
            await asyncio.sleep(gap)

    async def teardown(self) -> None:
        if getattr(self, "device", None) is not None:
            self.device.close()
        if getattr(self, "genicam", None) is not None:
            await asyncio.to_thread(self.genicam.close)
        task = getattr(self, "_file_task", None)
        if task is not None:
            task.cancel()
