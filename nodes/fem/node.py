"""FEM node: fingertip in, deformed virtual object out. A thin shell around :class:`flexsheet.fem.realtime.RealtimeModel`.

Subscribes ``/fingertip`` (QoS LATEST; ``predicted_position`` when ``use_prediction``). Publishes
``/object/deformation`` (:class:`messages.ObjectDeformation`) per fingertip: deformed surface vertices (display
frame, float32), faces, contact force N, local stiffness dF/dd N/m, depth, method, max strain, status, valid,
``source_stamp`` = the fingertip's ``exposure_stamp``.

Start-up (``setup``): choose the mesh from the accuracy table (:mod:`flexsheet.fem.choose`, logged), then load the
capacitance matrices from the disk cache or precompute them (logged with timing). Then the model the scene
needs (:func:`flexsheet.fem.choose.choose_fem_model`, from ``flexsheet/fem/model_table.json``; mesh and model are
picked by :func:`flexsheet.fem.served.choose_cylinder_model`, which the experiments call too): linear where it
meets the accuracy target over ``depth_max``, otherwise the nonlinear snapshots (:mod:`flexsheet.fem.snapshots`), loaded
from the cache; when they are not cached the node serves the linear model and either builds them in a
background thread at low priority (``snapshot_build``) or says how to build them
(``flexsheet experiment fem --node-table``). The diagnostics message tells which model is being served and why.
The object is the ``scene`` param's (:mod:`flexsheet.model.scenes`; the launcher fills it from the launch file's
top-level ``scene:``, as for the planner and the renderer; none = the paper's cylinder). The paper's cylinder
(no scene, or a scene that is exactly it: same size and pose, back-half support, no inclusions) keeps the
path above; any other scene (sphere, rounded box, organ with its stiff inclusion) is meshed by gmsh and solved
by :class:`flexsheet.fem.scene_model.SceneModel` (linear, per-element material, capacitance over the stroke path,
cached), without the nonlinear snapshots (they exist for the cylinder only; the diagnostics message says so).
Every ``ObjectDeformation`` carries ``scene_key`` = the scene's :meth:`~flexsheet.model.scenes.Scene.key` so
that the planner uses the FEM's dF/dd only for the object it presents.
A lost marker publishes the rest shape with ``valid=False, status="rejected:marker_lost"``. NaN,
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
from pydantic import Field, field_validator

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.config import FemConfig
from flexsheet.fem.force_depth import build_force_depth
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.snapshot_build import load_or_build
from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC
from flexsheet.fem.scene_model import SceneModel, attach_scene_table
from flexsheet.fem.served import CylinderChoice, choose_cylinder_model, fem_models_as_cylinder
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, load_snapshot_table
from flexsheet.model.scenes import Scene, load_scene_or_paper
from flexsheet.model.timing import LAB
from flexsheet.runtime.node import InputRejected, Node
from flexsheet.runtime.params import build, config_fields, params_model
from flexsheet.runtime.qos import QoS
from messages import Fingertip, ObjectDeformation, ObjectForceDepth, topics

__all__ = ["FemParams", "FemNode"]


def _scene_file(cls, v: str | None) -> str | None:
    load_scene_or_paper(v)
    return v


FemParams = params_model(
    "FemParams",
    """FEM node parameters (launch file / ``--param k=v``). SI units.

    ``accuracy_target`` m (rendered-surface error target, default one projector pixel 0.7 mm);
    ``depth_min``/``depth_max`` m push-depth range the accuracy must hold over; ``max_depth`` m deeper input is
    rejected; ``finger_radius`` m; ``E`` Pa, ``nu``: material (soft-tissue defaults, see material.py; without a
    scene file the hyperelastic law is the paper scene's, a Gent solid with Jm 97.2, whose snapshot table ships
    in ``flexsheet/fem/data``);
    ``strain_limit``: largest principal strain before linear is declared invalid; ``cache_dir`` ("" = no
    disk cache); ``mesh_h``/``mesh_h_fine``/``refine_radius`` m and ``order`` override the automatic choice
    when all of h, h_fine are > 0; ``arc_deg``: half-angle of the working arc (deg) whose neighbourhood gets
    the precomputed contact region and refinement (0 = the front centre, the paper's push; elsewhere the full
    sparse solve is used); ``nonlinear``: build the corotational depth table (background thread);
    ``nonlinear_steps``: depth samples of that table; ``use_prediction``: use ``predicted_position``;
    ``model``: "auto" (the model table decides), "linear" or "snapshots"; ``snapshot_build``: build missing
    snapshots in a background thread (heavy: tens of minutes on a 2-core machine; else run
    ``flexsheet experiment fem --node-table``); ``snapshot_axial_max`` m: largest axial offset of the push served by the
    snapshots (translation along the axis). ``scene``: the scene file (launch/scenes/*.yaml; filled by the
    launcher from the launch file's ``scene:``; none = the paper's cylinder); for a scene other than the
    paper's cylinder its material, support and finger radius replace ``E``/``nu``/``finger_radius``, and
    ``mesh_h``/``mesh_h_fine``/``refine_radius``/``order`` (when h, h_fine > 0) set its mesh (default
    :data:`flexsheet.fem.scene_mesh.DEFAULT_SCENE_SPEC`, P2). Every param but ``scene`` is a field of —
    defined, defaulted and range-checked in — :class:`flexsheet.fem.config.FemConfig`; ``fem_config()`` builds it.
    """,
    config_fields(FemConfig),
    validators={"_scene_file": field_validator("scene")(_scene_file)},
    methods={"fem_config": lambda self: build(FemConfig, self)},
    module=__name__,
    scene=(str | None, Field(default=None, description="scene file (launch/scenes/*.yaml); none: the paper's")),
)


class FemNode(Node):
    """See the module docstring."""

    Params = FemParams
    #: a deformation (~20 kB of vertices) or the force-depth table (~23 kB), with room (sizes the send queue)
    LARGEST_MESSAGE_BYTES = 64 << 10

    async def setup(self) -> None:
        """Choose the model, load or precompute it (may take seconds: runs in a worker thread), then subscribe."""
        p: FemParams = self.params
        self.scene = load_scene_or_paper(p.scene)
        self.scene_key = self.scene.key()
        self.log.info("fem: scene: %s", self.scene.describe())
        self._lock = threading.Lock()
        if not fem_models_as_cylinder(self.scene):
            await self._setup_scene()
            return
        # a scene file's material; no scene: E, ν from the params with the paper scene's law (Gent, its Jm)
        mat = Material.of_scene(self.scene.material)
        mat = mat if p.scene else Material(p.E, p.nu, mat.Jm)
        choice = choose_cylinder_model(p.fem_config())
        spec, order = choice.spec, choice.order
        self.log.info("fem: %s", choice.mesh_reason)
        cache = p.cache_dir or None
        self.model = await asyncio.to_thread(
            RealtimeModel, spec, mat, p.finger_radius, p.max_depth, p.strain_limit, cache, None, order)
        m = self.model
        self.log.info("fem: ready in %.2f s (%s): P%d, %d nodes, %d candidate contact points, %.1f MB",
                      m.precompute_s, "cache hit" if m.cache_hit else "precomputed", order, m.n_nodes,
                      m.n_candidates, m.solver.nbytes / 1e6)
        self.pub = self.publisher(topics.DEFORMATION)
        self.pub_force_depth = self.publisher(topics.FORCE_DEPTH)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST, sim_cost=LAB.compute("fem"))
        if p.nonlinear:
            await self._background(self._build_nonlinear, "fem-corotational")
        await self._setup_snapshots(mat, choice)
        await asyncio.to_thread(self._publish_force_depth)

    async def _background(self, target, name: str, *args) -> None:
        """Run ``target(*args)`` in a daemon thread; on a simulated clock to completion before the node is
        active (what it attaches must not arrive at a host-dependent moment of simulated time)."""
        if self.clock.simulated:
            await asyncio.to_thread(target, *args)
        else:
            threading.Thread(target=target, args=args, name=name, daemon=True).start()

    async def _setup_scene(self) -> None:
        """Mesh and precompute (or load from the cache) the scene's model, then subscribe."""
        p: FemParams = self.params
        sc = self.scene
        spec, order = DEFAULT_SCENE_SPEC, 2
        if p.mesh_h > 0 and p.mesh_h_fine > 0:
            spec, order = MeshSpec(p.mesh_h, p.mesh_h_fine, p.refine_radius), p.order
        self.model = await asyncio.to_thread(SceneModel, sc, spec, order, None, p.max_depth, p.strain_limit,
                                             p.cache_dir or None, None)
        m = self.model
        self.log.info("fem: scene %r ready in %.2f s (%s): P%d %s, %d nodes, %d candidate contact points along "
                      "the stroke, %.1f MB", sc.name, m.precompute_s, "cache hit" if m.cache_hit else "precomputed",
                      order, spec.key(), m.n_nodes, m.n_candidates, m.solver.nbytes / 1e6)
        self.state_message = (f"fem: scene {sc.name!r}: linear P{order} scene model with per-element material "
                              f"({len(sc.inclusions)} inclusion(s)); nonlinear snapshots exist for the paper's "
                              "cylinder, the sphere and along a scene's stroke (path tables) only")
        # off the event loop: attaching a path table precomputes its contact-following moves (2-5 s, more on a
        # loaded machine; flexsheet/fem/path_snapshots.py), during which heartbeats must go on
        await asyncio.to_thread(self._setup_scene_table, sc)
        self.pub = self.publisher(topics.DEFORMATION)
        self.pub_force_depth = self.publisher(topics.FORCE_DEPTH)
        self.subscribe(topics.FINGERTIP, self.on_fingertip, qos=QoS.LATEST, sim_cost=LAB.compute("fem"))
        await asyncio.to_thread(self._publish_force_depth)
        await self._background(self._warm_sparse, "fem-sparse")

    def _publish_force_depth(self) -> None:
        """Push the served model along the stroke (:func:`flexsheet.fem.force_depth.build_force_depth`) and
        publish what the finger is asked to feel on the latched ``/object/force_depth``: in setup, off the event
        loop, before any fingertip is served (0.7–2 s; in a background thread it held the model's lock per push
        and stalled the fingertips waiting for it). A failure is logged, never fatal."""
        t = time.perf_counter()
        try:
            fd = build_force_depth(self.scene, self.model, lock=self._lock)
        except Exception:  # noqa: BLE001 - the table must never take the node down
            self.log.exception("fem: building the force-depth table failed; the planner keeps its own estimate")
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

    def _setup_scene_table(self, sc: Scene) -> None:
        """Attach the scene's nonlinear table (:func:`flexsheet.fem.scene_model.attach_scene_table`: a sphere's
        sphere table, any other scene's path table along its stroke) when this machine's cache or the shipped
        store has it, else serve linear and name the command that builds it."""
        cache = ArrayCache(self.params.cache_dir or None)
        try:
            kind, where = attach_scene_table(self.model, cache)
        except ValueError as exc:
            self.state_message = f"fem: scene {sc.name!r}: nonlinear table unusable ({exc}) - serving LINEAR"
            self.log.error(self.state_message)
            return
        if where is None:
            self.state_message = (f"fem: scene {sc.name!r}: no nonlinear {kind} table cached - serving the LINEAR "
                                  f"model (build it with `flexsheet experiment fem --scene {sc.source or 'SCENE.yaml'} "
                                  "--node-table --out DIR`)")
            self.log.warning(self.state_message)
            return
        if kind == "sphere":
            sm = self.model.snapshots
            self.state_message = (f"fem: scene {sc.name!r}: nonlinear sphere snapshots loaded from {where}: "
                                  f"polar angle <= {np.degrees(sm.alphas[-1]):.0f} deg, depth <= "
                                  f"{sm.depth_max * 1e3:.0f} mm; linear elsewhere")
        else:
            pt = self.model.path_table
            self.state_message = (f"fem: scene {sc.name!r}: nonlinear path table loaded from {where}: "
                                  f"{len(pt.fractions)} stations along the stroke, depth <= {pt.depth_max * 1e3:.0f} "
                                  f"mm, within {pt.reach * 1e3:.0f} mm of the stroke; linear elsewhere")
        self.log.info(self.state_message)

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

    async def _setup_snapshots(self, mat: Material, choice: CylinderChoice) -> None:
        """Attach the nonlinear snapshots when the scene needs them (cache hit), else say why not."""
        p: FemParams = self.params
        kind, why = choice.kind, choice.kind_reason
        self.log.info("fem: real-time model: %s (%s)", kind, why)
        if kind != "snapshots":
            self.state_message = f"fem: linear model ({why})"
            return
        cache = ArrayCache(p.cache_dir or None)
        table = load_snapshot_table(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, p.finger_radius,
                                    self.scene.finger.contact)
        if table is not None:
            self._attach(table, "loaded from the shipped store (flexsheet/fem/data)" if cache.shipped() else
                         "loaded from cache")
            return
        if not p.snapshot_build:
            self.state_message = ("fem: nonlinear snapshots not cached - serving the LINEAR model (build them with "
                                  f"`flexsheet experiment fem --node-table --nu {mat.nu:g} --Jm {mat.Jm:g}`, or set "
                                  "snapshot_build=true)")
            self.log.warning(self.state_message)
            return
        self.state_message = "fem: building nonlinear snapshots in the background - serving the LINEAR model"
        self.log.warning(self.state_message)
        await self._background(self._build_snapshots, "fem-snapshots", cache, mat)

    def _attach(self, table: dict, how: str) -> None:
        p: FemParams = self.params
        with self._lock:
            self.model.attach_snapshots(table, axial_max=p.snapshot_axial_max)
        s = self.model.snapshots
        self.state_message = (f"fem: nonlinear snapshots {how}: |angle| <= {np.degrees(s.angle_max):.0f} deg, "
                              f"depth <= {s.depth_max * 1e3:.0f} mm ({s.nbytes / 1e6:.0f} MB)")
        self.log.info(self.state_message)

    def _build_snapshots(self, cache: ArrayCache, mat: Material) -> None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)   # this thread only (Linux)
        except (OSError, AttributeError):
            pass
        t = time.perf_counter()
        try:
            table, _, _ = load_or_build(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, self.params.finger_radius,
                                        build=True, contact=self.scene.finger.contact)
            self._attach(table, f"built in {time.perf_counter() - t:.0f} s")
        except Exception:  # noqa: BLE001 - background build must never take the node down
            self.state_message = "fem: building the nonlinear snapshots failed - serving the LINEAR model"
            self.log.exception(self.state_message)

    def _build_nonlinear(self) -> None:
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
            self._publish(msg, m.rest_vertices, 0.0, 0.0, 0.0, np.zeros(3), "none", 0.0, "rejected:marker_lost", False)
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

