"""Renderer node: draws the (deformed) object for both eyes, corrected for the actual sheet (paper §III-C).

Subscribes ``/object/deformation`` (rigid cylinder until the FEM publishes), both arms' joint states (the
measured clamp poses give the actual sheet pose, :meth:`SheetSurface.from_clamps`) and ``/fingertip`` (the
pushed point: a valid fingertip more than ``push_threshold`` behind the sheet plane and inside the sheet).
It redraws as soon as a new fingertip or deformation arrives (at most ``max_render_rate``; at least at
``publish_rate`` when nothing arrives) and publishes ``/render/stereo`` (:class:`messages.RenderedFrame`,
downscaled by ``publish_scale``) at ``publish_rate``, each published frame being the redraw for the newest
input; ``source_stamp`` is the newest exposure stamp of the fingertip / deformation it drew.

All GL work runs in one dedicated thread (the EGL context is bound to it). Bad input (unknown faces, a
clamp pose that is not a rotation, a sheet pose with the eye behind it) is rejected and counted; the last good
state keeps being drawn. ``correction="auto"`` picks the cheapest model meeting ``accuracy_target`` from a
table of predicted errors computed at setup (:func:`correction.choose_model`).
"""

from __future__ import annotations

import asyncio
import importlib.util
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from flexsheet.model import scene
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface
from flexsheet.runtime.node import InputRejected, Node, QoS
from messages import ArmJointState, Fingertip, ObjectDeformation, RenderedFrame, topics
from nodes.renderer.correction import MODELS, _check_screen, choose_model, predict_model_errors
from nodes.renderer.scene import StereoRenderer, cylinder_mesh, vertex_normals

__all__ = ["RendererNode", "RendererParams", "check_sheet"]


class RendererParams(BaseModel):
    """Renderer parameters (SI units, display frame)."""

    model_config = ConfigDict(extra="forbid")

    width: int = Field(1024, ge=16, description="projector width, px")
    height: int = Field(768, ge=16, description="projector height, px")
    ipd: float = Field(0.064, ge=0.0, le=0.1, description="interpupillary distance, m")
    eye: list[float] = Field(default_factory=lambda: scene.EYE.tolist(), description="cyclopean eye V, m")
    screen_point: list[float] = Field(default_factory=lambda: scene.SCREEN_POINT.tolist())
    screen_normal: list[float] = Field(default_factory=lambda: scene.SCREEN_NORMAL.tolist())
    projector_position: list[float] = Field(default_factory=lambda: scene.PROJECTOR.tolist(),
                                            description="projector light source P, m")
    projector_pixel: float = Field(scene.PIXEL_ON_SCREEN, gt=0.0, description="m per px on the screen")
    projector_K: list[list[float]] | None = Field(None, description="3x3 intrinsics, px (None: default model)")
    projector_R: list[list[float]] | None = Field(None, description="3x3, columns = projector x,y,z axes")
    correction: Literal["auto", "none", "flat", "four_triangle", "fine"] = "auto"
    accuracy_target: float = Field(scene.PIXEL_ON_SCREEN, gt=0.0, description="image error budget, m")
    fine_modes: int = Field(16, ge=1, le=64, description="membrane modes of the fine model")
    tension_ratio: float = Field(1.0, gt=0.0, description="membrane T_v / T_u")
    contact_radius: float = Field(0.008, gt=0.0, description="finger contact radius, m")
    push_threshold: float = Field(0.001, ge=0.0, description="depth behind the sheet that counts as a push, m")
    sheet_half_width: float = Field(scene.SHEET_SIZE / 2, gt=0.0, description="half the free-edge length, m")
    publish_rate: float = Field(10.0, gt=0.0, le=240.0, description="RenderedFrame rate, Hz")
    max_render_rate: float = Field(60.0, gt=0.0, le=240.0,
                                   description="cap on redraws, Hz (a redraw follows each new fingertip or "
                                               "deformation; the real projector window refreshes at 120 Hz)")
    publish_scale: float = Field(0.25, gt=0.0, le=1.0, description="downscale of the published images")
    samples: int = Field(0, ge=0, le=16, description="MSAA samples")
    display: Literal["headless", "window"] = "headless"
    stereo_mode: Literal["frame_sequential", "side_by_side"] = "frame_sequential"

    @field_validator("eye", "screen_point", "screen_normal", "projector_position")
    @classmethod
    def _vec3(cls, v: list[float]) -> list[float]:
        if len(v) != 3 or not all(np.isfinite(v)):
            raise ValueError(f"must be 3 finite numbers, got {v!r}")
        return v

    @field_validator("display")
    @classmethod
    def _window_lib(cls, v: str) -> str:
        if v == "window" and importlib.util.find_spec("glfw") is None:
            raise ValueError("display='window' (fullscreen projector output) needs the 'glfw' package, which is "
                             "not installed (pip install glfw); use display='headless'")
        if v == "window":
            raise ValueError("display='window' is not implemented yet; use display='headless'")
        return v


