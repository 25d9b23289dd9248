"""GenICam stereo pair (GigE Vision / USB3 Vision) through Aravis (``gi.repository.Aravis`` 0.8, PyGObject).

:class:`GenICamStereo` opens the two cameras by serial number (or Aravis device id, or IP address),
configures Mono8, the region, exposure and frame rate, chooses the synchronisation the cameras offer
(:mod:`nodes.camera.genicam_sync`: hardware trigger, master/slave line, software trigger or free run; PTP),
streams with one polling thread per camera and pairs frames by *device* timestamp
(:class:`flexsheet.vision.stereo_sync.StereoPairer`), measuring the left/right exposure skew and counting
dropped frames (incomplete buffers by status, frame id gaps, Aravis stream counters). Aravis is imported
lazily (:func:`aravis`); :func:`resolve_device` needs none. Setup guide: ``docs/camera.md``.

Time stamps: ``buffer.get_timestamp()`` is the device's stamp in ns (Aravis converts GigE ticks with the
camera's ``GevTimestampTickFrequency``; a camera that reports no tick frequency gets the *host arrival
time* instead — :meth:`GenICamStereo.start` logs that case). It is mapped to host time (``time.time()``)
with the offset :class:`~flexsheet.vision.stereo_sync.ClockMap` measures: by latching the device clock
(``TimestampLatch``/``GevTimestampControlLatch``, re-latched every ``relatch_s``) where the camera offers
it, else from the minimum of arrival − device stamp (late by the minimum delivery delay: :class:`ClockMap`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexsheet.vision.stereo_sync import CamFrame, StereoPair, StereoPairer
from nodes.camera.genicam_sync import PTP_LOCKED, SyncPlan, plan_sync, probe_features

__all__ = ["aravis", "DeviceInfo", "list_devices", "resolve_device", "GenICamConfig", "GenICamStereo"]

log = logging.getLogger("camera.genicam")


def aravis():
    """The ``Aravis`` 0.8 GObject-introspection module. Raises ``RuntimeError`` naming the Debian packages."""
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis
    except (ImportError, ValueError) as exc:
        raise RuntimeError("GenICam cameras need Aravis 0.8 with PyGObject: apt install gir1.2-aravis-0.8 "
                           f"(and pip install PyGObject); import failed: {exc}") from None
    return Aravis


@dataclass(frozen=True)
class DeviceInfo:
    """One device Aravis discovered: ``device_id`` (Aravis id, e.g. ``Basler-21234567``), ``serial``,
    ``address`` (IP for GigE, bus address for USB3), ``physical_id`` (MAC), ``vendor``, ``model``,
    ``protocol`` (``GigEVision`` | ``USB3Vision``)."""

    device_id: str
    serial: str
    address: str
    physical_id: str = ""
    vendor: str = ""
    model: str = ""
    protocol: str = ""


def list_devices() -> list[DeviceInfo]:
    """Discover cameras on every interface (``Aravis.update_device_list``; GigE discovery is a broadcast,
    ~1 s). Raises ``RuntimeError`` when Aravis is missing."""
    A = aravis()
    A.update_device_list()
    return [DeviceInfo(A.get_device_id(i) or "", A.get_device_serial_nbr(i) or "",
                       A.get_device_address(i) or "", A.get_device_physical_id(i) or "",
                       A.get_device_vendor(i) or "", A.get_device_model(i) or "",
                       A.get_device_protocol(i) or "")
            for i in range(A.get_n_devices())]


def resolve_device(key: str, devices: list[DeviceInfo]) -> DeviceInfo:
    """The device ``key`` names: a serial number, an Aravis device id, an IP/bus address or a MAC, matched
    exactly (serial first). Raises ``ValueError`` naming the key and listing what was found."""
    if not key:
        raise ValueError("camera id is empty: set left_id/right_id to the cameras' serial numbers")
    for attr in ("serial", "device_id", "address", "physical_id"):
        hits = [d for d in devices if getattr(d, attr) == key]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise ValueError(f"camera id {key!r} matches {len(hits)} devices by {attr}: "
                             f"{[d.device_id for d in hits]}")
    found = ", ".join(f"{d.serial} ({d.device_id} at {d.address})" for d in devices) or "none"
    raise ValueError(f"camera {key!r} not found; cameras found: {found}")


@dataclass
class GenICamConfig:
    """Settings of the pair (SI units). ``left_id``/``right_id``: serial numbers (or Aravis ids / IPs);
    ``width``/``height`` px and ``offset_x``/``offset_y`` px: the region (must match the calibration);
    ``exposure_s``; ``rate_hz``: frame rate (free/master) or software trigger rate; ``gain_db``: None
    leaves the gain; ``trigger``/``ptp``/``trigger_line``/``master_output_line``: see :func:`plan_sync`;
    ``ptp_timeout_s``: wait for PTP lock; ``device_clock``: auto (shared iff PTP locked) | shared |
    independent; ``pair_tolerance_s``: 0 → 0.25 / rate_hz; ``packet_size``: GigE packet size, bytes
    (0: negotiate the largest that passes, ``gv_auto_packet_size``); ``packet_delay_ns``: GigE inter-packet
    delay (share one NIC between two cameras); ``n_buffers``: stream buffers per camera;
    ``relatch_s``: device clock re-latch period; ``discover_timeout_s``: keep discovering this long for
    cameras still booting (0: once)."""

    left_id: str
    right_id: str
    width: int = 640
    height: int = 512
    offset_x: int = 0
    offset_y: int = 0
    exposure_s: float = 0.004
    rate_hz: float = 48.0
    gain_db: float | None = None
    trigger: str = "software"
    trigger_line: str = "Line1"
    master_output_line: str = "Line2"
    ptp: str = "auto"
    ptp_timeout_s: float = 10.0
    device_clock: str = "auto"
    pair_tolerance_s: float = 0.0
    packet_size: int = 0
    packet_delay_ns: int = 0
    n_buffers: int = 16
    relatch_s: float = 1.0
    discover_timeout_s: float = 10.0


class _Cam:
    """One opened camera with its stream and polling thread (internal)."""

    def __init__(self, A, info: DeviceInfo, side: int) -> None:
        self.A, self.info, self.side = A, info, side
        self.name = ("left", "right")[side]
        self.cam = A.Camera.new(info.device_id)
        self.features = probe_features(self.cam)
        self.stream = None
        self.thread: threading.Thread | None = None
        self.latch_lock = threading.Lock()

    def configure(self, cfg: GenICamConfig, plan: SyncPlan) -> None:
        cam, A = self.cam, self.A
        if "Mono8" not in self.features["pixel_formats"]:
            raise ValueError(f"{self.name} camera {self.info.serial}: pixel format Mono8 not offered "
                             f"(has {self.features['pixel_formats']})")
        cam.set_pixel_format_from_string("Mono8")
        cam.set_region(cfg.offset_x, cfg.offset_y, cfg.width, cfg.height)
        region = cam.get_region()
        if (region.width, region.height) != (cfg.width, cfg.height):
            raise ValueError(f"{self.name} camera {self.info.serial}: region {region.width}x{region.height} "
                             f"instead of the calibration's {cfg.width}x{cfg.height}")
        if cam.is_exposure_auto_available():
            cam.set_exposure_time_auto(A.Auto.OFF)
        cam.set_exposure_time(cfg.exposure_s * 1e6)
        if cfg.gain_db is not None and cam.is_gain_available():
            if cam.is_gain_auto_available():
                cam.set_gain_auto(A.Auto.OFF)
            cam.set_gain(cfg.gain_db)
        role = plan.trigger
        if role == "master":
            role = "free" if self.side == 0 else "hardware"
        if role == "free" and cam.is_frame_rate_available():
            cam.set_frame_rate(cfg.rate_hz)  # Aravis clears the triggers first
        if plan.ptp:
            cam.set_boolean(self.features["ptp"], True)
        if role == "free":
            cam.clear_triggers()
        elif role == "software":
            cam.set_trigger("Software")
        else:
            cam.set_trigger(plan.trigger_line)
        if plan.trigger == "master" and self.side == 0:
            cam.set_string("LineSelector", plan.master_output_line)
            cam.set_string("LineMode", "Output")
            cam.set_string("LineSource", "ExposureActive")
        if self.features["gv"]:
            if cfg.packet_size > 0:
                cam.gv_set_packet_size(cfg.packet_size)
            else:
                cam.gv_auto_packet_size()
            if cfg.packet_delay_ns > 0:
                cam.gv_set_packet_delay(cfg.packet_delay_ns)
        self.stream = cam.create_stream(None, None)
        if self.features["gv"]:
            self.stream.set_property("packet-resend", A.GvStreamPacketResend.ALWAYS)
        payload = cam.get_payload()
        for _ in range(cfg.n_buffers):
            self.stream.push_buffer(A.Buffer.new_allocate(payload))

    def ptp_status(self) -> str:
        st = self.features.get("ptp_status")
        if not st:
            return "unknown"
        try:
            return str(self.cam.get_string(st))
        except Exception:  # noqa: BLE001
            return "unreadable"

    def latch(self) -> tuple[int, float, float] | None:
        """Latch the device clock: (device ns, host before s, host after s), or None if not offered."""
        names = self.features["latch"]
        tick = self.features["tick_hz"] or 1e9
        if not names:
            return None
        with self.latch_lock:
            t0 = time.time()
            self.cam.execute_command(names[0])
            t1 = time.time()
            ticks = self.cam.get_integer(names[1])
        return int(round(ticks * 1e9 / tick)), t0, t1

    def stream_info(self) -> dict:
        out = {}
        if self.stream is None:
            return out
        for i in range(self.stream.get_n_infos()):
            name = self.stream.get_info_name(i)
            if name.startswith("n_"):
                try:
                    out[name] = int(self.stream.get_info_uint64(i))
                except Exception:  # noqa: BLE001
                    pass
        return out


class GenICamStereo:
    """A synchronised GenICam stereo pair (module doc). ``on_pair(StereoPair)`` is called from the camera
    threads for every pair (keep it short: publish and return).

    :meth:`start` opens, configures and starts both cameras; raises ``ValueError`` for a camera that is
    not found (after ``discover_timeout_s``) or cannot be configured (message names it), ``RuntimeError``
    when Aravis is missing.
    :meth:`stats` returns the counters for diagnostics; :meth:`close` stops everything.
    """

    def __init__(self, cfg: GenICamConfig, on_pair: Callable[[StereoPair], None] | None = None,
                 logger: logging.Logger | None = None) -> None:
        if cfg.device_clock not in ("auto", "shared", "independent"):
            raise ValueError(f"device_clock must be auto|shared|independent, got {cfg.device_clock!r}")
        if not cfg.rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {cfg.rate_hz!r}")
        self.cfg = cfg
        self._consumer = on_pair
        self.log = logger or log
        self.cams: list[_Cam] = []
        self.plan: SyncPlan | None = None
        self.pairer: StereoPairer | None = None
        self.notes: list[str] = []
        self.ptp_locked = False
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.started_at = 0.0
        self.trigger_late = 0
        self.last_pair_at = 0.0
        self.control_lost: list[str] = []
        self._final: dict | None = None

    # ------------------------------------------------------------------ setup
    def start(self, devices: list[DeviceInfo] | None = None) -> None:
        A = aravis()
        cfg = self.cfg
        deadline = time.monotonic() + cfg.discover_timeout_s
        while True:
            found = list_devices() if devices is None else devices
            try:
                infos = [resolve_device(cfg.left_id, found), resolve_device(cfg.right_id, found)]
                break
            except ValueError:
                if devices is not None or time.monotonic() >= deadline:
                    raise
                time.sleep(1.0)  # a camera still booting (PoE, power-up) appears after a few seconds
        if infos[0].device_id == infos[1].device_id:
            raise ValueError(f"left_id {cfg.left_id!r} and right_id {cfg.right_id!r} name the same camera")
        try:
            for side, info in enumerate(infos):
                try:
                    self.cams.append(_Cam(A, info, side))
                except Exception as exc:  # GLib.Error: camera busy, no access, wrong id
                    raise ValueError(f"cannot open {('left', 'right')[side]} camera {info.serial} "
                                     f"({info.device_id} at {info.address}): {exc}") from None
            L, R = (c.features for c in self.cams)
            self.plan = plan_sync(L, R, cfg.trigger, cfg.ptp, cfg.trigger_line, cfg.master_output_line)
            self.notes = list(self.plan.notes)
            for c in self.cams:
                if c.features["gv"] and not c.features["tick_hz"]:
                    self.notes.append(f"{c.name} camera reports no timestamp tick frequency: Aravis stamps "
                                      "its frames with the host arrival time, not the exposure")
                try:
                    c.configure(cfg, self.plan)
                except ValueError:
                    raise
                except Exception as exc:  # noqa: BLE001 - GLib.Error from a feature write
                    raise ValueError(f"{c.name} camera {c.info.serial}: configuration failed: "
                                     f"{exc}") from None
            self.ptp_locked = self._wait_ptp() if self.plan.ptp else False
            shared = cfg.device_clock == "shared" or (cfg.device_clock == "auto" and self.ptp_locked)
            if cfg.device_clock == "shared" and not self.ptp_locked:
                self.notes.append("device_clock: shared was set without PTP lock: skew = right − left device "
                                  "stamps assumes the two cameras share one clock")
            tol = cfg.pair_tolerance_s or 0.25 / cfg.rate_hz
            self.pairer = StereoPairer(tol, shared, on_pair=self._on_pair)
            for c in self.cams:
                c.cam.get_device().connect("control-lost", self._on_control_lost, c.name)
            for line in self.notes:
                self.log.warning("genicam: %s", line)
            self.log.info("genicam: %s + %s, %dx%d Mono8, %.1f Hz, exposure %.2f ms, trigger %s, PTP %s, "
                          "device clocks %s, pair tolerance %.2f ms", infos[0].serial, infos[1].serial,
                          cfg.width, cfg.height, cfg.rate_hz, cfg.exposure_s * 1e3, self.plan.trigger,
                          "locked" if self.ptp_locked else ("enabled, not locked" if self.plan.ptp
                                                            else "off"),
                          "shared" if shared else "independent", tol * 1e3)
            self._latch_all()
            for c in self.cams:
                c.cam.start_acquisition()
            self.started_at = time.time()
            for c in self.cams:
                t = threading.Thread(target=self._poll, args=(c,), name=f"genicam-{c.name}", daemon=True)
                t.start()
                self._threads.append(t)
            t = threading.Thread(target=self._housekeeping, name="genicam-housekeeping", daemon=True)
            t.start()
            self._threads.append(t)
        except BaseException:
            self.close()
            raise

    def _wait_ptp(self) -> bool:
        deadline = time.monotonic() + self.cfg.ptp_timeout_s
        while True:
            st = [c.ptp_status() for c in self.cams]
            if all(s in PTP_LOCKED for s in st) and "Slave" in st:  # one master + slave, or both slaves
                return True
            if time.monotonic() > deadline:
                self.notes.append(f"PTP enabled but not locked after {self.cfg.ptp_timeout_s:.0f} s "
                                  f"(status left {st[0]}, right {st[1]}): device clocks treated as "
                                  "independent")
                return False
            time.sleep(0.25)

    def _latch_all(self) -> None:
        for c in self.cams:
            try:
                got = c.latch()
            except Exception as exc:  # noqa: BLE001
                self.notes.append(f"{c.name} camera: timestamp latch failed ({exc}); offset from frame "
                                  "arrivals")
                c.features["latch"] = None
                continue
            if got is not None and self.pairer is not None:
                self.pairer.sides[c.side].clock.add_latch(*got)

    # ------------------------------------------------------------------ threads
    def _on_pair(self, pair: StereoPair) -> None:
        self.last_pair_at = time.time()
        if self._consumer is not None:
            self._consumer(pair)

    def _on_control_lost(self, _device, name: str) -> None:
        """Aravis lost the control channel (cable, power, heartbeat timeout): say so in the log and the
        diagnostics line; the stream stays silent until the node is restarted."""
        self.control_lost.append(name)
        self.log.error("genicam: %s camera lost its control channel (cable, power or heartbeat timeout)",
                       name)

    def _poll(self, c: _Cam) -> None:
        ok = aravis().BufferStatus.SUCCESS
        while not self._stop.is_set():
            buf = c.stream.timeout_pop_buffer(100_000)  # µs; releases the GIL while waiting
            if buf is None:
                continue
            try:
                status = buf.get_status()
                dev_ns = int(buf.get_timestamp())
                sys_ns = int(buf.get_system_timestamp())
                fid = int(buf.get_frame_id())
                img = None
                if status == ok:
                    w, h = buf.get_image_width(), buf.get_image_height()
                    data = buf.get_image_data() if hasattr(buf, "get_image_data") else buf.get_data()
                    img = np.frombuffer(data, np.uint8, count=w * h).reshape(h, w).copy()
                name = "ok" if status == ok else status.value_nick
            finally:
                c.stream.push_buffer(buf)
            frame = CamFrame(img, fid, dev_ns, sys_ns * 1e-9 if sys_ns else time.time(), name)
            try:
                self.pairer.push(c.side, frame)
            except Exception:  # noqa: BLE001 - a failing consumer must not kill acquisition
                self.log.exception("genicam: pair consumer failed")

    def _housekeeping(self) -> None:
        period = 1.0 / self.cfg.rate_hz
        nxt = time.monotonic()
        next_latch = time.monotonic() + self.cfg.relatch_s
        soft = self.plan.trigger == "software"
        while not self._stop.is_set():
            if soft:
                for c in self.cams:
                    try:
                        c.cam.software_trigger()
                    except Exception as exc:  # noqa: BLE001
                        self.log.warning("genicam: software trigger on %s failed: %s", c.name, exc)
                nxt += period
                delay = nxt - time.monotonic()
                if delay < 0:
                    self.trigger_late += 1
                    nxt = time.monotonic()
                    delay = 0.0
            else:
                delay = 0.1
            if time.monotonic() >= next_latch:
                self._latch_all()
                next_latch = time.monotonic() + self.cfg.relatch_s
            self._stop.wait(delay)

    # ------------------------------------------------------------------ results
    def stats(self) -> dict:
        """Counters: pairer stats (skew in s, drops per side), Aravis stream counters per side
        (``left_stream``/``right_stream``), sync plan, PTP lock, elapsed s and pair rate Hz. After
        :meth:`close`: the figures at closing."""
        if self._final is not None:
            return dict(self._final)
        out: dict = {}
        if self.pairer is not None:
            out.update(self.pairer.stats())
        for c in self.cams:
            out[f"{c.name}_stream"] = c.stream_info()
            out[f"{c.name}_serial"] = c.info.serial
        if self.plan is not None:
            out["trigger"] = self.plan.trigger
            out["ptp_enabled"] = self.plan.ptp
        out["ptp_locked"] = self.ptp_locked
        out["software_trigger_late"] = self.trigger_late
        out["control_lost"] = list(self.control_lost)
        out["last_pair_age_s"] = time.time() - self.last_pair_at if self.last_pair_at else float("inf")
        el = time.time() - self.started_at if self.started_at else 0.0
        out["elapsed_s"] = el
        out["pair_rate_hz"] = out.get("pairs", 0) / el if el > 0 else 0.0
        return out

    def summary_line(self) -> str:
        """One line for ``/diagnostics`` (ms, counts)."""
        s = self.stats()
        lost = f"CONTROL LOST ({', '.join(s['control_lost'])}); " if s.get("control_lost") else ""
        stale = s.get("last_pair_age_s", 0.0)
        if s.get("pairs") and stale > 1.0:
            lost += f"no pair for {stale:.1f} s; "
        return lost + self._summary(s)

    @staticmethod
    def _summary(s: dict) -> str:
        if not s.get("pairs"):
            return (f"genicam {s.get('trigger', '?')}: no pairs yet (left {s.get('left_received', 0)} "
                    f"frames, right {s.get('right_received', 0)})")
        return (f"genicam {s['trigger']}: {s['pair_rate_hz']:.1f} pairs/s, skew ({s['skew_basis']}) p50 "
                f"{s['skew_p50_s'] * 1e3:.3f} ms p99 {s['skew_p99_s'] * 1e3:.3f} ms "
                f"max {s['skew_max_s'] * 1e3:.3f} ms; dropped left {s['left_dropped']} "
                f"right {s['right_dropped']}, "
                f"unpaired left {s['left_unpaired']} right {s['right_unpaired']}")

    def close(self) -> None:
        """Stop the threads and the acquisition; safe to call twice."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads = []
        if self.cams and self._final is None:
            self._final = self.stats()
        for c in self.cams:
            try:
                c.cam.stop_acquisition()
            except Exception:  # noqa: BLE001 - camera gone: nothing to stop
                pass
        self.cams = []


def main(argv: list[str] | None = None) -> int:
    """``python3 -m nodes.camera.genicam``: list the GenICam cameras Aravis finds (serial, id, address) —
    the serials go into the camera node's ``left_id``/``right_id``."""
    import argparse

    p = argparse.ArgumentParser(prog="python3 -m nodes.camera.genicam",
                                description=main.__doc__.splitlines()[0],
                                epilog="example:\n  python3 -m nodes.camera.genicam",
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.parse_args(argv)
    try:
        devs = list_devices()
    except RuntimeError as exc:
        print(exc)
        return 2
    for d in devs:
        print(f"serial {d.serial:16s} id {d.device_id:32s} {d.protocol:11s} {d.address:16s} {d.vendor} "
              f"{d.model}")
    if not devs:
        print("no GenICam camera found (GigE: same subnet, firewall open for UDP 3956; USB3: udev rules)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
