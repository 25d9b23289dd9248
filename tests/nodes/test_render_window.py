"""The projector window: under Xvfb, a screenshot read back through X equals the offscreen render of
the same inputs in each stereo format; frame-sequential shows left then right and stays in phase across a
dropped vsync; mirror_x flips; the node's window output publishes frames and reports pacing on /diagnostics.

The window runs on a thread of its own (as in the node): a thread holding the headless EGL context cannot make
a GLX context current (libglvnd). Screenshots come from the X server (XCB GetImage), not from OpenGL.
"""

import asyncio
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from flexsheet.benches.xvfb import XvfbError, grab, xvfb
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface
from flexsheet.rendering.pacing import LEFT, RIGHT, FramePacer, frame_layout
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh
from flexsheet.runtime.testing import NodeHarness
from messages import topics

W, H = 160, 120
R = geometry.CYLINDER_RADIUS
TOL = 2  # max abs difference per channel (8-bit) between the screenshot and the offscreen render


def _sheet():
    th = np.radians(30)
    return SheetSurface([-R + R * np.cos(th), 0, -R * np.sin(th)], [np.cos(th), 0, -np.sin(th)], [0, 1, 0])


def _draw(r):
    r.set_mesh(*cylinder_draw_mesh(n_around=48, n_along=16))
    r.set_model("flat", _sheet())          # a pre-distorted, shaded image: not a trivial picture
    r.render_pair()


@pytest.fixture(scope="module")
def display():
    try:
        with xvfb(1280, 1024) as d:
            yield d
    except XvfbError as exc:   # pragma: no cover - docker/install.sh installs xvfb
        pytest.fail(str(exc))


@pytest.fixture(scope="module")
def offscreen():
    """Offscreen (EGL) renders of the same inputs: {ipd: (left, right)}; made with no DISPLAY set."""
    saved = os.environ.pop("DISPLAY", None)
    try:
        out = {}
        for ipd in (0.064, 0.0):
            r = StereoRenderer(Projector.default(W, H, pixel=0.0028), ipd=ipd)
            _draw(r)
            out[ipd] = r.read_pair()
            r.release()
        return out
    finally:
        if saved is not None:
            os.environ["DISPLAY"] = saved


@pytest.fixture
def window(display, monkeypatch):
    """Factory of WindowOutputs on a dedicated thread; yields (open, call)."""
    monkeypatch.setenv("DISPLAY", display)
    ex = ThreadPoolExecutor(1, thread_name_prefix="test-window")
    outs = []

    def call(fn, *a, **kw):
        return ex.submit(fn, *a, **kw).result(timeout=60)

    def open_(**kw):
        from nodes.renderer.window import WindowOutput

        kw.setdefault("refresh_hz", 4.0)   # 250 ms frames: a screenshot fits inside one "vsync"
        out = call(lambda: WindowOutput(Projector.default(W, H, pixel=0.0028), fullscreen=False, **kw))
        outs.append(out)
        call(_draw, out.renderer)
        return out

    yield open_, call
    for out in outs:
        call(out.close)
    ex.shutdown()


def shot(display, out):
    x, y = out.window.position
    w, h = out.window.framebuffer_size
    return grab(display, (x, y, x + w, y + h)).astype(int)


def diff(a, b):
    assert a.shape == b.shape, (a.shape, b.shape)
    return int(np.abs(a.astype(int) - b.astype(int)).max())


# ---------------------------------------------------------------------------------------------- pure pacing
def test_pacer_counts_missed_vsyncs_and_keeps_the_eyes_in_phase():
    hz = 120.0
    period = 1 / hz
    p = FramePacer(hz)
    rng = np.random.default_rng(3)
    # the display: frames land on these vsyncs (gaps = dropped vsyncs), swap returns jitter by up to 1.5 ms
    landed = [0, 1, 2, 3, 5, 6, 7, 10, 11, 12, 13, 14, 16]
    naive_eye, shown = 0, []
    for k in landed:
        eye = p.next_eye()
        shown.append((k, eye, naive_eye))
        p.on_swap(100.0 + k * period + rng.uniform(-1.5e-3, 1.5e-3))
        naive_eye ^= 1
    # each frame that lands on the vsync after its predecessor shows the eye of that vsync's parity
    on_time = [(k, e) for (k, e, _), prev in zip(shown[1:], landed[:-1], strict=True) if k == prev + 1]
    assert all(e == k % 2 for k, e in on_time) and len(on_time) == 9
    # a per-frame counter would be out of phase after the
    # 1-vsync drop (vsync 4) and stay so until the next odd drop
    assert [n == k % 2 for k, _, n in shown].count(False) >= 3
    st = p.stats()
    assert st.missed_vsyncs == 1 + 2 + 1 and st.eye_resyncs == 2 and st.frames == len(landed)
    assert abs(st.period_ms - 1e3 / hz) < 0.2 and st.source == "time"
    assert abs(st.interval_mean_ms - (landed[-1] - landed[0]) * period * 1e3 / (len(landed) - 1)) < 0.5


