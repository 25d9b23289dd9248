"""The honest camera twin: images formed through a hidden truth, the calibration a lab would have,
realistic sensing (measured noise, optical blur, self-occlusion, dropped frames), and the fingertip error
against the truth measured from the images — for three truth seeds (no tuning to one).

The registration of each seed is the twin's own (``flexsheet.twin.registration.sim_display_calib``, test
preset, cached per seed under ~/.cache/flexsheet/display — shared with the registration tests; ~20 s per seed
when not cached).
"""

import asyncio
import math

import numpy as np
import pytest

from flexsheet.calibration.display_calib import CameraEntry, DisplayCalib, Provenance, nominal_display_calib
from flexsheet.calibration.display_calib_file import write_display_calib
from flexsheet.experiments import vision_twin as vt
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.camera import StereoCameraTwin, twin_renderer
from flexsheet.twin.camera_config import XIMEA_SENSOR, SimConfig
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.camera_model import camera_model
from flexsheet.vision.tracker import FingertipTracker, TrackerConfig
from messages import topics
from nodes.camera.node import CameraNode

SEEDS = (0, 1, 2)
TARGET_MM = 0.5                     # ≤ 0.5 mm RMS static at 0.5 m


@pytest.fixture(scope="module")
def registered():
    """seed → (truth, camera entry from the twin's camera-pose procedure)."""
    out = {}
    for s in SEEDS:
        truth = TwinTruth.draw(s)
        out[s] = (truth, vt.registered_camera(truth, quick=True)[0])
    return out


@pytest.mark.parametrize("seed", SEEDS)
def test_true_camera_image_differs_from_nominal_render(seed):
    """The camera twin renders through the truth's cameras and mount, not the nominal ones: the marker lands
    pixels away from where the nominal model puts it; the ideal truth renders exactly the nominal image."""
    p = np.array([0.02, 0.01, 0.0])
    cfg = SimConfig(noise_scale=0.0)
    nom = nominal_display_calib().camera
    nominal = StereoCameraTwin(nom.stereo, nom.T_display_camera, cfg)
    true = twin_renderer(TwinTruth.draw(seed), cfg)
    ul_n, ur_n = nominal.model.project(nominal.to_camera(p))
    ul_t, ur_t = true.model.project(true.to_camera(p))
    shift = min(np.linalg.norm(ul_t - ul_n), np.linalg.norm(ur_t - ur_n))
    assert shift > 1.0, shift                          # mount spread 10 mm / 1°: several px at 0.5 m
    Ln, _ = nominal.render(p)
    Lt, _ = true.render(p)
    assert np.mean(np.abs(Ln.astype(int) - Lt.astype(int))) > 1.0
    ideal = twin_renderer(TwinTruth.draw(seed, "ideal"), cfg)
    Li, Ri = ideal.render(p)
    Ln2, Rn2 = StereoCameraTwin(nom.stereo, nom.T_display_camera, cfg).render(p)
    assert np.array_equal(Li, Ln2) and np.array_equal(Ri, Rn2)


def test_sensor_noise_is_the_measured_model():
    """Two renders of one still frame differ by noise of σ² = read² + gain·I (the XIMEA measurement) at the
    background's level — the noise is formed in the image, not added to a centroid."""
    truth = TwinTruth.draw(0)
    rnd = twin_renderer(truth, SimConfig(clutter=False))
    p = np.array([0.02, 0.0, 0.0])
    a, _ = rnd.render(p)
    b, _ = rnd.render(p)
    flat = rnd.backgrounds[0]
    level = float(np.median(flat))
    sel = np.abs(flat.astype(float) - level) < 1
    sel[200:330, 250:420] = False                      # away from the finger and the marker
    d = (a.astype(float) - b.astype(float))[sel]
    sigma = float(np.std(d) / math.sqrt(2.0))
    model = math.sqrt(XIMEA_SENSOR["read_dn"] ** 2 + XIMEA_SENSOR["shot_gain"] * level)
    assert abs(sigma - model) < 0.12 * model, (sigma, model, level)
    quiet = twin_renderer(truth, SimConfig(clutter=False, noise_scale=0.0))
    assert np.array_equal(quiet.render(p)[0], quiet.render(p)[0])


