"""The pose path's fingertip filter (flexsheet.planning.pose_filter) alone and in the surface planner: a 10 Hz
tremor on a slow stroke is cut in the sheet's orientation while the stroke is not delayed and the push depth
is not filtered."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.pose_filter import PoseFilter
from flexsheet.planning.surface_planner import SurfacePlanner

R = geometry.CYLINDER_RADIUS
FS = 48.0          # the camera's fingertip rate, Hz
TREMOR = 5e-5      # m rms, the scripted finger's per axis


def band_rms(y: np.ndarray, lo: float, hi: float) -> float:
    """rms (y's unit) of the part of ``y`` (N,), sampled at FS, between ``lo`` and ``hi`` Hz."""
    Y = np.fft.rfft(y - y.mean())
    f = np.fft.rfftfreq(len(y), 1.0 / FS)
    Y[(f < lo) | (f > hi)] = 0.0
    return float(np.sqrt(np.mean(np.fft.irfft(Y, len(y)) ** 2)))


def stroke_angles(t: np.ndarray, speed: float = math.radians(6.0), t0: float = 1.0, t1: float = 9.0):
    """The stroke's angle (N,) rad at ``t`` (N,) s: at rest, then ``speed`` rad/s from ``t0`` to ``t1``."""
    return speed * (np.clip(t, t0, t1) - t0)


def run_filter(f: PoseFilter, x: np.ndarray) -> np.ndarray:
    """``x`` (N,) m along one axis through ``f`` at FS; (N,) m."""
    return np.array([f.step((float(v), 0.0, 0.0), None if k == 0 else 1.0 / FS)[0] for k, v in enumerate(x)])


def test_constant_and_ramp_pass_without_offset_or_lag():
    t = np.arange(0.0, 6.0, 1.0 / FS)
    f = PoseFilter(3.0, 3.0)
    const = run_filter(f, np.full(len(t), 0.012))
    assert np.max(np.abs(const - 0.012)) < 1e-15
    f.reset()
    ramp = 0.0037 * t                                     # the 10 s stroke's speed on the cylinder, m/s
    y = run_filter(f, ramp)
    steady = t > 2.0
    assert np.max(np.abs(y[steady] - ramp[steady])) < 1e-9   # no lag: a 1 ms lag would be 3.7 µm


def test_tremor_band_cut_and_slow_band_kept():
    t = np.arange(0.0, 20.0, 1.0 / FS)
    f = PoseFilter(3.0, 3.0)
    tremor = TREMOR * math.sqrt(2.0) * np.sin(2 * math.pi * 10.0 * t)
    y = run_filter(f, tremor)
    assert band_rms(y[int(FS) * 4:], 7.0, 13.0) < 0.3 * band_rms(tremor[int(FS) * 4:], 7.0, 13.0)
    f.reset()
    slow = 0.001 * np.sin(2 * math.pi * 0.5 * t)           # the finger's wander band
    y = run_filter(f, slow)
    err = y[96:] - slow[96:]
    assert np.sqrt(np.mean(err ** 2)) < 0.07 * np.sqrt(np.mean(slow[96:] ** 2))


def test_off_returns_the_sample_and_bad_corners_raise():
    f = PoseFilter(0.0, 3.0)
    assert not f.enabled and f.step((1.0, 2.0, 3.0), 0.02) == (1.0, 2.0, 3.0)
    for bad in ((-1.0, 3.0), (math.nan, 3.0), (3.0, 0.0), (3.0, math.inf)):
        with pytest.raises(ValueError):
            PoseFilter(*bad)
    with pytest.raises(ValueError):
        PlannerConfig(pose_cutoff=-1.0)


def planner_angles(cfg: PlannerConfig, t: np.ndarray, phi: np.ndarray, tremor: np.ndarray,
                   depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A finger on the paper's cylinder at angles ``phi`` (N,) rad plus ``tremor`` (N,) m along the surface,
    ``depth`` (N,) m in: the plans' normal angles (N,) rad and depths (N,) m."""
    c = paper_cylinder()
    pl = SurfacePlanner(c, cfg)
    ang, dep = [], []
    for k in range(len(t)):
        a = phi[k] + tremor[k] / R
        plan = pl.update(float(t[k]), c.point_at(-a, 0.0, R - depth[k]))
        n = np.array(plan.normal)
        ang.append(math.atan2(n[2], n[0]))
        dep.append(plan.depth)
    return np.array(ang), np.array(dep)


def test_planner_orientation_ignores_tremor_but_follows_stroke_and_push():
    t = np.arange(0.0, 10.0, 1.0 / FS)
    phi = stroke_angles(t)
    tremor = TREMOR * math.sqrt(2.0) * np.sin(2 * math.pi * 10.0 * t)
    depth = 0.0005 + 0.002 * (1 - np.cos(2 * math.pi * 2.0 * t))       # a 2 Hz press
    off = PlannerConfig(pose_cutoff=0.0)
    raw, raw_depth = planner_angles(off, t, phi, tremor, depth)
    filt, filt_depth = planner_angles(PlannerConfig(), t, phi, tremor, depth)
    ref, _ = planner_angles(off, t, phi, np.zeros(len(t)), depth)       # the stroke alone, unfiltered
    trem_raw = band_rms(raw - ref, 7.0, 13.0)
    trem_filt = band_rms(filt - ref, 7.0, 13.0)
    assert trem_raw == pytest.approx(TREMOR / R, rel=0.05)     # unfiltered: the whole tremor turns the sheet
    assert trem_filt < 0.3 * trem_raw
    # the slow stroke is not delayed: mid-stroke, the mean orientation error is under a 1 ms lag's
    mid = (t > 3.0) & (t < 8.5)
    bias = np.mean(filt[mid] - ref[mid])
    assert abs(bias) < math.radians(6.0) * 1e-3
    # the push depth follows the raw finger sample by sample (the stretch path is not filtered)
    assert np.max(np.abs(filt_depth - raw_depth)) < 1e-6


def test_away_the_sheet_goes_to_the_raw_fingertip():
    c = paper_cylinder()
    pl = SurfacePlanner(c, PlannerConfig())
    t = np.arange(0.0, 2.0, 1.0 / FS)
    phi = 0.3 + 0.2 * t + TREMOR * math.sqrt(2.0) * np.sin(2 * math.pi * 10.0 * t) / R
    for k in range(len(t)):
        p = c.point_at(-phi[k], 0.0, R + 0.01)                   # 10 mm away: not touching
        plan = pl.update(float(t[k]), p)
        assert not plan.touching
        assert np.max(np.abs(np.array(plan.contact) - np.array(c.project(p).point))) < 1e-12
