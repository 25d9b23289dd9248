"""Renderer node: draws the (deformed) object for both eyes, corrected for the actual sheet (paper §III-C).

Subscribes ``/object/deformation`` (the scene's rigid object until the FEM publishes), both arms' joint states (the
measured clamp poses give the actual sheet pose and its stretch), ``/fingertip`` (the pushed point and depth) and
``/sheet/target`` (the stretch the planner sets: its pushed-sheet table is prepared before the arms get there) and
``/eye/pose`` (the viewer's tracked eyes: each pair is corrected for them, predicted to the moment it is on the
sheet; the last good pose while the glasses are lost, then the registered V: :mod:`flexsheet.rendering.viewpoint`).

The pushed sheet's shape is the FEM of the sheet gripped on its clamp edges (:mod:`flexsheet.model.sheet_model`:
nominal material, the strain offset identified in ``display_calib``'s ``sheet`` entry, the planner's; never the
twin's truth), one table per sheet-strain node (shipped, or cached on disk), sampled per push into a depth table
that the fine shader reads from a texture.
A table that is not on disk is built in a worker process at lower priority (~2 min per node on one core);
meanwhile a push at that stretch is drawn with the 4-triangle model and ``/diagnostics`` says so. It redraws as soon as a
new fingertip or deformation arrives (at most ``max_render_rate``; at least at ``publish_rate`` when nothing
arrives) and publishes ``/render/stereo`` (:class:`messages.RenderedFrame`, downscaled by ``publish_scale``) at
``publish_rate``; ``source_stamp`` is the newest exposure stamp of the fingertip / deformation it drew.

Geometry: the object is the ``scene`` file's (:mod:`flexsheet.model.scenes`; default the
paper's cylinder), and the projector (K_p, distortion, pose) and the eye (V, ipd) come from ``display_calib``
(``display.yaml``, filled in by the launcher from the launch file's top-level ``display_calib:``); without
one the node draws through the nominal geometry and says so in its log. ``width``/``height`` only choose the
drawing resolution of that projector.

This file only wires topics and params. The state and the decisions (inputs → sheet, model choice, error
table) are :mod:`flexsheet.rendering.state`; the drawing :mod:`flexsheet.rendering.stereo_renderer`; the projector window
:mod:`nodes.renderer.window`.

``output: offscreen`` (default) draws with a headless EGL context in one GL thread. ``output: window`` opens
the projector window (glfw) on a thread of its own, which presents a frame on every vsync in the ``stereo``
format and redraws the pair there when inputs arrive; ``/diagnostics`` then reports the window's frame rate,
frame intervals and missed vsyncs. Bad input is rejected and counted; the last good state keeps being drawn.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from flexsheet.model import geometry as paper
from flexsheet.model.projector import eye_positions
from flexsheet.model.sheet_model import SheetConfig, sheet_model_for
from flexsheet.model.timing import LAB
from flexsheet.rendering.correction import check_screen
from flexsheet.rendering.state import PendingPush, RendererState, load_geometry, pick_model
from flexsheet.rendering.stereo_renderer import StereoRenderer
from flexsheet.rendering.viewpoint import Viewpoint
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.qos import QoS
from messages import (
    EyePose,
    Fingertip,
    Heartbeat,
    ObjectDeformation,
    ProjectorImage,
    RenderedFrame,
    SheetTarget,
    topics,
)
from nodes.renderer.params import RendererParams
from nodes.renderer.tables import SheetTables
from nodes.renderer.window import WindowOutput

__all__ = ["RendererNode"]


class RendererNode(SheetTables, Node):
    """Projector renderer (see module docstring). Params: :class:`RendererParams`."""

    Params = RendererParams
    node_type = "renderer"
    #: a rendered stereo pair of two 1024 x 768 RGB images, with room for its header (sizes the send queue)
    LARGEST_MESSAGE_BYTES = 2 * 1024 * 768 * 3 + (16 << 10)

    async def setup(self) -> None:
        p: RendererParams = self.params
        loop = asyncio.get_running_loop()
        geo = await loop.run_in_executor(None, load_geometry, p.scene, p.display_calib, p.width, p.height)
        self.geometry = geo
        for line in geo.log:
            loud = geo.nominal and "NOMINAL" in line
            (self.log.warning if loud else self.log.info)("%s", line)
        self.eye = geo.eye
        self.projector = geo.projector
        self._image = None          # an image show_image set, drawn instead of the scene
        self.service("show_image", self.srv_show_image, "{path}: show an image file in both eyes (registration "
                     "patterns) instead of the scene, scaled to the projector", commanding=True)
        self.service("clear_image", self.srv_clear_image, "draw the scene again", commanding=True)
        check_screen(self.eye, self.projector.position, paper.SCREEN_POINT, paper.SCREEN_NORMAL)
        self.sheet_config = SheetConfig(half_width=p.sheet_half_width, push_threshold=p.push_threshold,
                                        grid_step=p.depth_table_step, strain_offset=geo.strain_offset,
                                        tension_ratio=p.tension_ratio, cache_dir=p.sheet_cache,
                                        mesh=dict(p.sheet_mesh))
        self.sheet_model = sheet_model_for(self.sheet_config)
        self.state = RendererState(self.eye, self.projector.position, self.sheet_config, mesh=geo.mesh,
                                   sheet_model=self.sheet_model, build=False, on_missing=self._want_table)
        self.table = None                     # the models' error table, once the first FEM table is there
        self._tables_wanted: list[float] = []
        self._tables_asked: set[float] = set()
        self._sim_missing: list[float] = []
        self._tables_event = asyncio.Event()
        self._builds: set = set()
        self._failed: set[float] = set()
        self.sim = self.clock.simulated
        if self.sim and p.output == "window":
            raise ValueError("output: window needs the wall clock (launch file clock: wall): a projector window "
                             "shows frames on real vsyncs")
        if not self.sim:   # on a simulated clock tables are made when wanted, while simulated time waits
            self._builder_task = loop.create_task(self._build_tables())
        # tables are built when a push or the planner's stretch needs them; the error table comes from the first
        # one there is (a cached one near the home stretch now, if any)
        near = self.sheet_model.nearest_on_disk(self.sheet_model.node_of_span(self.state.last_good.half_span))
        if near is not None:
            if self.sim:
                await self._sim_table(near)
            else:
                self._want_table(near)
        self.model_used = "none"
        self.frames = 0
        self.output = None
        self.pacing = None
        self._last_render = 0.0
        self._last_publish = 0.0
        self.pub = self.publisher(topics.RENDERED)
        self.image_pub = self.publisher(topics.PROJECTOR_IMAGE)
        # the clamps' poses, read per frame, before any output draws (sampled: the 140 Hz joint states are decoded per frame, not each)
        self._arm_states = {"left": self.sample(topics.ARM_LEFT_STATE), "right": self.sample(topics.ARM_RIGHT_STATE)}
        self._dirty = False
        self.viewpoint = Viewpoint(*eye_positions(self.eye, self.geometry.ipd))   # before the first frame
        if p.output == "window":
            await self._open_window()
        elif self.sim:     # one thread: the loop's; each redraw is charged the lab's render time
            self._gl_init()
            self.timer(1.0 / p.max_render_rate, self._sim_tick)
        else:
            self._gl = ThreadPoolExecutor(1, thread_name_prefix="renderer-gl")
            await loop.run_in_executor(self._gl, self._gl_init)
            self._want = asyncio.Event()
            self._render_task = loop.create_task(self._render_loop())
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST)
        self.subscribe(topics.SHEET_TARGET, self.on_sheet_target, qos=QoS.LATEST)
        self.subscribe(topics.EYE_POSE, self.on_eye_pose, qos=QoS.LATEST)
        self.timer(1.0 / p.publish_rate, self.on_timer)
        self._request()

    def _renderer_kwargs(self) -> dict:
        p: RendererParams = self.params
        return {"eye": self.eye, "ipd": 0.0 if p.stereo == "mono" else self.geometry.ipd,
                "screen_point": paper.SCREEN_POINT, "screen_normal": paper.SCREEN_NORMAL, "samples": p.samples,
                "distortion": self.geometry.distortion}

    # ------------------------------------------------------------------ offscreen output (GL thread)
    def _gl_init(self) -> None:
        self.renderer = StereoRenderer(self.projector, **self._renderer_kwargs())

    async def _render_loop(self) -> None:
        p: RendererParams = self.params
        loop = asyncio.get_running_loop()
        while True:
            await self._want.wait()
            self._want.clear()
            wait = self._last_render + 1.0 / p.max_render_rate - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
            self._last_render = time.monotonic()
            publish = self._last_render - self._last_publish >= 1.0 / p.publish_rate
            try:
                msg = await loop.run_in_executor(self._gl, self._frame, publish)
            except ValueError as exc:
                self._reject(f"render: {exc}")
                continue
            if msg is not None:
                self._last_publish = self._last_render
                self.pub.publish(msg)

    # ------------------------------------------------------------------ window output (window thread)
    async def _open_window(self) -> None:
        self._stop_window = threading.Event()
        self._redraw = threading.Event()
        ready: concurrent.futures.Future = concurrent.futures.Future()
        self._window_thread = threading.Thread(target=self._window_main, args=(ready,), name="renderer-window",
                                               daemon=True)
        self._window_thread.start()
        await asyncio.wrap_future(ready)      # a WindowError (ValueError) is a configuration error

    def _window_main(self, ready: concurrent.futures.Future) -> None:
        p: RendererParams = self.params
        try:
            out = WindowOutput(self.projector, stereo=p.stereo, monitor=p.monitor, fullscreen=p.fullscreen,
                               mirror_x=p.mirror_x, refresh_hz=p.refresh_hz, quad_buffer=p.quad_buffer,
                               swap_eyes=p.swap_eyes, title=f"flexsheet {self.name}", **self._renderer_kwargs())
        except BaseException as exc:  # noqa: BLE001 - handed to setup, which reports it
            ready.set_exception(exc)
            return
        self.output, self.renderer = out, out.renderer
        if out.window.warnings:
            self.state_message = "; ".join(out.window.warnings)
        ready.set_result(None)
        try:
            self._window_loop(out)
        except Exception:  # noqa: BLE001 - the projector image is gone: say so and stop the node (respawn)
            self.errors_total += 1
            self.state_message = "projector window failed"
            self.log.exception("projector window failed; stopping the node")
            self.shutdown()
        finally:
            out.close()

    def _window_loop(self, out) -> None:
        p: RendererParams = self.params
        last_stats = 0.0
        while not self._stop_window.is_set():
            if not out.window.poll(keep_open=True):
                self.log.warning("projector window close request ignored (stop the node instead)")
            now = time.monotonic()
            if self._redraw.is_set() and now - self._last_render >= 1.0 / p.max_render_rate:
                self._redraw.clear()
                self._last_render = now
                publish = now - self._last_publish >= 1.0 / p.publish_rate
                try:
                    msg = self._frame(publish)
                except ValueError as exc:
                    self._loop.call_soon_threadsafe(self._reject, f"render: {exc}")
                    msg = None
                if msg is not None:
                    self._last_publish = now
                    self._loop.call_soon_threadsafe(self.pub.publish, msg)
            out.show()
            if now - last_stats >= 0.25:
                self.pacing = out.pacer.stats()          # read by heartbeat() in the loop thread
                last_stats = now

    def heartbeat(self) -> Heartbeat:
        """Diagnostics; with the window output the message leads with its frame rate and missed vsyncs."""
        hb = super().heartbeat()
        pacing = getattr(self, "pacing", None)
        if pacing is None:
            return hb
        w = self.output.window
        line = f"{pacing.line()} [pacing {w.pacing}, counter {w.counter}, quad buffer {w.quad_buffered}]"
        return hb.model_copy(update={"message": f"{line}; {hb.message}" if hb.message else line})

    # ------------------------------------------------------------------ shared
    def _request(self) -> None:
        """Ask for a redraw (thread-safe: input handlers run in worker threads)."""
        if self.sim:
            self._dirty = True
            self._sim_render()
            return
        if self.params.output == "window":
            self._redraw.set()
        else:
            self._loop.call_soon_threadsafe(self._want.set)

    # ------------------------------------------------------------------ simulated clock (one thread)
    def _sim_render(self) -> None:
        """Redraw now if one is wanted and ``max_render_rate`` allows (else the next tick does), charging the
        lab's render time; publish at ``publish_rate``. Only the published pairs are drawn on the host: nobody
        sees the others in a simulation, and a pair is drawn from the newest inputs whatever came before."""
        p: RendererParams = self.params
        now = self.now()
        if not self._dirty or now - self._last_render < 1.0 / p.max_render_rate - 1e-9:
            return
        self._dirty = False
        self._last_render = now
        publish = now - self._last_publish >= 1.0 / p.publish_rate - 1e-9
        self.charge(LAB.compute("renderer"))
        if not publish:
            return
        try:
            msg = self._frame(publish)
        except ValueError as exc:
            self._reject(f"render: {exc}")
            return
        if msg is not None:
            self._last_publish = now
            self.pub.publish(msg)

    async def teardown(self) -> None:
        loop = asyncio.get_running_loop()
        if hasattr(self, "_render_task"):
            self._render_task.cancel()
        if hasattr(self, "_builder_task"):
            builds = list(self._builds)          # our own table builders (a partial table is never cached)
            self._builder_task.cancel()
            for proc in builds:
                proc.terminate()
                await loop.run_in_executor(None, proc.join, 5.0)
        if getattr(self, "sim", False) and hasattr(self, "renderer"):
            self.renderer.release()
        if hasattr(self, "_gl"):
            if hasattr(self, "renderer"):
                await loop.run_in_executor(self._gl, self.renderer.release)
            self._gl.shutdown(wait=True)
        if hasattr(self, "_window_thread"):
            self._stop_window.set()
            await loop.run_in_executor(None, self._window_thread.join, 5.0)

    # ------------------------------------------------------------------ inputs (worker threads)
    def on_deformation(self, msg: ObjectDeformation) -> None:
        try:
            self.state.set_mesh(msg.vertices, msg.faces, msg.source_stamp)
        except ValueError as exc:
            raise InputRejected(str(exc)) from exc
        self._request()

    def _read_arms(self) -> None:
        """Take each arm's newest clamp pose (a pose that gives an unusable sheet is rejected, counted)."""
        for side, sub in self._arm_states.items():
            sub.take(lambda msg, side=side: self.state.set_arm_pose(side, msg.pose))

    async def on_sheet_target(self, msg: SheetTarget) -> None:
        """The planner's stretch: prepare its pushed-sheet table before the arms reach it (on a simulated clock
        while simulated time waits)."""
        node = self.sheet_model.node_of(msg.stretch)
        if self.sim:
            if self._in_range(node):
                await self._sim_table(float(node))
        else:
            self._want_table(node)

    def on_fingertip(self, msg: Fingertip) -> None:
        self.state.set_fingertip(msg.position if msg.valid else None, msg.exposure_stamp)
        self._request()

    # ------------------------------------------------------------------ drawing (GL / window thread)
    def on_eye_pose(self, msg: EyePose) -> None:
        """The tracked eyes: the pairs are corrected for them from now on (:class:`Viewpoint`)."""
        try:
            self.viewpoint.update(float(msg.header.stamp), msg.left, msg.right, msg.velocity, msg.valid)
        except ValueError as exc:
            raise InputRejected(f"/eye/pose: {exc}") from None
        # no redraw of its own: the next pair (each fingertip, at least publish_rate) takes the newest eyes; a
        # redraw per pose kept the renderer busy enough to delay the fingertip's pairs by 4-12 ms

    def _eyes(self):
        """The eyes of the pair drawn now, predicted to the moment it is on the sheet (logged on a change)."""
        photon = LAB.projected_at(self.now() + LAB.compute("renderer"))
        choice = self.viewpoint.eyes(photon)
        if choice.say:
            (self.log.warning if choice.source != "tracked" else self.log.info)("%s", choice.say)
        if self.params.stereo == "mono":
            mid = 0.5 * (choice.left + choice.right)
            return choice, [mid, mid]
        return choice, [choice.left, choice.right]

    def srv_show_image(self, args: dict) -> dict:
        """``{path}``: show an image file (any size: scaled to the projector's, nearest neighbour for patterns)
        in both eyes instead of the scene, until ``clear_image``; latched on ``/projector/image``. Returns the
        path, the projector's size and the stamp it was shown at (s, the graph's clock)."""
        import cv2

        path = args.get("path")
        if not isinstance(path, str) or not path:
            raise ValueError(f"show_image needs 'path' (an image file), got {path!r}")
        img = cv2.imread(path, cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"cannot read an image from {path!r}")
        W, H = self.projector.width, self.projector.height
        if img.shape[:2] != (H, W):
            img = cv2.resize(img, (W, H), interpolation=cv2.INTER_NEAREST)
        self._image = img[:, :, ::-1].copy()        # BGR → RGB
        self._request()
        header = self.image_pub.header("projector")
        self.image_pub.publish(ProjectorImage(header=header, image=cv2.cvtColor(img, cv2.COLOR_BGR2GRAY),
                                              showing=True, name=path))
        return {"path": path, "size": [W, H], "stamp": header.stamp}

    def srv_clear_image(self, args: dict) -> str:
        self._image = None
        self._request()
        self.image_pub.publish(ProjectorImage(header=self.image_pub.header("projector"),
                                              image=np.zeros((0, 0), np.uint8), showing=False))
        return "drawing the scene"

    def _frame(self, publish: bool = True) -> RenderedFrame | None:
        """Correct and draw the pair for the newest inputs (or the image ``show_image`` set); read it back if
        ``publish``."""
        p: RendererParams = self.params
        t0 = time.perf_counter()
        self._read_arms()
        image = self._image
        if image is not None:
            self.renderer.show_image(image)
            if not publish:
                return None
            left, right = self.renderer.read_pair(p.publish_scale)
            self.frames += 1
            return RenderedFrame(header=self.pub.header("projector"), left=left, right=right, scale=p.publish_scale,
                                 correction="image", render_time=time.perf_counter() - t0,
                                 source_stamp=self.state.source_stamp, eyes=np.stack(self.viewpoint.fixed))
        mesh = self.state.take_mesh()
        stamp = self.state.source_stamp
        if mesh is not None:
            self.renderer.set_mesh(*mesh)
        sheet, warning = self.state.sheet_for_frame()
        if warning:
            self.state_message = warning
        if isinstance(sheet.membrane, PendingPush):
            self.state_message = (f"pushed-sheet table for stretch {sheet.membrane.node:g} not built yet: "
                                  "drawing the push with the 4-triangle model")
        elif self.state_message.startswith("pushed-sheet table"):
            self.state_message = ""
        model = pick_model(p.correction, sheet, self.table, p.accuracy_target)
        try:
            self.renderer.set_model(model, sheet)
        except ValueError as exc:
            self.state_message = f"model {model} failed ({exc}); drawing uncorrected"
            self.renderer.set_model("none")
        self.model_used = self.renderer.model
        choice, eyes = self._eyes()
        self.renderer.render_pair(eyes=eyes)
        # the host's drawing time; on a simulated clock the lab's declared one (the message must not depend on the host)
        render_time = LAB.compute("renderer") if self.sim else time.perf_counter() - t0
        if not publish:
            return None
        left, right = self.renderer.read_pair(p.publish_scale)
        self.frames += 1
        return RenderedFrame(header=self.pub.header("projector"), left=left, right=right, scale=p.publish_scale,
                             correction=self.model_used, render_time=render_time, source_stamp=stamp,
                             eyes=np.stack(eyes), eye_source=choice.source)

    async def on_timer(self) -> None:
        if self.monotonic() - self._last_render >= 1.0 / self.params.publish_rate:
            self._request()   # nothing new arrived: still redraw (and publish) at publish_rate
