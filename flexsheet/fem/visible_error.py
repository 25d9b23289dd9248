"""What the display shows of a push, and how far a model is from the reference there: the rendered vertices
the finger does not hide (:func:`visible_vertices`), the largest visible distance between two reference paths
(:func:`visible_diffs`), a real-time model's visible error on reference cases (:func:`errors`), and the
real-time model of a run's linear mesh whose vertices are the ones judged (:func:`realtime_model`)."""

from __future__ import annotations

import logging
import math

import numpy as np

from flexsheet.fem.choose import visible_mask
from flexsheet.fem.contact import finger_at
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.settings import FINGER_R, Settings
from flexsheet.fem.solver import solve_full

log = logging.getLogger(__name__)


def visible_vertices(points: np.ndarray, fixed: np.ndarray, angle_deg: float, depth: float,
                     mesh) -> np.ndarray:
    """(k,) bool: rendered vertices the finger (radius ``FINGER_R``, pushed at ``angle_deg`` deg to ``depth``
    m into the cylinder ``mesh``) does not hide. ``points`` (k, 3) m are the vertices' positions in the
    *deformed* reference surface (rest + the reference's displacement): vertices dragged down onto the
    finger's side lie inside the footprint though they started outside it. ``fixed`` (k,) support vertices."""
    fg = finger_at(math.radians(angle_deg), depth, FINGER_R, mesh.radius, mesh.center)
    return visible_mask(points, fg) & ~fixed


def visible_diffs(a: dict, b: dict, depths: np.ndarray, verts: np.ndarray, fixed: np.ndarray, mesh,
                  angle_deg: float = 0.0) -> list[float]:
    """Largest distance (m) between two reference paths' fields ``a["u"]``, ``b["u"]`` (D, k, 3) m at the
    rendered vertices ``verts`` (k, 3) m, per depth (D,) m, over the vertices visible on ``b``'s deformed
    surface (:func:`visible_vertices`, the push at azimuth ``angle_deg``)."""
    return [float(np.linalg.norm(a["u"][j] - b["u"][j], axis=1)[
        visible_vertices(verts + b["u"][j], fixed, angle_deg, d, mesh)].max()) for j, d in enumerate(depths)]


def errors(rm: RealtimeModel, cases: list[dict], kind: str, rest_footprint: bool = False) -> list[float]:
    """Largest visible-surface error (m) of model ``kind`` ("snapshots" | "linear") per validation case; the
    footprint taken on the deformed reference surface, or (``rest_footprint``) on the rest surface as before
    solver nh-3 (it counts vertices lying on the finger's side as visible; reported beside, for
    comparison)."""
    fixed = rm.mesh.fixed[rm.surface_nodes]
    verts = rm.rest_vertices.astype(float)
    model = rm.model if kind == "linear" else None
    surf_pts = rm.surface_nodes
    out = []
    for c in cases:
        a = math.radians(c["angle_deg"])
        fg = finger_at(a, c["depth"], FINGER_R, rm.mesh.radius, rm.mesh.center)
        if kind == "snapshots":
            u = rm.snapshots.surface(a, c["depth"], 0.0)[0]
        else:
            u = solve_full(model, fg).u[surf_pts]
        vis = visible_vertices(verts if rest_footprint else verts + c["u"], fixed, c["angle_deg"], c["depth"],
                               rm.mesh)
        out.append(float(np.linalg.norm(u - c["u"], axis=1)[vis].max()))
    return out


def realtime_model(st: Settings, mat: Material, cache_dir: str | None) -> RealtimeModel:
    """The node's real-time model (linear capacitance part) on the settings' mesh."""
    rm = RealtimeModel(st.linear_spec, mat, FINGER_R, max_depth=0.06, cache_dir=cache_dir, order=2)
    log.info(f"real-time mesh P2 {st.linear_spec.key()}: {rm.n_nodes} nodes, {len(rm.surface_nodes)} "
             "rendered vertices, "
             f"{'cache hit' if rm.cache_hit else f'precomputed in {rm.precompute_s:.1f} s'}")
    return rm