def test_pacer_uses_the_media_stream_counter_and_rejects_bad_input():
    p = FramePacer(120.0, swap_eyes=True)
    assert p.next_eye() == RIGHT
    for t, msc in ((0.0, 1000), (0.0083, 1001), (0.03, 1004)):   # the counter, not the times, decides
        p.on_swap(t, msc)
    assert p.missed == 2 and p.resyncs == 0 and p.stats().source == "counter"
    assert p.next_eye() == ((1005 - 1000) % 2) ^ 1
    with pytest.raises(ValueError, match="backwards"):
        p.on_swap(0.01)
    with pytest.raises(ValueError, match="refresh_hz"):
        FramePacer(0.0)


def test_frame_layout():
    assert frame_layout("frame_sequential", 4, 3) == ((4, 3), [(None, (0, 0, 4, 3))])
    assert frame_layout("side_by_side", 4, 3) == ((8, 3), [(LEFT, (0, 0, 4, 3)), (RIGHT, (4, 0, 4, 3))])
    assert frame_layout("top_bottom", 4, 3) == ((4, 6), [(LEFT, (0, 3, 4, 3)), (RIGHT, (0, 0, 4, 3))])
    with pytest.raises(ValueError, match="stereo"):
        frame_layout("anaglyph", 4, 3)


# ---------------------------------------------------------------------------------------------- window
def _record_vsyncs(out) -> list[int]:
    """Record the vsync (timer-grid index, the window's own clock under Xvfb) at which each frame is shown."""
    ks, swap = [], out.window.swap

    def recording_swap():
        t, k = swap()
        ks.append(k)
        return t, k

    out.window.swap = recording_swap
    return ks


def test_frame_sequential_shows_left_then_right(display, offscreen, window):
    open_, call = window
    out = open_(stereo="frame_sequential", refresh_hz=2.0)    # 500 ms vsyncs: room for a screenshot each
    L, Rt = offscreen[0.064]
    assert diff(L, Rt) > 50  # the eyes differ: the test can tell them apart
    assert out.window.pacing == "timer" and not out.window.quad_buffered   # Xvfb: no vsync, no quad buffer
    assert out.window.counter == "grid"
    ks = _record_vsyncs(out)
    eyes = []
    for _ in range(4):
        eyes.append(call(out.show))
        assert diff(shot(display, out), L if eyes[-1] == LEFT else Rt) <= TOL   # X shows the eye drawn
    assert eyes[0] == LEFT and ks[0] == 0
    # a frame shown on the vsync after its predecessor's carries that vsync's eye: even = left, odd = right
    on_time = [i for i in range(1, 4) if ks[i] == ks[i - 1] + 1]
    assert on_time, f"no two frames on consecutive vsyncs: {ks}"
    assert all(eyes[i] == ks[i] % 2 and eyes[i] != eyes[i - 1] for i in on_time)
    assert (eyes[0], eyes[1]) == (LEFT, RIGHT) or ks[1] != 1


def test_frame_sequential_stays_in_phase_after_a_dropped_vsync(display, offscreen, window):
    open_, call = window
    out = open_(stereo="frame_sequential")
    L, Rt = offscreen[0.064]
    ks = _record_vsyncs(out)
    eyes = [call(out.show), call(out.show)]
    time.sleep(0.25)                                 # one whole refresh without a new frame
    eyes += [call(out.show), call(out.show)]
    gaps = np.diff(ks)
    assert gaps[1] >= 2                              # the display repeated the old frame at least once
    assert out.pacer.missed == int((gaps - 1).sum()) and out.pacer.resyncs == int(((gaps - 1) % 2 == 1).sum())
    # the late frame was drawn for the vsync it missed; the next one on time has its own vsync's eye again,
    # where a per-frame counter would have kept alternating (and swapped the eyes for good after an odd gap)
    for i in (1, 3):
        if ks[i] == ks[i - 1] + 1:
            assert eyes[i] == ks[i] % 2
    if gaps[1] % 2 == 0 and gaps[2] == 1:            # the usual case: one vsync dropped
        assert eyes[3] == eyes[2] and out.pacer.resyncs >= 1
    assert diff(shot(display, out), L if eyes[3] == LEFT else Rt) <= TOL


@pytest.mark.parametrize("stereo", ["side_by_side", "top_bottom", "mono"])
def test_window_equals_offscreen_render(display, offscreen, window, stereo):
    open_, call = window
    ipd = 0.0 if stereo == "mono" else 0.064
    out = open_(stereo=stereo, ipd=ipd)
    L, Rt = offscreen[ipd]
    call(out.show)
    img = shot(display, out)
    if stereo == "side_by_side":
        assert img.shape == (H, 2 * W, 3)
        assert diff(img[:, :W], L) <= TOL and diff(img[:, W:], Rt) <= TOL
    elif stereo == "top_bottom":
        assert img.shape == (2 * H, W, 3)
        assert diff(img[:H], L) <= TOL and diff(img[H:], Rt) <= TOL
    else:
        assert diff(img, L) <= TOL and diff(L, Rt) == 0            # mono: one image, from the cyclopean eye


