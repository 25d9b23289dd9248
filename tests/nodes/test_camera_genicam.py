"""GenICam stereo camera and the honest skew of the UVC path.

Pure parts without hardware: frame-id gaps, device→host clock mapping, pairing by device stamp, sync planning,
device lookup, the UVC skew bound. The real GVCP/GVSP path: two Aravis fake GigE Vision cameras
(``arv-fake-gv-camera-0.8``) on 127.0.0.1 / 127.0.0.2 in a private network namespace
(:func:`flexsheet.benches.fakecam.isolated`), streamed through the camera node into the triangulator. This
file doubles as the script run inside the namespace (``python3 tests/nodes/test_camera_genicam.py child
OUT``).
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from flexsheet.vision.stereo_sync import CamFrame, ClockMap, FrameIdTracker, StereoPairer  # noqa: E402
from nodes.camera.device import DeviceSource, skew_upper_bound  # noqa: E402
from nodes.camera.genicam import DeviceInfo, resolve_device  # noqa: E402
from nodes.camera.genicam_sync import plan_sync  # noqa: E402

IMG = np.zeros((4, 6), np.uint8)


# ---------------------------------------------------------------------------------------------- pure parts
def test_frame_id_tracker_counts_gaps_wraps_and_resets():
    t = FrameIdTracker()
    assert [t.update(i) for i in (10, 11, 12, 15, 16)] == [0, 0, 0, 2, 0] and t.missing == 2
    t.update(16)                                    # duplicate: nothing missing
    t.update(14)                                    # late/reordered: nothing, newest kept
    assert t.update(17) == 0 and t.missing == 2
    # GigE Vision 16-bit block ids skip 0 on wrap: 65534, 65535, 1 is gapless; 65535 -> 2 misses id 1
    w = FrameIdTracker()
    assert [w.update(i) for i in (65534, 65535, 1, 2)] == [0, 0, 0, 0]
    assert w.update(65535) == 0 and w.last == 2 and w.missing == 0   # a late frame from before the wrap
    w2 = FrameIdTracker()
    assert [w2.update(i) for i in (65533, 65535, 2)] == [0, 1, 1] and w2.missing == 2
    # a device that uses 0 (Aravis fake camera): 65535 -> 0 is gapless once 0 was seen
    z = FrameIdTracker()
    z.update(0)
    z.update(1)
    z.last = 65535
    assert z.update(0) == 0 and z.update(2) == 1
    # acquisition restarted: big jump back is a reset, not 60000 lost frames
    r = FrameIdTracker()
    r.update(5000)
    assert r.update(3) == 0 and r.resets == 1 and r.missing == 0
    # 64-bit extended ids never wrap
    e = FrameIdTracker()
    assert [e.update(i) for i in (70000, 70001, 70005)] == [0, 0, 3]
    with pytest.raises(ValueError, match="frame_id"):
        e.update(-1)


def test_clock_map_latch_and_passive_envelope_recover_the_offset():
    rng = np.random.default_rng(3)
    true_off, drift, d_min = 1234.5, 30e-6, 0.003       # host = device*(1+drift) + off; delay >= 3 ms
    cm = ClockMap()
    dev = np.arange(0, 60, 0.02)                          # 60 s at 50 Hz
    host_at_exposure = dev * (1 + drift) + true_off
    arrival = host_at_exposure + d_min + rng.exponential(0.002, dev.size)
    for d, a in zip(dev, arrival, strict=True):
        cm.add_arrival(int(round(d * 1e9)), float(a))
    assert cm.method == "arrival" and np.isnan(cm.uncertainty())
    # the envelope sits on the fastest delivery: mapped = true exposure time + d_min, within 0.3 ms
    err = cm.to_host(int(dev[-1] * 1e9)) - (host_at_exposure[-1] + d_min)
    assert -1e-6 <= err < 3e-4, err
    assert 0.5e-3 < cm.delivery_jitter() < 3e-3         # median excess of an exponential(2 ms) delay
    # a latch overrides the envelope: offset exact to half the round trip
    t0 = host_at_exposure[-1] + 0.010
    cm.add_latch(int((dev[-1] + 0.010 / (1 + drift)) * 1e9), t0 - 2e-4, t0 + 2e-4)
    assert cm.method == "latch" and abs(cm.uncertainty() - 2e-4) < 1e-12
    assert abs(cm.to_host(int(dev[-1] * 1e9)) - host_at_exposure[-1]) < 2e-4 + 1e-6
    with pytest.raises(ValueError, match="reversed"):
        cm.add_latch(0, 2.0, 1.0)
    with pytest.raises(RuntimeError, match="no latch and no frame"):
        ClockMap().to_host(0)


def _streams(n, period, skew_fn, lose_right=(), incomplete_right=(), dev_off_r=0.0, delay=0.004):
    """Synthetic left/right frames in arrival order: (side, CamFrame); exposures on the host clock from
    100 s, the right camera's device clock ahead of the host by ``dev_off_r`` s."""
    t0_l = t0_r = 100.0
    ev = []
    for k in range(n):
        tl = t0_l + k * period
        ev.append((tl + delay, 0, CamFrame(IMG, 1000 + k, int(round(tl * 1e9)), tl + delay)))
        if k in lose_right:
            continue
        tr = t0_r + k * period + skew_fn(k)
        st = "missing_packets" if k in incomplete_right else "ok"
        ev.append((tr + delay + 1e-4, 1, CamFrame(IMG if st == "ok" else None, 7 + k,
                                                   int(round((tr + dev_off_r) * 1e9)),
                                                   tr + delay + 1e-4, st)))
    ev.sort(key=lambda e: e[0])
    return [(s, f) for _, s, f in ev]