def test_fingertip_error_from_images_within_target(registered):
    """Static finger 0.43–0.52 m from the camera, registered camera (display.yaml from the twin's procedure),
    three truth seeds: RMS error against the truth ≤ 0.5 mm with ≥ 95 % valid frames. The error comes out of
    the images: it is not zero, it grows when the camera noise is raised 8×, and a perfect registration (the
    truth's own camera, scoring only) removes only a part of it."""
    pts = vt.static_points(16, seed=3)
    for s, (truth, cam) in registered.items():
        r = vt.static_error(truth, cam.stereo, cam.T_display_camera, SimConfig(), pts, 2, s)
        assert r["valid_rate"] >= 0.95, (s, r["reasons"])
        assert 0.03 < r["rms_mm"] <= TARGET_MM, (s, r)
        loud = vt.static_error(truth, cam.stereo, cam.T_display_camera, SimConfig(noise_scale=8.0), pts, 2, s)
        assert loud["rms_mm"] > 1.5 * r["rms_mm"] or loud["valid_rate"] < 0.9, (s, r["rms_mm"], loud)
        reg = vt.registration_error(truth, cam)
        assert reg["translation_error_mm"] < 2.0 and reg["rotation_error_deg"] < 0.3, reg


def test_moving_fingertip_error_at_stroke_speed(registered):
    """2 s of the paper's 10 s stroke (0→60° of the cylinder, ~6 mm/s, motion blur over the 4 ms exposure)
    with 1 % dropped frames: RMS ≤ 0.5 mm on every seed, and the tracker keeps ≥ 95 % of the frames it
    gets."""
    for s, (truth, cam) in registered.items():
        m = vt.moving_error(truth, cam.stereo, cam.T_display_camera, SimConfig(), 10.0, 0.01, window_s=2.0,
                            sim_seed=s)
        assert m["valid_rate"] >= 0.95 and m["rms_mm"] <= TARGET_MM, (s, m)
        assert 0.002 < m["speed_mps"][0] < 0.02


@pytest.mark.parametrize("seed", SEEDS)
def test_self_occlusion_by_the_finger(seed, registered):
    """The finger hides the nail marker from the camera when it points toward it: visible fraction falls
    from 1 (finger away from the camera, azimuth +40°) through a partial occlusion to 0 (finger toward the
    camera, -45°); the detected area shrinks with it; the hidden marker gives no fix (never a wrong one) and
    a partly hidden one is either refused (occluded) or has a larger error than the unoccluded marker."""
    truth, cam = registered[seed]
    p = np.array([0.02, 0.0, 0.01])

    def finger(az, el=40.0):
        a, e = math.radians(az), math.radians(el)
        return (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e))

    def shoot(az):
        rnd = twin_renderer(truth, SimConfig(finger_dir=finger(az), noise_scale=0.0))
        L, R = rnd.render(p)
        res = FingertipTracker(cam.stereo, TrackerConfig(), cam.T_display_camera).process(L, R, 0.0)
        return min(rnd.marker_visibility(p)), res

    azs = np.arange(-50.0, 41.0, 5.0)
    shots = [shoot(a) for a in azs]
    vis = np.array([v for v, _ in shots])
    assert vis[-1] == pytest.approx(1.0) and vis.min() < 0.05, vis
    clear = shots[-1][1]
    assert clear.valid and np.linalg.norm(clear.position - p) < 1e-3
    for v, res in shots:
        if v < 0.05:
            assert not res.valid and np.all(res.position == 0), (v, res.reason)
    partial = [(v, res) for v, res in shots if 0.3 < v < 0.9]
    assert partial, vis
    e_clear = np.linalg.norm(clear.position - p)
    for v, res in partial:
        assert (not res.valid) or np.linalg.norm(res.position - p) > e_clear, (v, res.reason)


def test_dropped_frames_honoured_in_the_stroke():
    """moving_error drops each frame with the given probability: 25 % of 240 frames within 4σ (binomial)."""
    truth = TwinTruth.draw(0, "ideal")
    cam = nominal_display_calib().camera
    m = vt.moving_error(truth, cam.stereo, cam.T_display_camera, SimConfig.ideal(), 10.0, 0.25, window_s=5.0)
    n = m["frames"]
    assert n == 240 and abs(m["dropped"] - 0.25 * n) < 4 * math.sqrt(n * 0.25 * 0.75)
    assert m["n"] <= n - m["dropped"]


