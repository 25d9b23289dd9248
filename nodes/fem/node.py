"""FEM node: fingertip in, deformed virtual object out. A thin shell around the model
:mod:`flexsheet.fem.served` builds for its scene.

Subscribes ``/fingertip`` (QoS LATEST; ``predicted_position`` when ``use_prediction``). Publishes
``/object/deformation`` (:class:`messages.ObjectDeformation`) per fingertip: deformed surface vertices
(display frame, float32), faces, contact force N, local stiffness dF/dd N/m, depth, method, max strain,
status, valid, ``source_stamp`` = the fingertip's ``exposure_stamp``; and, latched, ``/object/force_depth``
(what the finger is asked to feel along the stroke).

The object is the ``scene`` param's scene file (:mod:`flexsheet.model.scenes`; the launcher fills it from the
launch file's top-level ``scene:``, as for the planner and the renderer; none =
``launch/scenes/cylinder.yaml``, the paper's cylinder), with its material and finger. Start-up (``setup``),
one path for every scene, off the event loop: :func:`flexsheet.fem.served.build_model` loads its real-time
linear model from the disk cache or precomputes it (logged with timing; the paper's cylinder on its own mesh,
chosen from the accuracy table, any other scene on its gmsh mesh along the stroke), then
:func:`flexsheet.fem.served.attach_table` attaches the scene's nonlinear table where one is stored (the
cylinder's snapshot table, a sphere's table, a path table along the stroke; the cylinder's model table may
pick linear instead, :func:`flexsheet.fem.choose.choose_fem_model`). Without a stored table the node serves
the linear model; any scene but the cylinder then has its path table built on first use (``table_build``, on
by default: :class:`flexsheet.fem.first_use_build.FirstUseBuild`, a worker process at idle priority; on the
wall clock the linear model serves meanwhile, a simulated clock waits for it as for any
:meth:`~flexsheet.runtime.node.Node.background` work, so no table arrives at a host-dependent simulated
moment; progress in the log and the diagnostics), attaches it and republishes ``/object/force_depth`` from
it; a failed build is logged and the linear model keeps serving. The cylinder's snapshots can be built
in a background thread at low priority (``snapshot_build``). The diagnostics message tells which
model is served and why. Every ``ObjectDeformation`` carries ``scene_key`` = the scene's
:meth:`~flexsheet.model.scenes.Scene.key` so that the planner uses the FEM's dF/dd only for the object it
presents. A lost marker publishes the rest shape with ``valid=False, status="rejected:marker_lost"``. NaN,
out-of-object or too-deep fingertips raise :class:`InputRejected` (one log line, counted in diagnostics; the
node keeps running).
"""

from __future__ import annotations

import asyncio
import math
import os
import threading
import time

import numpy as np

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.force_depth import build_force_depth
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.snapshot_build import load_or_build
from flexsheet.fem.scene_model import SceneModel
from flexsheet.fem.served import attach_table, build_model, snapshots_message
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC
from flexsheet.model.scenes import DEFAULT_SCENE_FILE, load_scene
from flexsheet.model.timing import LAB
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.qos import QoS
from messages import Fingertip, ObjectDeformation, ObjectForceDepth, topics
from nodes.fem.first_use import FirstUseTable
from nodes.fem.params import FemParams

__all__ = ["FemNode"]

