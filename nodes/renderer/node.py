"""Renderer node: draws the (deformed) object for both eyes, corrected for the actual sheet (paper §III-C).

Subscribes ``/object/deformation`` (the rigid object until the FEM publishes), both arms' joint states (the
actual sheet), ``/fingertip``, ``/sheet/target`` (its stretch's table is prepared before the arms get there)
and ``/eye/pose`` (each pair is corrected for the tracked eyes: :mod:`flexsheet.rendering.viewpoint`).

The pushed sheet's shape is the FEM of the sheet gripped on its clamp edges
(:mod:`flexsheet.model.sheet_model`; never the twin's truth), one table per sheet-strain node
(:mod:`nodes.renderer.tables`). It redraws as soon as a new fingertip or deformation arrives (at most
``max_render_rate``; at least at ``publish_rate``) and publishes ``/render/stereo``
(:class:`messages.RenderedFrame`, downscaled by ``publish_scale``) at ``publish_rate``; ``source_stamp`` is
the newest exposure stamp of the fingertip / deformation it drew.

Geometry: the ``scene`` file's object (default the paper's cylinder); the projector and the eye from
``display_calib`` (without one the nominal geometry, said in the log). The state and the decisions are
:mod:`flexsheet.rendering.state`; the drawing :mod:`flexsheet.rendering.stereo_renderer`.
``output: offscreen`` (default) draws headless (EGL) in a GL thread of its own
(:class:`flexsheet.runtime.paced.PacedCall`; on a simulated clock on the loop's, charged the lab's render
time); ``output: window``: :mod:`nodes.renderer.window_thread`. Bad input is rejected and counted; the last
good state keeps being drawn.
"""

from __future__ import annotations

import asyncio
import time

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
from flexsheet.runtime.paced import PacedCall
from flexsheet.runtime.qos import QoS
from messages import EyePose, Fingertip, ObjectDeformation, RenderedFrame, SheetTarget, topics
from nodes.renderer.params import RendererParams
from nodes.renderer.show_image import ImageServices
from nodes.renderer.tables import SheetTables
from nodes.renderer.window_thread import WindowThread

__all__ = ["RendererNode"]


