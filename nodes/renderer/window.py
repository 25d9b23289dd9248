"""Projector output: a real window (glfw) showing the stereo pair that :class:`StereoRenderer` draws.

The drawing is the offscreen renderer's, unchanged: :class:`WindowOutput` creates the
:class:`~flexsheet.rendering.stereo_renderer.StereoRenderer` on the window's OpenGL context
(``moderngl.create_context()`` after ``glfw.make_context_current``), the renderer draws both eyes into its
framebuffer texture exactly as headless, and :class:`Presenter` copies the eye images into the window's back
buffer at 1:1 (texelFetch), in the chosen stereo format (:func:`flexsheet.rendering.pacing.frame_layout`),
optionally mirrored left-right.

* **Monitor, mode.** ``monitor`` is an index into ``glfw.get_monitors()`` (0 = primary) or a substring of a
  monitor's name (on X11 the RandR output, e.g. ``"DP-1"``). Fullscreen asks for a video mode of the frame's
  size at ``refresh_hz`` (default: the monitor's current rate), so a 1024×768 projector runs at its native
  mode; if the mode granted differs, the frame is scaled to it and a warning says so.
* **Vsync.** ``glfw.swap_interval(1)``; after each swap ``glFinish`` waits until the swap has happened, so the
  swap-return time is the vsync time. At open the window probes whether swaps really block; where they do not
  (Xvfb, some drivers) it paces itself on a virtual vsync grid at ``refresh_hz`` and says so (``pacing``);
  the grid index then counts the vsyncs.
* **Frame-sequential stereo.** With ``quad_buffer`` it asks for a quad-buffered (``glfw.STEREO``) context; if
  the driver grants one (Quadro-class GPUs with stereo enabled), both eyes go to ``GL_BACK_LEFT`` /
  ``GL_BACK_RIGHT`` every frame and the driver alternates them and drives the glasses' emitter. Otherwise the
  eyes alternate on successive vsyncs, the eye chosen from the vsync count (:class:`FramePacer`: from the
  ``GLX_OML_sync_control`` media stream counter where the driver offers it, else from swap times), so a
  dropped vsync does not leave the eyes swapped.

All calls must come from one thread (glfw's window-system calls and the GL context are bound to it), and that
thread must not hold a headless EGL context: with libglvnd a thread can have a current context of one API
only, and GLX answers the window's ``MakeCurrent`` with the fatal X error BadAccess. :class:`ProjectorWindow`
checks this and raises :class:`WindowError` instead; the renderer node opens the window on a thread of its
own.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import math
import time

import numpy as np

from flexsheet.model.projector import Projector
from flexsheet.rendering.pacing import LEFT, RIGHT, STEREO_MODES, FramePacer, frame_layout
from flexsheet.rendering.stereo_renderer import StereoRenderer

__all__ = ["ProjectorWindow", "Presenter", "WindowOutput", "find_monitor", "monitor_names", "WindowError"]

log = logging.getLogger(__name__)

from flexsheet.rendering.stereo_renderer import SHADER_DIR  # noqa: E402

GL_BACK = 0x0405
GL_BACK_LEFT = 0x0402
GL_BACK_RIGHT = 0x0403
GL_STEREO = 0x0C33
DEFAULT_REFRESH_HZ = 60.0
_PROBE_SWAPS = 12


class WindowError(ValueError):
    """The window cannot be opened as configured (no display, unknown monitor, no GL 3.3 context); the message
    names the parameter and value. A ``ValueError``, so a node's setup reports it as a configuration error."""


def _egl_current() -> bool:
    """True if this thread has a current EGL context (e.g. a headless moderngl context)."""
    name = ctypes.util.find_library("EGL")
    if name is None:
        return False
    fn = ctypes.CDLL(name).eglGetCurrentContext
    fn.restype = ctypes.c_void_p
    return bool(fn())


def _glfw():
    if _egl_current():
        raise WindowError("this thread has a current EGL (headless) OpenGL context; libglvnd then refuses "
                          "the window's GLX context (X error BadAccess, fatal): open the window on its own "
                          "thread")
    import glfw

    glfw.ERROR_REPORTING = "log"     # glfw errors are logged; every call's result is checked here
    if not glfw.init():
        raise WindowError("cannot initialise glfw: no display (is DISPLAY set and the X server running?)")
    return glfw


