"""One-off (session 23; run from the repository root: python3 docs/figures/fem/node_table/nine_vs_ten.py 6.25 7.5 8.75 15):
the nine-azimuth table (session 22) and the ten-azimuth one (session 23) judged at the same held-out azimuths
against the cached stable paths, as node_table_holdout judges. Writes nine_vs_ten.json in the working folder."""
import json, sys
sys.path.insert(0, ".")
from dataclasses import replace
from flexsheet.experiments import fem as F
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
from nodes.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, PREVIOUS_ANGLES_DEG, table_key

mat = F.DEFAULT_MATERIAL
cache = ArrayCache(DEFAULT_CACHE_DIR, F._log)
st = replace(F.settings_for(False), grid=DEFAULT_GRID, snap_spec=DEFAULT_REF_SPEC)
rm = F.realtime_model(st, mat, DEFAULT_CACHE_DIR)
tabs = {n: cache.load("snapshots", table_key(g, DEFAULT_REF_SPEC, mat.nu, F.FINGER_R, Jm=mat.Jm))
        for n, g in (("nine", replace(DEFAULT_GRID, angles_deg=PREVIOUS_ANGLES_DEG)), ("ten", DEFAULT_GRID))}
out = {"what": "largest visible-surface error (mm) of each table at a held-out azimuth against that push's own "
               "stable path on the table's mesh (node_table_holdout); one-off script, session 23",
       "rows": F.node_table_compare(tabs, sys.argv[1:], mat, cache, rm)}
for row in out["rows"]:
    print(row["azimuth_deg"], {k: (v["max_error_mm"], v["over_target_from_mm"]) if isinstance(v, dict) else v
                               for k, v in row.items() if k not in ("azimuth_deg", "depths_mm")}, flush=True)
json.dump(out, open("nine_vs_ten.json", "w"), indent=1)