def check_sheet(sheet: SheetSurface, eye, projector, min_cos: float = 0.02) -> None:
    """Raise ``ValueError`` if the eye is not in front of ``sheet`` or the projector not behind it."""
    if (np.asarray(eye) - sheet.origin) @ sheet.normal <= 1e-6:
        raise ValueError(f"eye on the wrong side of the sheet (normal {sheet.normal.round(3).tolist()})")
    if (np.asarray(projector) - sheet.origin) @ sheet.normal >= -1e-6:
        raise ValueError("projector is not behind the sheet")


def _check_pose(name: str, T: np.ndarray) -> None:
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0 or not np.allclose(T[3], [0, 0, 0, 1]):
        raise InputRejected(f"{name}.pose is not a rigid transform: {T.round(4).tolist()}")


class RendererNode(Node):
    """Projector renderer (see module docstring). Params: :class:`RendererParams`."""

    Params = RendererParams
    node_type = "renderer"

    async def setup(self) -> None:
        p: RendererParams = self.params
        self.eye = np.asarray(p.eye, dtype=float)
        _check_screen(self.eye, p.projector_position, p.screen_point, p.screen_normal)
        if p.projector_K is not None or p.projector_R is not None:
            d = Projector.default(p.width, p.height, p.projector_pixel, p.projector_position)
            K = np.asarray(p.projector_K, dtype=float) if p.projector_K is not None else d.K
            R = np.asarray(p.projector_R, dtype=float) if p.projector_R is not None else d.R
            if K.shape != (3, 3) or R.shape != (3, 3):
                raise ValueError(f"projector_K and projector_R must be 3x3, got {K.shape}, {R.shape}")
            self.projector = Projector(K, R, np.asarray(p.projector_position, dtype=float), p.width, p.height)
        else:
            self.projector = Projector.default(p.width, p.height, p.projector_pixel, p.projector_position)
        self._lock = threading.Lock()
        self._mesh = cylinder_mesh()
        self._mesh_normals = vertex_normals(*self._mesh)
        self._mesh_dirty = True
        self._mesh_stamp = 0.0
        self._home_left, self._home_right = scene.clamp_poses(np.zeros(3), scene.SCREEN_NORMAL,
                                                              np.array([0.0, 1.0, 0.0]), 0.0)
        self._pose = {"left": None, "right": None}
        self._finger: np.ndarray | None = None
        self._finger_stamp = 0.0
        self._last_sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], half_width=p.sheet_half_width)
        self.model_used = "none"
        self.frames = 0
        self._gl = ThreadPoolExecutor(1, thread_name_prefix="renderer-gl")
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._gl, self._gl_init)
        self.pub = self.publisher(topics.RENDERED)
        self.subscribe(topics.DEFORMATION, self.on_deformation, qos=QoS.LATEST)
        self.subscribe(topics.ARM_LEFT_STATE, self.on_arm, qos=QoS.LATEST)
        self.subscribe(topics.ARM_RIGHT_STATE, self.on_arm, qos=QoS.LATEST)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST)
        self._want = asyncio.Event()
        self._last_render = 0.0
        self._last_publish = 0.0
        self._render_task = loop.create_task(self._render_loop())
        self.timer(1.0 / p.publish_rate, self.on_timer)

    def _request(self) -> None:
        """Ask for a redraw (thread-safe: input handlers run in worker threads)."""
        self._loop.call_soon_threadsafe(self._want.set)

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

    def _gl_init(self) -> None:
        p: RendererParams = self.params
        self.renderer = StereoRenderer(self.projector, eye=self.eye, ipd=p.ipd, screen_point=p.screen_point,
                                       screen_normal=p.screen_normal, samples=p.samples)
        probes = self._mesh[0][self._mesh[0][:, 0] > -scene.CYLINDER_RADIUS].astype(float)[::7]
        home = self._last_sheet
        self.table = {m: [] for m in MODELS}
        for S in np.linspace(0.0, 0.06, 13):
            pe = predict_model_errors(float(S), eye=self.eye, projector=self.projector.position,
                                      screen_point=p.screen_point, screen_normal=p.screen_normal,
                                      probes=probes, sheet=home)
            for m in MODELS:
                self.table[m].append((float(S), pe[m]))

    async def teardown(self) -> None:
        if hasattr(self, "_render_task"):
            self._render_task.cancel()
        if hasattr(self, "_gl"):
            if hasattr(self, "renderer"):
                await asyncio.get_running_loop().run_in_executor(self._gl, self.renderer.release)
            self._gl.shutdown(wait=True)

    # ------------------------------------------------------------------ inputs (worker threads)
    def on_deformation(self, msg: ObjectDeformation) -> None:
        v, f = msg.vertices, msg.faces
        if len(v) == 0 or len(f) == 0:
            raise InputRejected(f"deformation has {len(v)} vertices and {len(f)} faces")
        if f.min() < 0 or f.max() >= len(v):
            raise InputRejected(f"faces index out of range [0, {len(v)}): min {f.min()}, max {f.max()}")
        n = vertex_normals(v, f)
        with self._lock:
            self._mesh = (v, f)
            self._mesh_normals = n
            self._mesh_dirty = True
            self._mesh_stamp = float(msg.source_stamp)
        self._request()

    def on_arm(self, msg: ArmJointState) -> None:
        T = np.asarray(msg.pose, dtype=float)
        _check_pose(f"{msg.arm} arm", T)
        with self._lock:
            other = self._pose["right" if msg.arm == "left" else "left"]
        if other is None:
            other = self._home_right if msg.arm == "left" else self._home_left
        Tl, Tr = (T, other) if msg.arm == "left" else (other, T)
        try:
            sheet = SheetSurface.from_clamps(Tl, Tr, half_width=self.params.sheet_half_width)
            check_sheet(sheet, self.eye, self.projector.position)
        except ValueError as exc:
            raise InputRejected(f"{msg.arm} arm pose gives an unusable sheet: {exc}") from exc
        with self._lock:
            self._pose[msg.arm] = T

    def on_fingertip(self, msg: Fingertip) -> None:
        with self._lock:
            self._finger = np.asarray(msg.position, dtype=float) if msg.valid else None
            self._finger_stamp = float(msg.exposure_stamp)
        self._request()

    # ------------------------------------------------------------------ output
    def current_sheet(self) -> SheetSurface:
        """Actual sheet from the latest clamp poses (home pose for an arm not heard from) and fingertip."""
        p: RendererParams = self.params
        with self._lock:
            Tl = self._pose["left"] if self._pose["left"] is not None else self._home_left
            Tr = self._pose["right"] if self._pose["right"] is not None else self._home_right
            finger = self._finger
        flat = SheetSurface.from_clamps(Tl, Tr, half_width=p.sheet_half_width)
        if finger is None:
            return flat
        depth = -float((finger - flat.origin) @ flat.normal)
        if depth <= p.push_threshold:
            return flat
        kw = {"modes": p.fine_modes, "tension_ratio": p.tension_ratio, "contact_radius": p.contact_radius}
        return SheetSurface.from_clamps(Tl, Tr, half_width=p.sheet_half_width, pushed_point=finger,
                                        membrane_kwargs=kw)

    def pick_model(self, sheet: SheetSurface) -> str:
        """The correction model for ``sheet`` (param ``correction``; "auto" chooses by ``accuracy_target``)."""
        want = self.params.correction
        if want != "auto":
            return want
        if sheet.membrane is None:
            return "flat"
        return choose_model(sheet.membrane.depth, self.table, self.params.accuracy_target,
                            models=("flat", "four_triangle", "fine"))

    def _frame(self, publish: bool = True) -> RenderedFrame | None:
        """Correct and draw the pair for the newest inputs (GL thread); read it back if ``publish``."""
        p: RendererParams = self.params
        t0 = time.perf_counter()
        with self._lock:
            mesh, normals, dirty = self._mesh, self._mesh_normals, self._mesh_dirty
            self._mesh_dirty = False
            stamp = max(self._finger_stamp, self._mesh_stamp)
        if dirty:
            self.renderer.set_mesh(mesh[0], mesh[1], normals)
        try:
            sheet = self.current_sheet()
            check_sheet(sheet, self.eye, self.projector.position)
            self._last_sheet = sheet
        except ValueError as exc:
            self.state_message = f"sheet unusable ({exc}); drawing the last good sheet"
            sheet = self._last_sheet
        model = self.pick_model(sheet)
        try:
            self.renderer.set_model(model, sheet, fine_modes=p.fine_modes)
        except ValueError as exc:
            self.state_message = f"model {model} failed ({exc}); drawing uncorrected"
            self.renderer.set_model("none")
        self.model_used = self.renderer.model
        self.renderer.render_pair()
        render_time = time.perf_counter() - t0
        if not publish:
            return None
        left, right = self.renderer.read_pair(p.publish_scale)
        self.frames += 1
        return RenderedFrame(header=self.pub.header("projector"), left=left, right=right, scale=p.publish_scale,
                             correction=self.model_used, render_time=render_time, source_stamp=stamp)

    async def on_timer(self) -> None:
        if time.monotonic() - self._last_render >= 1.0 / self.params.publish_rate:
            self._want.set()   # nothing new arrived: still redraw (and publish) at publish_rate
