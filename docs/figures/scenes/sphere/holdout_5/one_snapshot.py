"""One-off (session 29; run from the repository root after the held-out 5° run beside this file has cached its
push: ``python3 docs/figures/scenes/sphere/holdout_5/one_snapshot.py``): which of the sphere table's two
snapshots around 5° is off? The held-out 5° push against the table served three ways — the shipped blend of
0° and 10° (what the FEM node serves), the 0° snapshot alone rotated by +5°, and the 10° snapshot alone rotated
by −5° (the same rotate-then-blend as nodes/fem/sphere_snapshots.py, with one angle) — over the visible rendered
vertices, depth by depth. Writes one_snapshot.json beside this file."""

import json
import math
import os
import sys

sys.path.insert(0, ".")
import numpy as np  # noqa: E402

from flexsheet.experiments.fem_scene import visible_errors  # noqa: E402
from flexsheet.experiments.sphere_table import alpha_path  # noqa: E402
from flexsheet.model.scenes import load_scene  # noqa: E402
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache  # noqa: E402
from nodes.fem.material import Material  # noqa: E402
from nodes.fem.scene_model import SceneModel  # noqa: E402
from nodes.fem.sphere_snapshots import (  # noqa: E402
    DEFAULT_SPHERE_GRID,
    DEFAULT_SPHERE_SPEC,
    SphereSnapshotModel,
    sphere_frame,
    sphere_table_key,
)

HERE = os.path.dirname(os.path.abspath(__file__))
ALPHA = 5.0


def main() -> int:
    sc = load_scene(os.path.join("launch", "scenes", "sphere.yaml"))
    fr, grid, spec = sphere_frame(sc), DEFAULT_SPHERE_GRID, DEFAULT_SPHERE_SPEC
    cache = ArrayCache(DEFAULT_CACHE_DIR)
    rt = SceneModel(sc)
    probes = rt.rest_vertices.astype(float)
    table = cache.load("spheresnap", sphere_table_key(sc, grid, spec))
    p = alpha_path(sc, ALPHA, grid, spec, probes, cache)
    n = fr.direction(math.radians(ALPHA))
    q = fr.center + fr.radius * n
    depths = grid.depths()[1:]
    held = rt.held
    ref = np.asarray(p["u_probes"], float)[1:]
    k = len(np.asarray(table["alphas"]))

    def one(i):
        return {key: (np.asarray(v)[[i]] if np.ndim(v) >= 1 and np.shape(v)[0] == k else v)
                for key, v in table.items()}

    rows = {}
    for name, tb in (("blend of 0 and 10 deg (served)", table), ("0 deg alone", one(0)), ("10 deg alone", one(1))):
        sm = SphereSnapshotModel(tb, probes, E=Material.of_scene(sc.material).E)
        u = np.stack([sm.surface(n, float(d))[0] for d in depths])
        e = visible_errors(u, ref, probes, held, q, n, depths, sc.finger.radius)
        rows[name] = {"error_mm": e, "max_mm": max(e)}
        print(f"{name}: {max(e):.2f} mm at most", file=sys.stderr)
    out = {"what": __doc__.split("\n\n")[0].replace("\n", " "), "alpha_deg": ALPHA,
           "depths_m": depths.tolist(), "variants": rows}
    with open(os.path.join(HERE, "one_snapshot.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
