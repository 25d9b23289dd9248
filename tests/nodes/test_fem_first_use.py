"""The FEM node on a scene with no stored nonlinear table (the sticky sphere with its short stroke,
tests/unit/conftest.py): it serves the linear model at once while the path table is built on first use in a
worker (here a tiny spec, nice 19 without SCHED_IDLE beside the test workers), then attaches it, says so once
and serves it; a second start loads it from the cache and builds nothing; a build that fails is logged as an
error and the linear model keeps serving."""

import asyncio
import functools
import time

import numpy as np
import yaml
from test_fem_node import PARAMS, _tip
from unit.conftest import _scene

import nodes.fem.first_use as fem_first_use
from flexsheet.fem import first_use
from flexsheet.fem.first_use import FirstUseSpec
from flexsheet.fem.first_use_build import FirstUseBuild
from flexsheet.runtime.testing import NodeHarness
from messages import topics
from nodes.fem.node import FemNode

TINY = FirstUseSpec(stations=2, h=0.02, h_fine=0.015, refine_radius=0.015, depth_max=0.0025)


def _params(tmp_path) -> dict:
    sc = _scene()
    path = tmp_path / "sticky_sphere.yaml"
    path.write_text(yaml.safe_dump(sc.model_dump(mode="json")))
    return dict(PARAMS, scene=str(path), cache_dir=str(tmp_path / "cache"))


def _press():
    q, n = _scene().stroke_at([0.5])
    return q[0] - 0.002 * n[0]


async def _until(h, what: str, timeout: float) -> None:
    t = time.monotonic()
    while what not in h.node.state_message:
        assert time.monotonic() - t < timeout, h.node.state_message
        await asyncio.sleep(0.2)


async def _served(h, stamp: float):
    h.inject(topics.FINGERTIP, _tip(_press(), stamp=stamp))
    return (await h.wait_for(topics.DEFORMATION, n=int(stamp), timeout=30.0))[-1]


def test_the_table_is_built_on_first_use_served_then_loaded_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setattr(first_use, "FIRST_USE", TINY)
    monkeypatch.setattr(fem_first_use, "FirstUseBuild", functools.partial(FirstUseBuild, idle=False))
    params = _params(tmp_path)

    async def first():
        async with NodeHarness(FemNode, params=params) as h:
            assert "built on first use in the background (2 stations to 2.5 mm)" in h.node.state_message
            lin = await _served(h, 1.0)               # served at once, by the linear model
            assert lin.valid and lin.method == "condensed" and lin.depth > 0.0015
            await _until(h, "built on first use, now served", 120.0)
            assert "nonlinear path table built on first use, now served (first-use table ready (2 stations" \
                in h.node.state_message, h.node.state_message
            tab = await _served(h, 2.0)
            assert tab.method == "path_snapshots" and abs(tab.depth - lin.depth) < 1e-9
            assert tab.contact_force > 0 and abs(tab.contact_force / lin.contact_force - 1) > 1e-4
            fd = await h.wait_for(topics.FORCE_DEPTH, n=2, timeout=10.0)     # republished from the table
            j = int(np.searchsorted(fd[0].depths, 0.002))               # a depth inside the table
            assert np.abs(fd[-1].force[:, j] - fd[0].force[:, j]).max() > 1e-4 * fd[0].force[:, j].max()
            return tab

    async def second():
        async with NodeHarness(FemNode, params=params) as h:
            assert h.node._first_use is None
            assert "nonlinear path table loaded from cache (built on first use): 2 stations" \
                in h.node.state_message, h.node.state_message
            return await _served(h, 1.0)

    tab = asyncio.run(first())
    again = asyncio.run(second())
    assert again.method == "path_snapshots"
    assert abs(again.contact_force - tab.contact_force) < 1e-9
    assert np.abs(np.asarray(again.vertices) - np.asarray(tab.vertices)).max() < 1e-7


def test_a_failing_build_is_logged_and_linear_keeps_serving(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(first_use, "FIRST_USE", FirstUseSpec(stations=2, h=0.2, depth_max=0.0025))  # bad h
    monkeypatch.setattr(fem_first_use, "FirstUseBuild", functools.partial(FirstUseBuild, idle=False))

    async def scenario():
        async with NodeHarness(FemNode, params=_params(tmp_path)) as h:
            await _until(h, "first-use table build failed", 120.0)
            assert "ValueError" in h.node.state_message and "serving the LINEAR model" in h.node.state_message
            d = await _served(h, 1.0)
            assert d.valid and d.method == "condensed"

    with caplog.at_level("ERROR"):
        asyncio.run(scenario())
    assert any("first-use table build failed" in r.getMessage() and r.levelname == "ERROR"
               for r in caplog.records), [r.getMessage() for r in caplog.records]


def test_without_a_disk_cache_nothing_is_built_and_linear_serves(tmp_path):
    params = dict(_params(tmp_path), cache_dir="")

    async def scenario():
        async with NodeHarness(FemNode, params=params) as h:
            assert h.node._first_use is None
            assert "no disk cache to build one in" in h.node.state_message, h.node.state_message
            assert (await _served(h, 1.0)).method == "condensed"

    asyncio.run(scenario())
