"""The hottest code of a simulated run: ``flexsheet bench sim --profile`` runs the launch's ``clock: sim``
container under :mod:`cProfile` (``$FLEXSHEET_PROFILE``, :data:`flexsheet.runtime.container.PROFILE_ENV`)
and reduces its stats to what a reader acts on: the functions and the files with the most own time, in
CPU-seconds per simulated second (the profiler's overhead included, so read them as shares, not as the run's
speed; the speed is the unprofiled run's).
"""

from __future__ import annotations

import pstats
from pathlib import Path

__all__ = ["hottest"]


def _where(filename: str, root: Path) -> str:
    """``filename`` relative to the checkout or to ``site-packages`` (a library's own path), else as is."""
    if filename.startswith(str(root)):
        return str(Path(filename).relative_to(root))
    marker = "site-packages/"
    return filename.split(marker, 1)[1] if marker in filename else filename


def hottest(stats_file: str | Path, sim_s: float, top: int = 25) -> dict:
    """From a :mod:`cProfile` stats file of a run spanning ``sim_s`` simulated seconds:
    ``{"functions": [{"where", "function", "calls", "own", "cumulative"}], "files": [{"file", "own"}],
    "total_own"}``, times in CPU-s per simulated s, the ``top`` largest own times first (``files`` sums own
    time per source file). Raises ``ValueError`` if ``sim_s`` is not > 0; ``OSError`` if the file is
    missing."""
    if not sim_s > 0.0:
        raise ValueError(f"sim_s must be > 0 simulated seconds, got {sim_s!r}")
    st = pstats.Stats(str(stats_file))
    root = Path(__file__).resolve().parents[2]
    rows, files = [], {}
    total = 0.0
    for (filename, line, func), (_cc, ncalls, tt, ct, _callers) in st.stats.items():  # type: ignore[attr-defined]
        where = _where(filename, root)
        total += tt
        files[where] = files.get(where, 0.0) + tt
        rows.append({"where": f"{where}:{line}", "function": func, "calls": int(ncalls),
                     "own": tt / sim_s, "cumulative": ct / sim_s})
    rows.sort(key=lambda r: -r["own"])
    ranked = sorted(files.items(), key=lambda kv: -kv[1])[:top]
    rnd = {"own": 4, "cumulative": 4}
    funcs = [{k: (round(v, rnd[k]) if k in rnd else v) for k, v in r.items()} for r in rows[:top]]
    return {"functions": funcs,
            "files": [{"file": f, "own": round(t / sim_s, 4)} for f, t in ranked],
            "total_own": round(total / sim_s, 4)}