def monitor_names() -> list[str]:
    """Names of the connected monitors, in ``glfw.get_monitors()`` order (glfw must be initialised)."""
    import glfw

    return [glfw.get_monitor_name(m).decode(errors="replace") for m in glfw.get_monitors() or []]


def find_monitor(monitor: int | str):
    """The glfw monitor for ``monitor``: an index (int or digit string; 0 = primary) or a substring of its
    name. Raises :class:`WindowError` listing the monitors when there is no match."""
    import glfw

    mons = list(glfw.get_monitors() or [])
    names = monitor_names()
    if not mons:
        raise WindowError("no monitor is connected")
    key = monitor.strip() if isinstance(monitor, str) else monitor
    if isinstance(key, str) and key.isdigit():
        key = int(key)
    if isinstance(key, int):
        if 0 <= key < len(mons):
            return mons[key]
        raise WindowError(f"monitor={monitor!r}: index out of range; monitors: {list(enumerate(names))}")
    hits = [m for m, n in zip(mons, names, strict=True) if key.lower() in n.lower()]
    if len(hits) != 1:
        raise WindowError(f"monitor={monitor!r} matches {len(hits)} monitors; monitors: "
                          f"{list(enumerate(names))}")
    return hits[0]


class _OmlSync:
    """``glXGetSyncValuesOML`` (media stream counter) through ctypes, where the GLX extension is offered."""

    def __init__(self, glfw, window) -> None:
        self.fn = None
        if not glfw.extension_supported("GLX_OML_sync_control"):
            return
        name = ctypes.util.find_library("GL")
        if name is None:  # pragma: no cover - GLX without libGL cannot happen
            return
        lib = ctypes.CDLL(name)
        get = lib.glXGetProcAddressARB
        get.restype = ctypes.c_void_p
        get.argtypes = [ctypes.c_char_p]
        addr = get(b"glXGetSyncValuesOML")
        if not addr:  # pragma: no cover
            return
        proto = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_ulong,
                                 ctypes.POINTER(ctypes.c_int64),
                                 ctypes.POINTER(ctypes.c_int64), ctypes.POINTER(ctypes.c_int64))
        self.fn = proto(addr)
        self.display = glfw.get_x11_display()
        self.drawable = glfw.get_glx_window(window)

    def msc(self) -> int | None:
        """The current media stream counter (vsyncs since some origin), or None."""
        if self.fn is None:
            return None
        ust, msc, sbc = ctypes.c_int64(), ctypes.c_int64(), ctypes.c_int64()
        if not self.fn(self.display, self.drawable, ctypes.byref(ust), ctypes.byref(msc), ctypes.byref(sbc)):
            return None  # pragma: no cover
        return int(msc.value)


