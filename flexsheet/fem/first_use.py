"""A scene's nonlinear path table built on its first use: the FEM node serves a scene that has no stored table
(a new or drawn object) its linear model, builds the table in a worker process at idle priority, and serves
the table once it is cached; a later start loads it from the cache.

The table is the path table of :mod:`flexsheet.fem.path_snapshots` (stations along the stroke, pushed along
the inward normal by the scene's hyperelastic reference, :func:`flexsheet.fem.reference.scene_reference.
scene_reference`, minus the real-time model's linear solve; assembled by
:func:`flexsheet.fem.reference.path_table.assemble_path_table`), built to no more than the scene needs
(:data:`FIRST_USE`): 3 stations (the stroke's start, middle and end), pushes to the scene's ``use.max_depth``
(the depths it is judged at, ≥ 15 mm; drawn objects 20 mm) instead of 50 mm, on a mesh refined to 8 mm along
the push path instead of 6 mm. It is stored under its own key (:func:`first_use_key`: the full table's key and
the spec), so a full table (``flexsheet experiment fem --node-table``, shipped or cached) is always looked up
first and wins. Each station's push is cached on its own (kind "scenereference"), so a build that was stopped
resumes where it stopped.

The build itself: :mod:`flexsheet.fem.first_use_build`.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.path_snapshots import GRID, path_table_key

__all__ = ["FirstUseSpec", "FIRST_USE", "first_use_settings", "first_use_key", "load_first_use_table"]


@dataclass(frozen=True)
class FirstUseSpec:
    """What a first-use table holds: ``stations`` evenly along the stroke (start and end included), pushes in
    :data:`~flexsheet.fem.path_snapshots.GRID`'s 2.5 mm steps to ``depth_max`` m (None: the scene's
    ``use.max_depth``), the reference mesh of size ``h`` m refined to ``h_fine`` m within ``refine_radius`` m
    of the push path."""

    stations: int = 3
    h: float = 0.012
    h_fine: float = 0.008
    refine_radius: float = 0.015
    depth_max: float | None = None


#: the first-use build's one spec (module doc; docs/fem.md "A new scene's table" for its cost and accuracy)
FIRST_USE = FirstUseSpec()


def first_use_settings(sc, spec: FirstUseSpec | None = None) -> dict:
    """The stations' settings for :func:`~flexsheet.fem.reference.scene_reference.scene_reference`: depths
    (GRID's steps, the first ones of the full table's) to ``spec.depth_max`` or the scene's
    ``use.max_depth``, rounded up to a step; the mesh of ``spec`` (None: :data:`FIRST_USE`), refined along the
    whole push path."""
    spec = spec or FIRST_USE
    step = GRID["step"]
    d_max = float(spec.depth_max if spec.depth_max is not None else sc.use.max_depth)
    n = max(1, int(math.ceil(d_max / step - 1e-9)))
    depths = tuple(np.round(np.arange(1, n + 1) * step, 9))
    return {"depths": depths, "step": step, "h": spec.h, "refine_radius": spec.refine_radius,
            "path_depth": float(depths[-1])}


def first_use_key(sc, rt, spec: FirstUseSpec | None = None) -> str:
    """The cache key (kind "pathsnap") of scene ``sc``'s first-use table for the real-time model ``rt``: the
    full table's key (:func:`~flexsheet.fem.path_snapshots.path_table_key`), the spec and the depths it
    reaches (``spec`` None: :data:`FIRST_USE`)."""
    spec = spec or FIRST_USE
    return cache_key(path_table_key(sc.key(), rt.cache_key), "first-use",
                     json.dumps(asdict(spec), sort_keys=True), first_use_settings(sc, spec)["depths"][-1])


def load_first_use_table(rt, cache: ArrayCache, spec: FirstUseSpec | None = None) -> dict | None:
    """Scene ``rt.scene``'s first-use table (``spec`` None: :data:`FIRST_USE`) from ``cache``, or None."""
    return cache.load("pathsnap", first_use_key(rt.scene, rt, spec))
