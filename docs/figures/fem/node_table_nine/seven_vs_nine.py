"""One-off (session 22; run from the repository root: python3 docs/figures/fem/node_table_nine/seven_vs_nine.py OLD7.npz 5 55 7.5 15, OLD7.npz = git show 511d178:nodes/fem/data/snapshots_2c347cbc84a9e6b10389beb3.npz): the seven-azimuth table (sessions 18-21) and the nine-azimuth one judged at the same
held-out azimuths against the cached stable paths, as node_table_holdout judges."""
import json, sys
import numpy as np
sys.path.insert(0, ".")
from dataclasses import replace
from flexsheet.experiments import fem as F
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
from nodes.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, PREVIOUS_ANGLES_DEG, table_key

mat = F.DEFAULT_MATERIAL
cache = ArrayCache(DEFAULT_CACHE_DIR, F._log)
st = replace(F.settings_for(False), grid=DEFAULT_GRID, snap_spec=DEFAULT_REF_SPEC)
rm = F.realtime_model(st, mat, DEFAULT_CACHE_DIR)
seven = dict(np.load(sys.argv[1], allow_pickle=False))
# the nine-azimuth grid is PREVIOUS_ANGLES_DEG since session 23 added 7.5 deg (DEFAULT_GRID has ten)
nine = cache.load("snapshots", table_key(replace(DEFAULT_GRID, angles_deg=PREVIOUS_ANGLES_DEG), DEFAULT_REF_SPEC,
                                         mat.nu, F.FINGER_R, Jm=mat.Jm))
out = {"what": "largest visible-surface error (mm) of each table at a held-out azimuth against that push's own "
               "stable path on the table's mesh (node_table_holdout); one-off script, session 22",
       "rows": F.node_table_compare({"seven": seven, "nine": nine}, sys.argv[2:], mat, cache, rm)}
for row in out["rows"]:
    print(row["azimuth_deg"], {k: (v["max_error_mm"], v["over_target_from_mm"]) if isinstance(v, dict) else v
                               for k, v in row.items() if k not in ("azimuth_deg", "depths_mm")}, flush=True)
json.dump(out, open("seven_vs_nine.json", "w"), indent=1)