def test_pairer_pairs_by_device_stamp_and_counts_drops():
    rng = np.random.default_rng(0)
    skews = rng.normal(0.0, 3e-4, 200)
    got = []
    pr = StereoPairer(tolerance_s=0.005, shared_clock=True, on_pair=got.append)
    for side, f in _streams(200, 0.02, lambda k: skews[k], lose_right={20, 21, 90}, incomplete_right={50}):
        pr.push(side, f)
    assert len(got) == 200 - 4
    assert all(p.right.frame_id - 7 == p.left.frame_id - 1000 for p in got)  # each with its true partner
    ks = np.array([p.left.frame_id - 1000 for p in got])
    assert np.all(np.diff(ks) > 0)                                            # in order
    assert np.allclose([p.skew_s for p in got], skews[ks], atol=2e-9)         # skew = right − left device
    s = pr.stats()
    assert s["right_missing_ids"] == 3 and s["right_incomplete"] == 1 and s["right_dropped"] == 4
    assert s["right_incomplete_by_status"] == {"missing_packets": 1}
    assert s["left_dropped"] == 0 and s["left_unpaired"] == 4 and s["right_unpaired"] == 0
    assert s["pairs"] == 196 and abs(s["skew_p50_s"] - np.median(np.abs(skews[ks]))) < 1e-9
    assert s["skew_basis"] == "device_clock"
    with pytest.raises(ValueError, match="side"):
        pr.push(2, CamFrame(IMG, 0, 0, 0.0))
    with pytest.raises(ValueError, match="tolerance_s"):
        StereoPairer(0.0, True)


def test_pairer_maps_independent_device_clocks_through_host_time():
    # right camera's clock started 900 s before the left's: raw stamps differ by 900 s, exposures by 0.5 ms
    ev = _streams(100, 0.02, lambda k: 5e-4, dev_off_r=900.0)
    shared = StereoPairer(0.005, shared_clock=True)
    indep = StereoPairer(0.005, shared_clock=False)
    n_shared = sum(len(shared.push(s, f)) for s, f in ev)
    pairs = [p for s, f in ev for p in indep.push(s, f)]
    assert n_shared == 0                                   # treating them as one clock pairs nothing
    assert len(pairs) >= 99 and indep.stats()["skew_basis"] == "host_mapped"
    assert all(abs(p.skew_s - 5e-4) < 2e-4 for p in pairs)