def test_mirror_x_flips_each_eye(display, offscreen, window):
    open_, call = window
    out = open_(stereo="side_by_side", mirror_x=True)
    L, Rt = offscreen[0.064]
    call(out.show)
    img = shot(display, out)
    assert diff(img[:, :W], L[:, ::-1]) <= TOL and diff(img[:, W:], Rt[:, ::-1]) <= TOL
    assert diff(img[:, :W], L) > 50


def test_fullscreen_takes_the_monitor_mode(offscreen):
    """A second Xvfb whose screen is one eye image: fullscreen on it shows the image 1:1 over the whole
    screen."""
    from nodes.renderer.window import WindowError, WindowOutput

    with xvfb(W, H) as d:
        ex = ThreadPoolExecutor(1)
        saved = os.environ.get("DISPLAY")
        os.environ["DISPLAY"] = d
        try:
            with pytest.raises(WindowError, match="monitor='HDMI-9'.*screen"):
                ex.submit(WindowOutput, Projector.default(W, H), monitor="HDMI-9").result()
            out = ex.submit(WindowOutput, Projector.default(W, H, pixel=0.0028), stereo="mono", ipd=0.0,
                            fullscreen=True, monitor="screen", refresh_hz=4.0).result()
            try:
                assert out.window.framebuffer_size == (W, H) and out.window.monitor_name == "screen"
                ex.submit(_draw, out.renderer).result()
                ex.submit(out.show).result()
                assert diff(grab(d), offscreen[0.0][0]) <= TOL
            finally:
                ex.submit(out.close).result()
            # a frame of half the monitor's mode: the mode stays,
            # the frame is scaled up (bilinear), with a warning
            small = Projector.default(W // 2, H // 2, pixel=0.0056)
            out = ex.submit(WindowOutput, small, stereo="mono", ipd=0.0, fullscreen=True,
                            refresh_hz=4.0).result()
            try:
                assert out.window.framebuffer_size == (W, H)
                assert any("scaled" in w for w in out.window.warnings)
                ex.submit(_draw, out.renderer).result()
                ex.submit(out.show).result()
                img = grab(d).astype(float)
                want = offscreen[0.0][0].astype(float)            # the same view at twice the resolution
                assert want.mean() > 5.0                                # the cylinder covers part of it
                assert np.abs(img - want).mean() < 0.15 * want.mean()   # measured 0.07
                assert np.corrcoef(img.ravel(), want.ravel())[0, 1] > 0.97
            finally:
                ex.submit(out.close).result()
        finally:
            ex.shutdown()
            if saved is None:
                os.environ.pop("DISPLAY", None)
            else:
                os.environ["DISPLAY"] = saved


def test_window_refuses_a_thread_holding_an_egl_context(display, monkeypatch):
    from nodes.renderer.window import WindowError, WindowOutput

    monkeypatch.setenv("DISPLAY", display)
    import moderngl

    ctx = moderngl.create_standalone_context(backend="egl")    # current on this thread from here on
    try:
        with pytest.raises(WindowError, match="own thread"):
            WindowOutput(Projector.default(W, H))
    finally:
        ctx.release()


# ---------------------------------------------------------------------------------------------- node
def test_node_window_output_publishes_and_reports_pacing(display, monkeypatch):
    from nodes.renderer.node import RendererNode

    monkeypatch.setenv("DISPLAY", display)
    params = {"width": W, "height": H, "output": "window", "fullscreen": False, "stereo": "side_by_side",
              "refresh_hz": 30.0, "publish_rate": 5.0, "publish_scale": 1.0, "max_render_rate": 10.0,
              "correction": "none"}

    async def scenario():
        async with NodeHarness(RendererNode, params=params) as h:
            m = (await h.wait_for(topics.RENDERED, n=2, timeout=20.0))[-1]
            out = h.node.output
            await asyncio.sleep(0.2)
            img = shot(display, out)
            assert diff(img[:, :W], m.left) <= TOL and diff(img[:, W:], m.right) <= TOL
            assert m.left.max() > 100 and m.correction == "none"
            hb = (await h.wait_for(topics.DIAGNOSTICS, n=2, timeout=10.0))[-1]
            assert ("fps" in hb.message and "missed vsyncs" in hb.message
                    and "pacing timer, counter grid" in hb.message)
            fps = float(hb.message.split("window ")[1].split(" fps")[0])
            assert 10.0 < fps < 35.0                       # paced near 30 Hz even on a loaded 2-core machine
            assert h.node.pacing.frames > 10

    asyncio.run(scenario())


def test_node_window_unknown_monitor_is_a_configuration_error(display, monkeypatch):
    from nodes.renderer.node import RendererNode

    monkeypatch.setenv("DISPLAY", display)

    async def scenario():
        async with NodeHarness(RendererNode, params={"width": W, "height": H, "output": "window",
                                                     "monitor": 3}):
            pass

    with pytest.raises(ValueError, match="monitor=3: index out of range"):
        asyncio.run(scenario())