class FemNode(FirstUseTable, Node):
    """See the module docstring."""

    Params = FemParams
    #: a deformation (~20 kB of vertices) or the force-depth table (~23 kB), with room (sizes the send queue)
    LARGEST_MESSAGE_BYTES = 64 << 10

    async def setup(self) -> None:
        """Load the scene, build its model and attach its table (may take seconds: in worker threads), then
        subscribe and publish the force-depth table."""
        p: FemParams = self.params
        self.scene = load_scene(p.scene or DEFAULT_SCENE_FILE)
        self.scene_key = self.scene.key()
        self.log.info("fem: scene: %s", self.scene.describe())
        self._lock = threading.Lock()
        self._first_use = None
        cfg = p.fem_config()
        self.model, built = await asyncio.to_thread(build_model, self.scene, cfg)
        self.log.info("%s", built)
        # off the event loop: attaching a path table precomputes its contact-following moves (2-5 s, more on a
        # loaded machine; flexsheet/fem/path_snapshots.py), during which heartbeats must go on
        table = await asyncio.to_thread(attach_table, self.model, self.scene, cfg)
        self.state_message = table.message
        builds = (isinstance(self.model, SceneModel) and table.missing and table.kind == "path"
                  and p.table_build)
        if not builds:                  # a first-use build says what serves meanwhile (first_use.py)
            self.log.log(table.level, table.message)
        self.pub = self.publisher(topics.DEFORMATION)
        self.pub_force_depth = self.publisher(topics.FORCE_DEPTH)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST, sim_cost=LAB.compute("fem"))
        if isinstance(self.model, RealtimeModel):
            if p.nonlinear:
                await self.background(self._build_nonlinear, "fem-corotational")
            if table.missing and p.snapshot_build:
                self.state_message = (f"fem: scene {self.scene.name!r}: building nonlinear snapshots in the "
                                      "background - serving the LINEAR model")
                self.log.warning(self.state_message)
                await self.background(self._build_snapshots, "fem-snapshots", ArrayCache(p.cache_dir or None),
                                       Material.of_scene(self.scene.material))
        await asyncio.to_thread(self._publish_force_depth)
        if isinstance(self.model, SceneModel):     # its sparse fallback serves any push off the stroke's band
            await self.background(self._warm_sparse, "fem-sparse")
            if builds:
                self._start_first_use(cfg.cache_dir)
            if self._first_use is not None:       # a simulated clock waits for it (Node.background)
                await self.background(self._first_use.join, "fem-first-use-wait")

    async def teardown(self) -> None:
        """End a first-use build still running (its finished pushes stay cached: the next start resumes)."""
        if self._first_use is not None:
            self._first_use.stop()
        await super().teardown()

    def _publish_force_depth(self) -> None:
        """Push the served model along the stroke (:func:`flexsheet.fem.force_depth.build_force_depth`) and
        publish what the finger is asked to feel on the latched ``/object/force_depth``: in setup, off the
        event loop, before any fingertip is served (0.7–2 s; in a background thread it held the model's lock
        per push and stalled the fingertips waiting for it). A failure is logged, never fatal."""
        t = time.perf_counter()
        try:
            fd = build_force_depth(self.scene, self.model, lock=self._lock)
        except Exception:  # noqa: BLE001 - the table must never take the node down
            self.log.exception("fem: building the force-depth table failed; the planner keeps its own "
                               "estimate")
            return
        self.pub_force_depth.publish(ObjectForceDepth(
            header=self.pub_force_depth.header("display"), points=fd.points, normals=fd.normals,
            names=list(fd.names), depths=fd.depths, force=fd.force, scene_key=fd.scene_key,
            method=type(self.model).__name__))
        i = fd.names.index("reference")
        self.log.info("fem: force-depth along the stroke: %d points x %d depths to %.0f mm in %.1f s; at the "
                      "reference %.3f N at 5 mm, %.3f N at 10 mm", len(fd.names), len(fd.depths),
                      fd.depths[-1] * 1e3, time.perf_counter() - t, fd.force_at(fd.points[i], 0.005),
                      fd.force_at(fd.points[i], 0.01))

    def _warm_sparse(self) -> None:
        """Assemble the scene's full model (the sparse fallback) off the real-time path."""
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
        except (OSError, AttributeError):
            pass
        try:
            _ = self.model.model
        except Exception:  # noqa: BLE001 - a warm-up must never take the node down
            self.log.exception("fem: assembling the scene's sparse fallback failed")

    def _attach(self, table: dict, how: str) -> None:
        """Attach the cylinder's snapshot ``table`` while fingertips are served, and say ``how`` it came."""
        with self._lock:
            self.model.attach_snapshots(table, axial_max=self.params.snapshot_axial_max)
        self.state_message = snapshots_message(self.scene, self.model, how)
        self.log.info(self.state_message)

    def _build_snapshots(self, cache: ArrayCache, mat: Material) -> None:
        """Build the cylinder's missing snapshot table (tens of minutes; this thread at nice 19), then attach
        it."""
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)   # this thread only (Linux)
        except (OSError, AttributeError):
            pass
        t = time.perf_counter()
        try:
            table, _, _ = load_or_build(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, self.scene.finger.radius,
                                        build=True, contact=self.scene.finger.contact)
            self._attach(table, f"built in {time.perf_counter() - t:.0f} s")
        except Exception:  # noqa: BLE001 - background build must never take the node down
            self.state_message = (f"fem: scene {self.scene.name!r}: building the nonlinear snapshots failed "
                                  "- serving the LINEAR model")
            self.log.exception(self.state_message)

    def _build_nonlinear(self) -> None:
        """Build (or load) the cylinder's corotational depth table and attach it (``nonlinear``)."""
        m = self.model
        p: FemParams = self.params
        depths = np.linspace(0.0, min(p.depth_max, p.max_depth), p.nonlinear_steps)
        cache = ArrayCache(p.cache_dir or None)
        key = cache_key(m.cache_key, p.nonlinear_steps, f"{depths[-1]:.4f}")
        t = time.perf_counter()

        def build() -> dict:
            self.log.info("fem: building corotational table (%d depths) in the background ...", len(depths))
            m.build_nonlinear_table(depths)
            return dict(m.nonlinear)

        try:
            z, hit, _ = cache.get_or_compute("corotational", key, build, "corotational table")
            m.nonlinear = {k: z[k] for k in ("angles", "depths", "U", "F", "inverted")}
            if not hit:
                self.log.info("fem: corotational table ready in %.1f s", time.perf_counter() - t)
        except Exception:  # noqa: BLE001 - background build must never take the node down
            self.log.exception("fem: corotational table failed; linear only")

    def on_fingertip(self, msg: Fingertip) -> None:
        """Deform for one fingertip and publish; raises :class:`InputRejected` for unusable positions."""
        m = self.model
        if not msg.valid:
            with self._lock:
                m.reset()
            self._publish(msg, m.rest_vertices, 0.0, 0.0, 0.0, np.zeros(3), "none", 0.0,
                          "rejected:marker_lost", False)
            return
        tip = msg.predicted_position if self.params.use_prediction else msg.position
        try:
            with self._lock:
                u = m.update(tip)
        except ValueError as exc:
            raise InputRejected(f"fingertip.position: {exc}") from exc
        self._publish(msg, u.vertices, u.force, u.stiffness, u.depth, u.contact_point, u.method, u.max_strain,
                      u.status, u.valid)

    def _publish(self, msg, verts, force, stiff, depth, cp, method, strain, status, valid) -> None:
        """Publish one deformation. The numbers are checked before a header (and its seq) is taken, so a value
        the message refuses never leaves a gap in ``seq`` that a subscriber would count as lost on the wire;
        round-off below zero (a dF/dd of −1e-12 N/m at first touch) is clamped to the message's bound 0."""
        vals = {"contact_force": force, "stiffness": stiff, "depth": depth, "max_strain": strain}
        for name, v in vals.items():
            if not math.isfinite(v):
                raise InputRejected(f"fem: {name} is {v!r} (not finite): nothing published")
        force, stiff, depth, strain = (max(0.0, float(v)) for v in vals.values())
        self.pub.publish(ObjectDeformation(
            header=self.pub.header("display"), vertices=np.ascontiguousarray(verts, np.float32),
            faces=self.model.faces, contact_force=float(force), stiffness=float(stiff), depth=float(depth),
            contact_point=np.asarray(cp, np.float64), method=method, max_strain=float(strain), status=status,
            valid=bool(valid), source_stamp=float(msg.exposure_stamp), scene_key=self.scene_key))

