"""An independent Foxglove client's view of the running simulated display (tests/system/test_viz_live.py):
connect to the viz bridge of a launch, subscribe, and collect what it shows. Used by the shared sim run
(tests/conftest.py ``sim_run``), which connects it while the graph runs."""

from __future__ import annotations

import asyncio
import math
import subprocess
import time
from pathlib import Path

import numpy as np

from flexsheet.viz.wsclient import FoxgloveClient

ROOT = Path(__file__).resolve().parents[1]
R = 0.025 * math.sqrt(2.0)                  # paper's cylinder radius, m (docs/scenes.md, BRIEF conventions)
HALF_LENGTH = 0.060                         # half its 0.120 m length, m
AXIS_X = -R                                 # axis along y through (-R, 0, 0)


def _radius(p: np.ndarray) -> np.ndarray:
    """Distance of points (N, 3) from the cylinder axis, m."""
    return np.hypot(p[:, 0] - AXIS_X, p[:, 2])


async def _connect(port: int, proc: subprocess.Popen, timeout: float) -> FoxgloveClient:
    deadline = time.monotonic() + timeout
    while True:
        try:
            return await FoxgloveClient.open(port)
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.5)


def _off_surface(position) -> float:
    """Distance of a point (3,) m from the cylinder's curved surface (radially), m."""
    return abs(float(_radius(np.asarray(position, dtype=float)[None])[0]) - R)


async def watch(port: int, proc: subprocess.Popen) -> tuple[dict, object, list[dict], dict]:
    """Connect, subscribe, and return (channels, a decoded SceneUpdate holding the FEM mesh, the valid
    /fingertip messages up to the first one within 3 mm of the surface: the finger on the object, the server's
    ``{"capabilities": [...], "times": [ns, ...]}``)."""
    c = await _connect(port, proc, timeout=90.0)
    try:
        await c.wait_channels({"/viz/scene", "/viz/tf", "/fingertip", "/camera/left"}, timeout=10.0)
        await c.subscribe(["/viz/scene", "/viz/tf", "/fingertip"])
        scene, tips = None, []
        deadline = time.monotonic() + 60.0
        while scene is None or not tips or _off_surface(tips[-1]["position"]) > 0.003:
            m = await c.recv(deadline)   # raises TimeoutError: the sim never produced them
            if m is None:
                continue
            topic, _, payload = m
            if topic == "/viz/scene" and scene is None:
                su = c.decode(topic, payload)
                ents = {e.id: e for e in su.entities}
                if "object" in ents and ents["object"].triangles:  # the FEM's mesh, not the fallback cylinder
                    scene = su
            elif topic == "/fingertip":
                msg = c.decode(topic, payload)
                if msg["valid"]:
                    tips.append(msg)
        return c.channels, scene, tips, {"capabilities": list((c.server_info or {}).get("capabilities", [])),
                                         "times": list(c.times)}
    finally:
        await c.ws.close()
