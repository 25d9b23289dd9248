"""The live view as the viewers' own code sees it: the official ``@foxglove/ws-protocol`` client (what
Lichtblick uses), offering one subprotocol name at a time, decodes every advertised channel with
``@mcap/support``'s channel parser (tests/js/foxglove_client.mjs; its packages come from
tests/js/package.json, installed by docker/install.sh)."""

from __future__ import annotations

import asyncio
import json
import shutil
import time
from pathlib import Path

import pytest
from conftest import free_port

from flexsheet.runtime.testing import NodeHarness
from flexsheet.viz.samples import sample_state
from flexsheet.viz.ws_relay import SUBPROTOCOLS
from messages import topics as T
from nodes.viz.node import VizNode

JS = Path(__file__).resolve().parents[1] / "js"


def _node() -> str:
    node = shutil.which("node")
    assert node, "node (Node.js) is not installed: run docker/install.sh"
    assert (JS / "node_modules" / "@foxglove" / "ws-protocol").is_dir(), \
        "tests/js/node_modules is missing: run docker/install.sh (npm ci in tests/js)"
    return node


@pytest.mark.parametrize("subprotocol", SUBPROTOCOLS)
def test_the_official_client_connects_with_either_subprotocol_and_decodes_every_channel(subprotocol):
    node = _node()
    port = free_port()

    async def scenario() -> tuple[dict, int]:
        async with NodeHarness(VizNode, params={"port": port, "scene_rate": 20.0, "camera_scale": 0.25}) as h:
            proc = await asyncio.create_subprocess_exec(node, str(JS / "foxglove_client.mjs"), str(port),
                                                        subprotocol, "20", cwd=str(JS),
                                                        stdout=asyncio.subprocess.PIPE,
                                                        stderr=asyncio.subprocess.PIPE)
            comm = asyncio.ensure_future(proc.communicate())
            while not comm.done():                     # the graph's state keeps arriving while it listens
                for name, msg in sample_state(stamp=time.time()).items():
                    h.inject(T.STEREO_PREVIEW if name == T.STEREO.name else T.BY_NAME[name], msg)
                await asyncio.wait([comm], timeout=0.1)
            out, err = comm.result()
            assert proc.returncode == 0, err.decode()[-2000:]
            return json.loads(out.decode().strip().splitlines()[-1]), h.rejected()

    res, rejected = asyncio.run(scenario())
    assert res["subprotocol"] == subprotocol, res
    rows = res["channels"]
    assert len(rows) >= 12, sorted(rows)               # every channel the view advertises
    undecoded = {t: r for t, r in rows.items() if r["decoded"] < 1 or r["error"]}
    assert undecoded == {}, undecoded
    assert rejected == 0
    # the timeline follows the graph's clock (here the wall clock): capability "time" and its times advancing
    assert "time" in res["capabilities"], res["capabilities"]
    t = res["time"]
    assert t["count"] >= 2 and int(t["last"]) > int(t["first"]), t
    assert abs(int(t["last"]) * 1e-9 - time.time()) < 30.0, t
