"""The viz bridge in the running simulated display, seen by an independent Foxglove client.

Launches the whole display, ``flexsheet launch launch/sim.yaml`` with only the viz port overridden
(``--set viz.port=PORT``, a free port), and connects :class:`flexsheet.viz.wsclient.FoxgloveClient` while it
runs — a client of the public Foxglove WebSocket protocol written on ``websockets`` + ``protobuf``, which
imports nothing of the foxglove-sdk. It checks the advertised channels and their schema names, decodes one
``foxglove.SceneUpdate`` from ``/viz/scene`` against the FileDescriptorSet the server advertised, and
judges the drawn object and the ``/fingertip`` JSON against the paper's scene (not against the bridge's
own code): cylinder radius R = 0.025·√2 m, length 0.120 m, axis along y through (−R, 0, 0).
"""

from __future__ import annotations

import base64

import numpy as np
from viz_watch import HALF_LENGTH, R, _off_surface, _radius


def test_independent_client_sees_the_running_sim(sim_run):
    """The client was connected while the shared sim run (tests/conftest.py ``sim_run``: launch/sim.yaml with
    ``--set viz.port=PORT``) ran, until it had the FEM's mesh and the finger on the object."""
    if isinstance(sim_run["viz"], BaseException):
        raise AssertionError(f"{sim_run['viz']!r}; launch output:\n{sim_run['stdout'][-5000:]}")
    channels, su, tips, server = sim_run["viz"]

    # the viewer's timeline follows simulated time: capability "time", times advancing with the graph's stamps
    assert "time" in server["capabilities"], server["capabilities"]
    times = [t * 1e-9 for t in server["times"]]
    assert len(times) >= 2 and times[-1] > times[0], times
    assert abs(times[-1] - tips[-1]["header"]["stamp"]) < 5.0, (times[-1], tips[-1]["header"]["stamp"])

    # advertised channels and their schema names (Foxglove's own schemas; our topics as JSON + jsonschema)
    names = {t: (ch["schemaName"], ch["encoding"]) for t, ch in channels.items()}
    assert names["/viz/scene"] == ("foxglove.SceneUpdate", "protobuf")
    assert names["/viz/tf"] == ("foxglove.FrameTransforms", "protobuf")
    assert names["/camera/left"] == names["/camera/right"] == ("foxglove.RawImage", "protobuf")
    assert names["/fingertip"] == ("flexsheet/Fingertip", "json")
    assert channels["/fingertip"]["schemaEncoding"] == "jsonschema"
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channels["/viz/scene"]["schema"]))
    assert "foxglove/SceneUpdate.proto" in {f.name for f in fds.file}   # decoded against what was advertised

    # the deformed object: the FEM's closed surface mesh of the paper's cylinder, in the display frame
    ents = {e.id: e for e in su.entities}
    assert {"object", "sheet", "fingertip", "projector", "eyes", "arm_left", "arm_right"} <= set(ents)
    obj = ents["object"]
    assert obj.frame_id == "display" and len(obj.triangles) == 1
    tri = obj.triangles[0]
    v = np.array([(p.x, p.y, p.z) for p in tri.points])
    idx = np.asarray(tri.indices)
    assert 200 <= len(v) <= 200_000, len(v)
    assert len(idx) % 3 == 0 and len(idx) >= len(v) and idx.max() < len(v) and idx.min() >= 0
    r = _radius(v)
    assert np.all(np.isfinite(v))
    assert (r.max() < R + 0.002 and np.all(np.abs(v[:, 1]) < HALF_LENGTH + 0.002)), (r.max(),
                                                                                     np.abs(v[:, 1]).max())
    side = np.abs(v[:, 1]) < HALF_LENGTH - 0.001   # away from the end caps: the curved surface, dented ≤ 2 cm
    assert side.sum() > 0.3 * len(v) and np.all(r[side] > R - 0.02), r[side].min()
    assert np.median(np.abs(r[side] - R)) < 0.001   # most of the surface is where the cylinder is
    assert tri.color.a > 0
    print(f"object: {len(v)} vertices, {len(idx) // 3} triangles, radius {r.min():.4f}..{r.max():.4f} m "
          f"(R = {R:.4f}), |y| <= {np.abs(v[:, 1]).max():.4f} m")

    # the measured fingertip (JSON, SI units, display frame) follows the
    # stroke: every valid one within a few cm of the cylinder's surface (the
    # finger approaches from ~3 cm), and it reaches the surface (within 3 mm)
    for tip in tips:
        p = np.asarray(tip["position"], dtype=float)
        assert p.shape == (3,) and tip["header"]["frame_id"] == "display"
        assert _off_surface(p) < 0.04 and abs(p[1]) < HALF_LENGTH + 0.04, p
    assert _off_surface(tips[-1]["position"]) <= 0.003
    print(f"{len(tips)} valid fingertips, from {1e3 * _off_surface(tips[0]['position']):.1f} mm to "
          f"{1e3 * _off_surface(tips[-1]['position']):.1f} mm off the cylinder surface")