class RendererNode(SheetTables, WindowThread, ImageServices, Node):
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
        self.service("show_image", self.srv_show_image, "{path}: show an image file in both eyes "
                     "(registration patterns) instead of the scene, scaled to the projector", commanding=True)
        self.service("clear_image", self.srv_clear_image, "draw the scene again", commanding=True)
        check_screen(self.eye, self.projector.position, paper.SCREEN_POINT, paper.SCREEN_NORMAL)
        self.sheet_config = SheetConfig(half_width=p.sheet_half_width, push_threshold=p.push_threshold,
                                        grid_step=p.depth_table_step, strain_offset=geo.strain_offset,
                                        tension_ratio=p.tension_ratio, cache_dir=p.sheet_cache,
                                        mesh=dict(p.sheet_mesh))
        self.sheet_model = sheet_model_for(self.sheet_config)
        self.state = RendererState(self.eye, self.projector.position, self.sheet_config, mesh=geo.mesh,
                                   sheet_model=self.sheet_model, build=False, on_missing=self._want_table)
        self._init_tables()
        if p.output == "window":
            self.require_wall_clock("output: window (a projector window shows frames on real vsyncs)")
        # tables are built when a push or the planner's stretch needs them; the error table
        # comes from the first one there is (a cached one near the home stretch now, if any)
        near = self.sheet_model.nearest_on_disk(self.sheet_model.node_of_span(self.state.last_good.half_span))
        if near is not None:
            await self._prepare(near)
        self.model_used, self.frames, self.output, self.pacing = "none", 0, None, None
        self._last_render = self._last_publish = 0.0      # s, the node's monotonic time
        self.pub = self.publisher(topics.RENDERED)
        self.image_pub = self.publisher(topics.PROJECTOR_IMAGE)
        # the clamps' poses, read per frame, before any output draws
        # (sampled: the 140 Hz joint states are decoded per frame, not each)
        self._arm_states = {"left": self.sample(topics.ARM_LEFT_STATE),
                            "right": self.sample(topics.ARM_RIGHT_STATE)}
        self.viewpoint = Viewpoint(*eye_positions(self.eye, self.geometry.ipd))   # before the first frame
        self.paced = None
        if p.output == "window":
            await self._open_window()
        else:   # offscreen: a GL thread of its own (a simulated clock: the loop's, charged the lab's time)
            self.paced = PacedCall(self, p.max_render_rate, self._draw, self._drawn,
                                   lambda exc: self._reject(f"render: {exc}"), LAB.compute("renderer"),
                                   "renderer-gl", before=self._prepare_missing)
            await self.paced.start(self._gl_init)
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST)
        self.subscribe(topics.SHEET_TARGET, self.on_sheet_target, qos=QoS.LATEST)
        self.subscribe(topics.EYE_POSE, self.on_eye_pose, qos=QoS.LATEST)
        self.timer(1.0 / p.publish_rate, self.on_timer)
        self._request()

    def _renderer_kwargs(self) -> dict:
        p: RendererParams = self.params
        return {"eye": self.eye, "ipd": 0.0 if p.stereo == "mono" else self.geometry.ipd,
                "screen_point": paper.SCREEN_POINT, "screen_normal": paper.SCREEN_NORMAL,
                "samples": p.samples,
                "distortion": self.geometry.distortion}

    # ------------------------------------------------------------------ offscreen output (GL thread)
    def _gl_init(self) -> None:
        self.renderer = StereoRenderer(self.projector, **self._renderer_kwargs())

    def _draw(self) -> RenderedFrame | None:
        """(The GL thread.) The pair for the newest inputs, when ``publish_rate`` is due (an offscreen pair
        nobody sees is not drawn)."""
        if self.paced.last - self._last_publish < 1.0 / self.params.publish_rate - 1e-9:
            return None
        return self._frame(True)

    def _drawn(self, msg: RenderedFrame | None) -> None:
        if msg is not None:
            self._last_publish = self.paced.last
            self.pub.publish(msg)

    # ------------------------------------------------------------------ shared
    def _request(self) -> None:
        """Ask for a redraw (thread-safe: input handlers run in worker threads)."""
        if self.paced is not None:
            self.paced.request()
        else:
            self._redraw.set()

    async def teardown(self) -> None:
        loop = asyncio.get_running_loop()
        if hasattr(self, "_builds"):
            self._stop_builds()
        if getattr(self, "paced", None) is not None:
            await self.paced.close(self.renderer.release if hasattr(self, "renderer") else None)
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
        """The planner's stretch: prepare its pushed-sheet table before the arms reach it (on a simulated
        clock while simulated time waits)."""
        await self._prepare(float(self.sheet_model.node_of(msg.stretch)))

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
            return RenderedFrame(header=self.pub.header("projector"), left=left, right=right,
                                 scale=p.publish_scale,
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
        # the host's drawing time; on a simulated clock the lab's
        # declared one (the message must not depend on the host)
        render_time = self.paced.elapsed(t0) if self.paced is not None else time.perf_counter() - t0
        if not publish:
            return None
        left, right = self.renderer.read_pair(p.publish_scale)
        self.frames += 1
        return RenderedFrame(header=self.pub.header("projector"), left=left, right=right,
                             scale=p.publish_scale,
                             correction=self.model_used, render_time=render_time, source_stamp=stamp,
                             eyes=np.stack(eyes), eye_source=choice.source)

    async def on_timer(self) -> None:
        last = self.paced.last if self.paced is not None else self._last_render
        if self.monotonic() - last >= 1.0 / self.params.publish_rate:
            self._request()   # nothing new arrived: still redraw (and publish) at publish_rate