class ProjectorWindow:
    """A glfw window with an OpenGL 3.3 core context and a moderngl context on it (see the module docstring).

    ``frame_size`` (w, h) px: the output frame; ``monitor``: index or name (:func:`find_monitor`);
    ``fullscreen``: take the monitor (else a window of the frame's size at the monitor's top-left corner, for
    debugging); ``refresh_hz``: wanted refresh (None: the monitor's; 60 Hz if it reports none, as Xvfb);
    ``quad_buffer``: ask for a quad-buffered stereo context. Raises :class:`WindowError`.
    Attributes: ``ctx`` (moderngl), ``quad_buffered`` (bool), ``refresh_hz`` (float, in use), ``pacing``
    ("vsync": swaps block on the display; "timer": a virtual vsync grid), ``framebuffer_size``, ``warnings``.
    """

    def __init__(self, frame_size: tuple[int, int], *, monitor: int | str = 0, fullscreen: bool = False,
                 refresh_hz: float | None = None, quad_buffer: bool = False,
                 title: str = "flexsheet projector",
                 position: tuple[int, int] | None = None) -> None:
        if refresh_hz is not None and not (math.isfinite(refresh_hz) and refresh_hz > 0):
            raise WindowError(f"refresh_hz must be > 0, got {refresh_hz!r}")
        glfw = self.glfw = _glfw()
        self.warnings: list[str] = []
        self.window = None
        try:
            mon = find_monitor(monitor)
            mode = glfw.get_video_mode(mon)
            self.monitor_name = glfw.get_monitor_name(mon).decode(errors="replace")
            want_hz = refresh_hz or float(mode.refresh_rate) or None
            if want_hz is None:
                self.warnings.append(f"monitor {self.monitor_name!r} reports no refresh rate; assuming "
                                     f"{DEFAULT_REFRESH_HZ:.0f} Hz (set refresh_hz)")
                want_hz = DEFAULT_REFRESH_HZ
            W, H = int(frame_size[0]), int(frame_size[1])
            self.window, self.quad_buffered = self._create(W, H, title, mon if fullscreen else None, want_hz,
                                                           quad_buffer)
            if fullscreen:
                got = glfw.get_video_mode(mon)
                if got.refresh_rate and abs(got.refresh_rate - want_hz) > 0.5:
                    self.warnings.append(f"asked for {want_hz:g} Hz, monitor runs at {got.refresh_rate} Hz")
                    want_hz = float(got.refresh_rate)
            else:
                x, y = position if position is not None else glfw.get_monitor_pos(mon)
                glfw.set_window_pos(self.window, int(x), int(y))
            self.refresh_hz = float(want_hz)
            glfw.make_context_current(self.window)
            glfw.swap_interval(1)
            import moderngl

            self.ctx = moderngl.create_context(require=330)
            self.framebuffer_size = tuple(glfw.get_framebuffer_size(self.window))
            if self.framebuffer_size != (W, H):
                self.warnings.append(f"frame {W}x{H} shown in a {self.framebuffer_size[0]}x"
                                     f"{self.framebuffer_size[1]} framebuffer: scaled (set width/height to "
                                     "the projector's native mode)")
            self._gl = self._gl_functions()
            if self.quad_buffered:
                self.quad_buffered = self._gl_stereo()
            self._oml = _OmlSync(glfw, self.window)
            glfw.show_window(self.window)
            glfw.poll_events()
            self.pacing = self._probe_vsync()
        except BaseException:
            self.close()
            raise
        self._grid0: float | None = None
        self._k = -1
        for w in self.warnings:
            log.warning("projector window: %s", w)

    def _create(self, W, H, title, mon, hz, quad):
        glfw = self.glfw
        for stereo in ((True, False) if quad else (False,)):
            glfw.default_window_hints()
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.DOUBLEBUFFER, True)
            glfw.window_hint(glfw.STEREO, stereo)
            glfw.window_hint(glfw.RESIZABLE, False)
            glfw.window_hint(glfw.VISIBLE, False)
            glfw.window_hint(glfw.AUTO_ICONIFY, False)     # keep the projector image when focus moves away
            glfw.window_hint(glfw.DECORATED, mon is None)
            glfw.window_hint(glfw.REFRESH_RATE, int(round(hz)))
            win = glfw.create_window(W, H, title, mon, None)
            if win:
                return win, stereo
            if stereo:
                log.info("no quad-buffered stereo context offered; alternating eyes on successive vsyncs")
        raise WindowError(f"cannot open a {W}x{H} OpenGL 3.3 window on {self.monitor_name!r}")

    def _gl_functions(self):
        glfw = self.glfw
        fns = {}
        for name, proto in (("glDrawBuffer", ctypes.CFUNCTYPE(None, ctypes.c_uint)),
                            ("glGetBooleanv",
                             ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.POINTER(ctypes.c_ubyte)))):
            addr = glfw.get_proc_address(name)
            if not addr:  # pragma: no cover - core GL 1.0 entry points
                raise WindowError(f"OpenGL entry point {name} not found")
            fns[name] = proto(addr)
        return fns

    def _gl_stereo(self) -> bool:
        v = ctypes.c_ubyte(0)
        self._gl["glGetBooleanv"](GL_STEREO, ctypes.byref(v))
        return bool(v.value)

    def draw_buffer(self, which: int) -> None:
        """Select the default framebuffer's draw buffer (``GL_BACK``, ``GL_BACK_LEFT``, ``GL_BACK_RIGHT``).
        moderngl leaves the default framebuffer's draw buffer alone, so this holds until changed."""
        self._gl["glDrawBuffer"](which)

    def _probe_vsync(self) -> str:
        """Swap a few black frames and see whether swaps wait for the display."""
        ts = []
        for _ in range(_PROBE_SWAPS):
            self.ctx.screen.use()
            self.ctx.screen.clear(0.0, 0.0, 0.0, 1.0)
            self.glfw.swap_buffers(self.window)
            self.ctx.finish()
            ts.append(time.perf_counter())
        dt = float(np.median(np.diff(ts)))
        if dt >= 0.5 / self.refresh_hz:
            return "vsync"
        self.warnings.append(f"swaps do not wait for vsync (median {dt * 1e3:.2f} ms): paced by a timer at "
                             f"{self.refresh_hz:g} Hz")
        return "timer"

    @property
    def counter(self) -> str:
        """What counts vsyncs: "oml" (the driver's media stream counter), "grid" (timer pacing: the index of
        the virtual vsync the frame was shown at) or "time" (none: :class:`FramePacer` infers it from
        times)."""
        if self.pacing == "timer":
            return "grid"
        return "oml" if self._oml.fn is not None else "time"

    def swap(self) -> tuple[float, int | None]:
        """Show the back buffer at the next vsync; returns (time the swap completed, s on
        ``time.perf_counter``; vsync counter or None, see :attr:`counter`). With ``pacing == "timer"`` it
        first sleeps to the next point of a virtual vsync grid (at most one frame per grid point, like a
        display), and the counter is that point's index: the timer is the display's clock there, so no
        inference from times is needed."""
        if self.pacing == "timer":
            now = time.perf_counter()
            period = 1.0 / self.refresh_hz
            if self._grid0 is None:
                self._grid0 = now
            k = max(self._k + 1, math.ceil((now - self._grid0) / period - 1e-9))
            self._k = k
            wait = self._grid0 + k * period - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            self.glfw.swap_buffers(self.window)
            self.ctx.finish()
            return time.perf_counter(), k
        self.glfw.swap_buffers(self.window)
        self.ctx.finish()
        return time.perf_counter(), self._oml.msc()

    def poll(self, keep_open: bool = False) -> bool:
        """Process window events; True while the window should stay open, False once the user asked to close
        it. With ``keep_open`` a close request is cancelled (a projector image must not vanish on a stray
        click or key); the return value still reports it."""
        self.glfw.poll_events()
        closing = bool(self.glfw.window_should_close(self.window))
        if closing and keep_open:
            self.glfw.set_window_should_close(self.window, False)
        return not closing

    @property
    def position(self) -> tuple[int, int]:
        """The window's top-left corner on the X screen, px."""
        return tuple(self.glfw.get_window_pos(self.window))

    def close(self) -> None:
        """Destroy the window and terminate glfw (idempotent)."""
        if self.window is not None:
            if getattr(self, "ctx", None) is not None:
                self.ctx.release()
            self.glfw.destroy_window(self.window)
            self.window = None
        self.glfw.terminate()


