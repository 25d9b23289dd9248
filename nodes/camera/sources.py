"""The stereo camera port's lab sides (:mod:`flexsheet.vision.camera_port`): ``genicam`` (a GigE Vision / USB3
Vision pair through Aravis, :mod:`nodes.camera.genicam`), ``device`` (UVC cameras, :mod:`nodes.camera.device`)
and ``files`` (a folder of pairs, :mod:`nodes.camera.files`)."""

from __future__ import annotations

import asyncio
import logging

import cv2
import numpy as np

from flexsheet.vision.camera_port import CameraHost, CameraSource
from nodes.camera.device import DeviceSource
from nodes.camera.files import FileSource
from nodes.camera.genicam import GenICamConfig, GenICamStereo, list_devices, resolve_device

__all__ = ["GenICamCamera", "UvcCamera", "FilesCamera"]


class GenICamCamera(CameraSource):
    """A hardware/software-triggered or PTP-synced pair opened by serial, stamped and paired by device
    timestamp; each pair published from a camera thread as it comes."""

    def __init__(self, host: CameraHost, genicam: GenICamStereo):
        self.host = host
        self.genicam = genicam
        self._lost_seen = 0

    @classmethod
    async def open(cls, host: CameraHost, calib: dict) -> GenICamCamera:
        p = host.params
        w, h = (int(v) for v in calib["image_size"])
        cfg = GenICamConfig(left_id=p.left_id, right_id=p.right_id, width=w, height=h,
                            offset_x=p.offset_x, offset_y=p.offset_y, exposure_s=p.exposure_s,
                            rate_hz=p.rate_hz, gain_db=p.gain_db, trigger=p.trigger,
                            trigger_line=p.trigger_line, master_output_line=p.master_output_line,
                            ptp=p.ptp, ptp_timeout_s=p.ptp_timeout_s, device_clock=p.device_clock,
                            pair_tolerance_s=p.pair_tolerance_s, packet_size=p.packet_size,
                            packet_delay_ns=p.packet_delay_ns, n_buffers=p.n_buffers,
                            discover_timeout_s=p.discover_timeout_s)
        self = cls(host, None)
        self.genicam = GenICamStereo(cfg, on_pair=self._on_pair, logger=host.log)
        try:
            await asyncio.to_thread(self.genicam.start)
        except RuntimeError as exc:  # Aravis missing: an installation problem, respawning cannot help
            raise ValueError(str(exc)) from None
        return self

    @classmethod
    def probe(cls, params) -> list[str]:
        """The serials/ids ``params`` name that Aravis discovery (~1 s) does not find here."""
        try:
            devices = list_devices()
        except RuntimeError as exc:
            return [f"camera: cannot discover GenICam cameras here: {exc}"]
        out = []
        for side, key in (("left_id", params.left_id), ("right_id", params.right_id)):
            try:
                resolve_device(key, devices)
            except ValueError as exc:
                out.append(f"camera {side}: {exc}")
        return out

    def _on_pair(self, pair) -> None:
        """Publish one pair (a camera thread): exposure stamp = left device stamp mapped to host time, moved
        to mid-exposure; skew = measured right − left (``pair.skew_basis``)."""
        p = self.host.params
        half = 0.5 * p.exposure_s
        stamp = pair.stamp_s + (half if p.timestamp_at == "exposure_start" else -half)
        self.host.publish_pair(pair.left.image, pair.right.image, stamp, pair.skew_s)

    def status_line(self) -> str:
        return self.genicam.summary_line()

    def health(self, state: str) -> str:
        """``warn`` when frames were dropped or left unpaired since the last heartbeat or no pair came for 1
        s, ``error`` when a camera lost its control channel."""
        s = self.genicam.stats()
        lost = sum(s.get(k, 0) for k in ("left_dropped", "right_dropped", "left_unpaired", "right_unpaired"))
        stale = s.get("last_pair_age_s", 0.0) > 1.0
        if (lost > self._lost_seen or stale) and state == "ok":
            state = "warn"
        if s.get("control_lost"):
            state = "error"
        self._lost_seen = lost
        return state

    async def close(self) -> None:
        await asyncio.to_thread(self.genicam.close)


class UvcCamera(CameraSource):
    """One side-by-side UVC stereo device or two devices, grabbed at ``rate_hz`` in a worker thread."""

    def __init__(self, host: CameraHost, device: DeviceSource):
        self.host = host
        self.device = device

    @classmethod
    async def open(cls, host: CameraHost, calib: dict) -> UvcCamera:
        p = host.params
        self = cls(host, DeviceSource(p.device_left, p.device_right, tuple(calib["image_size"]), p.exposure_s,
                                      fallback_period_s=1.0 / p.rate_hz))
        host.timer(1.0 / p.rate_hz, self.on_tick)
        return self

    @classmethod
    def probe(cls, params) -> list[str]:
        """The devices ``params`` name that cannot be opened here."""
        out = []
        for side, dev in (("device_left", params.device_left), ("device_right", params.device_right)):
            if dev is None:
                continue
            cap = cv2.VideoCapture(dev)
            try:
                if not cap.isOpened():
                    out.append(f"camera {side} = {dev!r}: no such video device can be opened here")
            finally:
                cap.release()
        return out

    def _frame(self) -> None:
        try:
            left, right, stamp, skew = self.device.read()
        except ValueError as exc:
            self.host.log_limited(logging.WARNING, f"camera device: {exc}")
            return
        self.host.publish_pair(left, right, stamp, skew)

    async def on_tick(self) -> None:
        """Grab and publish one pair (in a worker thread)."""
        await asyncio.to_thread(self._frame)

    def status_line(self) -> str:
        if self.device.skew_kind == "zero_by_construction":
            return "device (one side-by-side UVC device): stereo_skew 0 by construction, not measured"
        return ("device (two UVC devices, unsynchronised): exposure skew unknown; stereo_skew is an upper "
                f"bound = |grab interval| + frame period ({self.device.frame_period() * 1e3:.1f} ms)")

    async def close(self) -> None:
        self.device.close()


class FilesCamera(CameraSource):
    """A folder of pairs played at their recorded stamps (or ``rate_hz``), looped when ``loop``."""

    def __init__(self, host: CameraHost, files: FileSource):
        self.host = host
        self.files = files
        self._task: asyncio.Task | None = None

    @classmethod
    async def open(cls, host: CameraHost, calib: dict) -> FilesCamera:
        p = host.params
        self = cls(host, FileSource(p.files_left, p.files_right, p.files_csv, p.rate_hz))
        self._task = asyncio.get_running_loop().create_task(self._play())
        return self

    async def _play(self) -> None:
        host = self.host
        stamps = self.files.stamps()
        while True:
            start = host.now()
            for i in range(len(self.files)):
                target = start + stamps[i] - stamps[0]
                await asyncio.sleep(max(0.0, target - host.now()))
                try:
                    left, right = await asyncio.to_thread(self.files.read, i)
                except ValueError as exc:
                    host.log_limited(logging.WARNING, f"camera files: {exc}")
                    continue
                host.publish_pair(left, right, target)
            if not host.params.loop:
                return
            gap = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 1.0 / host.params.rate_hz
            await asyncio.sleep(gap)

    def status_line(self) -> str:
        return "files: stereo_skew 0 (not recorded)"

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