def _write_display(path, T):
    cal = DisplayCalib(camera=CameraEntry(T, Provenance("test fit", source="lab", n_poses=10,
                                                        residuals={"rms_px": 0.1, "residual_mm": 0.3})))
    write_display_calib(str(path), cal)


def test_camera_node_publishes_the_calibrated_registration_not_the_truth(tmp_path):
    """The sim camera renders through the truth (seed 2) but publishes display.yaml's camera pose with the
    stereo file's intrinsics — never the truth's, never the look_at default."""
    truth = TwinTruth.draw(2)
    nom = nominal_display_calib().camera
    T = nom.T_display_camera.copy()
    T[:3, 3] += [0.003, -0.002, 0.001]                 # a registration 3.7 mm off the design mount
    _write_display(tmp_path / "display.yaml", T)

    async def scenario():
        params = {"rate_hz": 40.0, "display_calib": str(tmp_path / "display.yaml"),
                  "twin": {"realism": "realistic", "truth_seed": 2}}
        async with NodeHarness(CameraNode, params=params) as h:
            cal = (await h.wait_for(topics.CALIBRATION, n=1, timeout=5.0))[0]
            assert np.allclose(cal.T_display_camera, T)
            assert not np.allclose(cal.T_display_camera[:3, 3], truth.T_display_camera[:3, 3], atol=1e-3)
            assert not np.allclose(cal.T_display_camera, nom.T_display_camera)
            shipped = camera_model("ximea")
            assert np.allclose(cal.K1, shipped["K1"]) and not np.allclose(cal.K1, truth.camera_calib["K1"])
            assert np.allclose(h.node.source.renderer.T_dc, truth.T_display_camera)  # images: the truth's
            assert np.allclose(h.node.source.renderer.model.K1, truth.camera_calib["K1"])
            assert ("display.yaml" in h.node.status_line()
                    and "realistic twin, truth seed 2" in h.node.status_line())
    asyncio.run(scenario())


@pytest.mark.parametrize("params,match", [
    ({}, "display_calib is not set"),                                   # realistic twin: no nominal fallback
    ({"source": "files", "files_left": "x*", "files_right": "y*"}, "display_calib is not set"),   # lab path
    ({"display_calib": "/nonexistent/display.yaml"}, "not found"),
])
def test_camera_node_refuses_a_missing_registration(params, match):
    async def scenario():
        with pytest.raises(Exception, match=match):
            async with NodeHarness(CameraNode, params={"rate_hz": 40.0, **params}):
                pass
    asyncio.run(scenario())


def test_camera_node_drops_frames_at_the_configured_rate(tmp_path):
    """drop_rate 0.3 at 100 Hz: about 30 % of the ticks publish nothing (counted, and said in
    /diagnostics)."""
    _write_display(tmp_path / "display.yaml", nominal_display_calib().camera.T_display_camera)

    async def scenario():
        params = {"rate_hz": 100.0, "display_calib": str(tmp_path / "display.yaml"), "drop_rate": 0.3,
                  "twin": {"realism": "ideal", "truth_seed": 0}}
        async with NodeHarness(CameraNode, params=params) as h:
            node = h.node
            for _ in range(60):       # 60 ticks: 0.6 s at 100 Hz, longer on a loaded machine (wall clock)
                await h.settle(0.5)
                if node.frames + node.source.dropped >= 60:
                    break
            frames, dropped = node.frames, node.source.dropped
            n = frames + dropped
            assert n >= 60
            frac = dropped / n
            assert abs(frac - 0.3) < 4 * math.sqrt(0.3 * 0.7 / n), (frac, n)
            # every frame counted as sent arrives (the last may
            # still be in flight when counted): seq 0..frames-1
            got = await h.wait_for(topics.STEREO, n=frames, timeout=5.0)
            assert [m.header.seq for m in got[:frames]] == list(range(frames))
            assert (
                f"dropped {node.source.dropped} of {node.frames + node.source.dropped}" in node.status_line())
    asyncio.run(scenario())