class Presenter:
    """Copies the eye images from the renderer's texture to the window's back buffer.

    ``window``: :class:`ProjectorWindow`; ``texture``: the renderer's colour texture (2W × H, left | right);
    ``eye_size`` (W, H) px; ``stereo``: a :data:`STEREO_MODES` format; ``mirror_x``: flip each eye's image
    left-right (a projector set to rear projection, or a fold mirror in the light path). Raises
    ``ValueError``.
    """

    def __init__(self, window: ProjectorWindow, texture, eye_size: tuple[int, int], stereo: str,
                 mirror_x: bool = False) -> None:
        if stereo not in STEREO_MODES:
            raise ValueError(f"stereo must be one of {STEREO_MODES}, got {stereo!r}")
        self.window = window
        self.ctx = window.ctx
        self.stereo = stereo
        self.mirror_x = bool(mirror_x)
        self.texture = texture
        self.frame_size, self.passes = frame_layout(stereo, *eye_size)
        fbw, fbh = window.framebuffer_size
        sx, sy = fbw / self.frame_size[0], fbh / self.frame_size[1]
        self.passes = [(eye, (round(x * sx), round(y * sy), round(w * sx), round(h * sy)))
                       for eye, (x, y, w, h) in self.passes]
        self.eye_size = (int(eye_size[0]), int(eye_size[1]))
        import moderngl

        self.moderngl = moderngl
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR)      # used only when the frame is scaled
        texture.repeat_x = texture.repeat_y = False
        self.prog = self.ctx.program(vertex_shader=(SHADER_DIR / "present.vert").read_text(),
                                     fragment_shader=(SHADER_DIR / "present.frag").read_text())
        self.prog["u_tex"].value = 0
        self.prog["u_mirror"].value = int(self.mirror_x)
        self.scaled = (sx, sy) != (1.0, 1.0)
        self.prog["u_scaled"].value = int(self.scaled)
        self.vao = self.ctx.vertex_array(self.prog, [])

    def _pass(self, eye: int, vp) -> None:
        W, H = self.eye_size
        self.ctx.screen.viewport = vp
        self.prog["u_vp"].value = tuple(float(c) for c in vp)
        self.prog["u_src"].value = (eye * W, 0, W, H)
        self.vao.render(self.moderngl.TRIANGLES, vertices=3)

    def draw(self, eye: int = LEFT) -> None:
        """Draw the frame into the back buffer(s): every pass of the format; for frame-sequential the given
        ``eye`` (or, on a quad-buffered window, left to ``GL_BACK_LEFT`` and right to ``GL_BACK_RIGHT``)."""
        if eye not in (LEFT, RIGHT):
            raise ValueError(f"eye must be {LEFT} (left) or {RIGHT} (right), got {eye!r}")
        ctx, win = self.ctx, self.window
        ctx.screen.use()
        ctx.disable(self.moderngl.DEPTH_TEST)
        self.texture.use(0)
        quad = self.stereo == "frame_sequential" and win.quad_buffered
        if quad:
            win.draw_buffer(GL_BACK)
        if self.scaled:                   # at 1:1 the passes tile the frame exactly: no clear needed
            ctx.screen.viewport = (0, 0, *win.framebuffer_size)
            ctx.screen.clear(0.0, 0.0, 0.0, 1.0)
        for p_eye, vp in self.passes:
            if p_eye is not None:
                self._pass(p_eye, vp)
            elif quad:
                for e, buf in ((LEFT, GL_BACK_LEFT), (RIGHT, GL_BACK_RIGHT)):
                    win.draw_buffer(buf)
                    self._pass(e, vp)
                win.draw_buffer(GL_BACK)
            else:
                self._pass(eye, vp)