def test_plan_sync_degrades_with_a_log_line_per_missing_feature():
    full = {"ptp": "PtpEnable", "trigger_sources": ["Line0", "Line1", "Software"], "software_trigger": True,
            "line_selector": ["Line1", "Line2"], "line_source": ["Off", "ExposureActive"]}
    fake = {"ptp": None, "trigger_sources": ["Line0", "Software"], "software_trigger": True,
            "line_selector": [], "line_source": []}
    p = plan_sync(full, full, "hardware", "auto")
    assert (p.trigger, p.ptp, p.notes) == ("hardware", True, [])
    p = plan_sync(full, full, "master", "off")
    assert (p.trigger, p.ptp, p.notes) == ("master", False, [])
    p = plan_sync(fake, fake, "hardware", "auto")          # fake camera: Line0 only, no PTP
    assert p.trigger == "software" and not p.ptp and "no TriggerSource 'Line1'" in p.notes[0]
    p = plan_sync(fake, fake, "hardware", "auto", trigger_line="Line0")
    assert p.trigger == "hardware" and p.notes == []
    p = plan_sync(fake, full, "master", "on")
    assert p.trigger == "software" and "left camera has no output line 'Line2'" in p.notes[0]
    assert any("neither PtpEnable nor GevIEEE1588" in n for n in p.notes)
    p = plan_sync(dict(fake, software_trigger=False), fake, "software", "auto")
    assert p.trigger == "free" and "left camera has no TriggerSoftware" in p.notes[0]
    assert "exposures are not synchronised" in p.notes[-1]
    with pytest.raises(ValueError, match="trigger must be"):
        plan_sync(full, full, "genlock", "auto")


def test_resolve_device_by_serial_id_or_address():
    devs = [DeviceInfo("Basler-21234567", "21234567", "192.168.20.11", "00:30:53:01:02:03", "Basler", "a2A"),
            DeviceInfo("Basler-21234568", "21234568", "192.168.21.11", "00:30:53:01:02:04", "Basler", "a2A")]
    assert resolve_device("21234568", devs) is devs[1]
    assert resolve_device("Basler-21234567", devs) is devs[0]
    assert resolve_device("192.168.21.11", devs) is devs[1]
    with pytest.raises(ValueError, match=r"'999' not found; cameras found: 21234567 \(Basler-21234567"):
        resolve_device("999", devs)
    with pytest.raises(ValueError, match="left_id/right_id"):
        resolve_device("", devs)


