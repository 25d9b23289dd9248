"""One-off (session 29; run from the repository root: ``python3
docs/figures/scenes/path_table_moves/rigid_moves.py [CACHE_DIR]``): would the path table's contact moves do
better over the rounded box's edge if they followed the contact's **frame** rather than its position? A negative
result, not adopted.

nodes/fem/path_snapshots.py moves each station's correction with the contact by the path's chord: vertex v takes
station s's correction at the rest-surface point nearest v − (P(f) − P(f_s)). Over the rounded box's 8 mm edge
the normal turns 23.4° between the stations at 0.75 and 0.833 of the stroke, so the chord is not how the
surface maps onto itself there. Tried: the rigid motion that carries the contact's frame (normal n, path tangent
t, n × t) at f onto the station's, v ↦ P(f_s) + R_s (v − P(f)), R_s = F(f_s) F(f)ᵀ ("rigid"), and the same with
the correction's vectors turned back by R_sᵀ ("rigid+rot"), against the translation the node serves, at the
held-out push at 0.792 (between those stations; solved on its own mesh as flexsheet.experiments.path_table
solves it, cached). The held-out pushes at 0.042 and 0.458 lie on the flat front face, where the frame does not
turn and the rigid move is the translation. Visible rendered vertices only, as everywhere. Writes
rigid_moves.json beside this file."""

import json
import math
import os
import sys

sys.path.insert(0, ".")
import numpy as np  # noqa: E402

from flexsheet.experiments import path_table as P  # noqa: E402
from flexsheet.experiments.fem_scene import visible_errors  # noqa: E402
from flexsheet.model.scenes import load_scene  # noqa: E402
from nodes.fem import path_snapshots as ps  # noqa: E402
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache  # noqa: E402
from nodes.fem.scene_model import SceneModel, attach_scene_table, finger_on_scene  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
HELD_OUT = 0.7916666666666666


class FrameMoves(ps.PathSnapshotModel):
    """The node's PathSnapshotModel with frame-following moves (module doc); ``frame(f)`` (3, 3): columns n, t, b."""

    def __init__(self, *a, frame, rotate_vectors: bool, **k):
        self._frame, self.rotate_vectors = frame, rotate_vectors
        super().__init__(*a, **k)

    def _move_targets(self, rv, g, f0, f1):
        pg, pst = self.path_point(g), self.path_point(np.array([f0, f1]))
        y = np.empty((len(g), 2, len(rv), 3))
        for a, ga in enumerate(g):
            fg = self._frame(ga)
            for s, fs in enumerate((f0, f1)):
                y[a, s] = pst[s] + (rv - pg[a]) @ (self._frame(fs) @ fg.T).T
        return y

    def lookup(self, fraction, depth):
        if not self.rotate_vectors:
            return super().lookup(fraction, depth)
        i, _ = self._cell(fraction, self.fractions)
        ff, saved = self._frame(fraction), self.correction
        c = saved.copy()
        for s in (i, i + 1):
            c[s] = (saved[s].astype(float) @ (self._frame(self.fractions[s]) @ ff.T)).astype(np.float32)
        self.correction = c
        try:
            return super().lookup(fraction, depth)
        finally:
            self.correction = saved


def main() -> int:
    cache_dir = sys.argv[1] if len(sys.argv) > 1 else DEFAULT_CACHE_DIR
    sc = load_scene(os.path.join("launch", "scenes", "rounded_box.yaml"))
    cache = ArrayCache(cache_dir)
    rt = SceneModel(sc, cache_dir=cache_dir)
    _, where = attach_scene_table(rt, cache)
    base = rt.path_table
    verts = rt.rest_vertices.astype(float)
    held = rt.held
    pf = np.linspace(0.0, 1.0, max(2, int(math.ceil(sc.stroke_length() / 0.0002)) + 1))   # as attach_path_table
    path, pn = sc.stroke_at(pf)

    def frame(f):
        n = np.array([np.interp(f, pf, pn[:, k]) for k in range(3)])
        n /= np.linalg.norm(n)
        i = min(max(int(np.searchsorted(pf, f)), 1), len(pf) - 1)
        t = path[i] - path[i - 1]
        t = t - (t @ n) * n
        t /= np.linalg.norm(t)
        return np.stack([n, t, np.cross(n, t)], axis=1)

    table = {k: getattr(base, k) for k in ("fractions", "depths", "correction", "force_ratio", "stiffness_ratio",
                                           "inverted", "max_strain")}
    table.update(reach=np.asarray(base.reach), rest_vertices=verts)
    table["points"], table["normals"] = sc.stroke_at(base.fractions)
    variants = {"translate (served)": base,
                "rigid": FrameMoves(table, verts, rt.faces, path, pf, frame=frame, rotate_vectors=False),
                "rigid+rot": FrameMoves(table, verts, rt.faces, path, pf, frame=frame, rotate_vectors=True)}
    ref = P._push(sc, HELD_OUT, P.GRID["h_fine"], verts, cache)
    q, n = sc.stroke_at([HELD_OUT])
    depths = np.asarray(base.depths[1:])
    u_ref = np.asarray(ref["u"])[:len(depths)]
    rows = {}
    for name, m in variants.items():
        rt.path_table = m
        u = np.stack([rt.update_finger(finger_on_scene(q[0], n[0], float(d), sc.finger.radius)).vertices.astype(float)
                      - verts for d in depths])
        e = visible_errors(u, u_ref, verts, held, q[0], n[0], depths, sc.finger.radius)
        rows[name] = {"error_mm": e, "max_mm": max(e)}
        print(f"{name}: {max(e):.2f} mm at most", file=sys.stderr)
    out = {"what": __doc__.split("\n\n")[1].replace("\n", " "), "scene": "rounded_box", "table_from": where,
           "held_out_fraction": HELD_OUT, "normal_turn_between_stations_deg": float(np.degrees(np.arccos(np.clip(
               table["normals"][9] @ table["normals"][10], -1, 1)))),
           "depths_m": depths.tolist(), "variants": rows, "adopted": False}
    with open(os.path.join(HERE, "rigid_moves.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