class WindowOutput:
    """The projector window with a stereo renderer on its context: :meth:`show` presents one frame per vsync.

    ``projector``: :class:`Projector` (its width × height is each eye's image); ``stereo``, ``mirror_x``: see
    :class:`Presenter`; ``monitor``, ``fullscreen``, ``refresh_hz``, ``quad_buffer``: see
    :class:`ProjectorWindow`; ``swap_eyes``: start frame-sequential stereo with the right eye (glasses in the
    other phase); ``renderer_kwargs``: :class:`StereoRenderer` arguments (eye, ipd, screen, samples...).
    Attributes: ``window``, ``renderer``, ``presenter``, ``pacer``. Raises
    :class:`WindowError`/``ValueError``.
    """

    def __init__(self, projector: Projector, *, stereo: str = "frame_sequential", monitor: int | str = 0,
                 fullscreen: bool = False, mirror_x: bool = False, refresh_hz: float | None = None,
                 quad_buffer: bool = True, swap_eyes: bool = False, title: str = "flexsheet projector",
                 position: tuple[int, int] | None = None, **renderer_kwargs) -> None:
        if stereo not in STEREO_MODES:
            raise ValueError(f"stereo must be one of {STEREO_MODES}, got {stereo!r}")
        size, _ = frame_layout(stereo, projector.width, projector.height)
        self.window = ProjectorWindow(size, monitor=monitor, fullscreen=fullscreen, refresh_hz=refresh_hz,
                                      quad_buffer=quad_buffer and stereo == "frame_sequential", title=title,
                                      position=position)
        try:
            self.renderer = StereoRenderer(projector, ctx=self.window.ctx, **renderer_kwargs)
            self.presenter = Presenter(self.window, self.renderer.texture,
                                       (projector.width, projector.height),
                                       stereo, mirror_x)
        except BaseException:
            self.window.close()
            raise
        self.pacer = FramePacer(self.window.refresh_hz, swap_eyes=swap_eyes)
        self.stereo = stereo

    def show(self) -> int:
        """Present the renderer's current pair for the next vsync and swap. Returns the eye shown
        (frame-sequential: chosen by the vsync count; other formats: :data:`LEFT`)."""
        eye = self.pacer.next_eye() if self.stereo == "frame_sequential" else LEFT
        self.presenter.draw(eye)
        t, msc = self.window.swap()
        self.pacer.on_swap(t, msc)
        return eye

    def close(self) -> None:
        """Release the renderer's GL objects and close the window."""
        try:
            self.renderer.release()
        finally:
            self.window.close()