def _video(path: Path, w: int, h: int, n: int, fps: float = 30.0) -> str:
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert vw.isOpened()
    for k in range(n):
        img = np.full((h, w, 3), 40, np.uint8)
        cv2.circle(img, (10 + 3 * k, h // 2), 6, (255, 255, 255), -1)
        vw.write(img)
    vw.release()
    return str(path)


def test_uvc_skew_is_zero_by_construction_or_an_upper_bound(tmp_path):
    # one side-by-side device: both halves from one frame -> 0 by construction
    sbs = DeviceSource(_video(tmp_path / "sbs.avi", 128, 48, 5), None)
    left, right, _, skew = sbs.read()
    assert left.shape == right.shape == (48, 64) and skew == 0.0 and sbs.skew_kind == "zero_by_construction"
    sbs.close()
    # two devices (30 fps files): the skew is unknown; reported = |grab interval| + one frame period >= 33 ms
    two = DeviceSource(_video(tmp_path / "l.avi", 64, 48, 8), _video(tmp_path / "r.avi", 64, 48, 8))
    assert two.skew_kind == "upper_bound"
    skews = [two.read()[3] for _ in range(5)]
    assert all(1 / 30 <= s < 1 / 30 + 0.05 for s in skews), skews
    two.close()
    assert skew_upper_bound(-0.002, 1 / 30) == pytest.approx(0.002 + 1 / 30)
    with pytest.raises(ValueError, match="frame_period_s"):
        skew_upper_bound(0.0, 0.0)


def test_camera_params_genicam_need_two_ids():
    from pydantic import ValidationError

    from nodes.camera.node import CameraParams

    with pytest.raises(ValidationError, match="left_id must name a camera"):
        CameraParams(source="genicam", right_id="R1")
    with pytest.raises(ValidationError, match="both 'X1'"):
        CameraParams(source="genicam", left_id="X1", right_id="X1")
    with pytest.raises(ValidationError, match="trigger"):
        CameraParams(source="genicam", left_id="a", right_id="b", trigger="genlock")
    assert CameraParams(source="genicam", left_id="a", right_id="b").trigger == "software"


def _display_yaml(folder) -> str:
    """A display.yaml with the nominal entries (the lab's registration stands in; these tests are about the
    GenICam path, not the geometry)."""
    from flexsheet.calibration.display_calib import nominal_display_calib
    from flexsheet.calibration.display_calib_file import write_display_calib

    path = str(Path(folder) / "display.yaml")
    write_display_calib(path, nominal_display_calib())
    return path


def test_genicam_camera_not_found_fails_setup_with_a_clear_error(tmp_path):
    from flexsheet.runtime.testing import NodeHarness
    from nodes.camera.node import CameraNode

    async def scenario():
        async with NodeHarness(CameraNode, params={"source": "genicam", "left_id": "NOSUCHCAM1",
                                                   "right_id": "NOSUCHCAM2", "discover_timeout_s": 0.0,
                                                   "display_calib": _display_yaml(tmp_path)}):
            pass
    with pytest.raises(ValueError, match="camera 'NOSUCHCAM1' not found"):
        asyncio.run(scenario())


# ------------------------------------------------------------- two fake GigE Vision cameras (real GVCP/GVSP)
def _in_namespace(args: list[str], timeout: float = 120.0) -> subprocess.CompletedProcess:
    from flexsheet.benches.fakecam import isolated

    return subprocess.run(isolated(args), capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def test_genicam_fake_pair_streams_through_camera_node_into_triangulator(tmp_path):
    out = tmp_path / "child.json"
    r = _in_namespace([sys.executable, str(Path(__file__)), "child", str(out)])
    assert r.returncode == 0 and out.exists(), f"child failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    res = json.loads(out.read_text())
    s = res["stats"]
    # frames arrive: 25 Hz for ~4 s, paired (slack for a loaded 2-core CI machine)
    assert res["frames"] >= 50 and s["pairs"] >= res["frames"]
    assert res["shapes"] == [[512, 640]] and res["calib_size"] == [640, 512]
    assert res["mean_grey"] > 50                          # the fake camera's ramp pattern, not a blank frame
    # device stamps: strictly increasing per camera, on the fake camera's 40 ms frame grid
    for side in ("left", "right"):
        d = np.diff(np.array(res[f"{side}_device_ns"], dtype=np.int64)) * 1e-9
        assert np.all(d > 0), f"{side} device stamps not monotonic"
        assert abs(np.median(d) - 0.040) < 0.002, np.median(d)
    # each frame's left/right come from the same grid slot: measured skew small, reported in the frames
    skew = np.array(res["stereo_skew"])
    dev_l = np.array(res["left_device_ns"], dtype=np.int64)
    raw = (np.array(res["right_device_ns"], dtype=np.int64) - dev_l) * 1e-9
    assert np.all(np.abs(skew) <= 0.010) and np.median(np.abs(skew)) < 0.003
    assert np.allclose(skew, raw, atol=1e-9)              # shared clock: skew = right − left device stamp
    # exposure stamps are the left device stamps mapped to host time: same spacing, except where the
    # passive envelope drops to a faster delivery (offset only falls, or rises by <= 100 ppm)
    ex, hd = np.array(res["exposure_stamp"]), np.array(res["header_stamp"])
    dl = np.diff(np.array(res["left_device_ns"], dtype=np.int64)) * 1e-9
    step = np.diff(ex) - dl
    assert np.all(np.diff(ex) > 0) and np.all(step <= 1e-4 * dl + 1e-6) and np.all(step > -0.015)
    assert abs(np.median(hd - ex)) < 0.05                 # host time base (published a few ms after)
    # skew and drops in /diagnostics
    msg = res["hb_message"]
    assert msg.startswith("genicam free:") and f"p50 {s['skew_p50_s'] * 1e3:.3f} ms" in msg
    assert f"dropped left {s['left_dropped']} right {s['right_dropped']}" in msg
    assert s["left_serial"] == "FSL0001" and s["right_serial"] == "FSR0001" and s["trigger"] == "free"
    # the triangulator consumed them: no marker in a ramp pattern -> invalid fixes, no crash, nothing rejected
    assert res["fingertips"] >= 10 and res["valid"] == 0
    assert res["tri_errors"] == 0 and res["tri_rejected"] == 0
    assert res["fingertips"] + res["tri_dropped"] == res["tri_received"]


def test_bench_camera_genicam_reports_rate_skew_and_dropped_frames(tmp_path):
    out = tmp_path / "bench.json"
    r = subprocess.run([sys.executable, "-m", "flexsheet.benches.camera", "--genicam", "--seconds", "3",
                        "--lost-permille", "5", "--out", str(out), "--json"],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    b = json.loads(out.read_text())
    assert b["mode"] == "fake" and b["trigger"] == "free" and b["skew_basis"] == "device_clock"
    assert 20.0 < b["left_fps"] <= 26.0                  # the clean camera streams at ~25 Hz
    # 5 per mille of ~240 packets per frame lost: most right frames arrive incomplete and are counted
    assert b["right_dropped"] >= 0.3 * b["left_received"] and b["left_dropped"] <= 2
    assert b["right_missing_packets"] > 0
    for side in ("left", "right"):                       # every received frame accounted for
        assert b["pairs"] == (b[f"{side}_received"] - b[f"{side}_unpaired"] - b[f"{side}_incomplete"]
                              - b[f"{side}_queued"])
    assert b["right_fps"] < 0.7 * b["left_fps"] and abs(b["pair_rate_hz"] - b["right_fps"]) < 2.0
    assert b["skew_p99_ms"] <= 10.0 and b["interval_p50_ms"] >= 40.0 - 0.5


# ------------------------------------------------------------------------------- child (inside the namespace)
async def _child(out_path: str) -> None:
    from flexsheet.benches.fakecam import fake_pair
    from flexsheet.runtime.testing import NodeHarness
    from messages import topics
    from nodes.camera.node import CameraNode
    from nodes.triangulator.node import TriangulatorNode

    cam_params_exposure = 0.004
    cam_params = {"exposure_s": cam_params_exposure, "source": "genicam", "left_id": "FSL0001",
                  "right_id": "FSR0001", "rate_hz": 25.0, "trigger": "free", "device_clock": "shared",
                  "model": "ximea", "display_calib": _display_yaml(Path(out_path).parent)}
    with fake_pair(("FSL0001", "FSR0001")):
        async with NodeHarness(CameraNode, cam_params, name="camera") as cam, \
                NodeHarness(TriangulatorNode, {"max_stereo_skew_s": 0.010}, name="triangulator") as tri:
            rec = {}
            pairer = cam.node.source.genicam.pairer
            forward = pairer.on_pair

            def spy(p):  # device stamps of each pair, keyed by the exposure stamp the node will publish
                rec[round(p.stamp_s + 0.5 * cam_params_exposure, 6)] = (p.left.device_ns, p.right.device_ns)
                forward(p)
            pairer.on_pair = spy
            tri.inject(topics.CALIBRATION, cam.messages(topics.CALIBRATION)[0])
            await tri.settle(0.2)
            n0 = len(cam.messages(topics.STEREO))
            cam.transport.listeners.append(tri.transport.deliver)   # camera -> triangulator (real codec)
            await asyncio.sleep(4.0)
            await asyncio.to_thread(cam.node.source.genicam.close)  # stop acquisition, keep the figures
            await tri.settle(0.5)
            cam.transport.listeners.clear()
            frames = cam.messages(topics.STEREO)[n0:]
            hb = cam.node.heartbeat()
            stats = cam.node.source.genicam.stats()
            fts = tri.messages(topics.FINGERTIP)
            sub = tri.node._subs[topics.STEREO.name][0]
            rec = [rec[round(f.exposure_stamp, 6)] for f in frames]
    res = {
        "frames": len(frames), "shapes": sorted({list(f.left.shape).__repr__() for f in frames}),
        "calib_size": [int(v) for v in cam.messages(topics.CALIBRATION)[0].image_size],
        "mean_grey": float(np.mean([f.left.mean() for f in frames[:5]])) if frames else 0.0,
        "left_device_ns": [int(a) for a, _ in rec], "right_device_ns": [int(b) for _, b in rec],
        "stereo_skew": [f.stereo_skew for f in frames], "exposure_stamp": [f.exposure_stamp for f in frames],
        "header_stamp": [f.header.stamp for f in frames], "hb_message": hb.message, "hb_state": hb.state,
        "stats": {k: v for k, v in stats.items() if not isinstance(v, float) or np.isfinite(v)},
        "fingertips": len(fts), "valid": sum(f.valid for f in fts), "tri_rejected": tri.node.rejected_total,
        "tri_errors": tri.node.errors_total, "tri_dropped": sub.stats.dropped,
        "tri_received": sub.stats.count + sub.stats.dropped,
    }
    res["shapes"] = [json.loads(s) for s in res["shapes"]]
    Path(out_path).write_text(json.dumps(res))


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] == "child":
    t0 = time.time()
    asyncio.run(_child(sys.argv[2]))
    print(f"child done in {time.time() - t0:.1f} s")
