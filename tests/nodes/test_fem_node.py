"""FEM node through the real codec: deformation out, bad fingertips rejected, node keeps running."""

import asyncio

import numpy as np
import pytest

from messages import Fingertip, Header, topics
from nodes.fem.node import FemNode

PARAMS = {"mesh_h": 0.012, "mesh_h_fine": 0.006, "refine_radius": 0.012, "order": 1, "cache_dir": "",
          "nonlinear": False}


def _tip(pos, valid=True, stamp=1.0):
    p = np.asarray(pos, float)
    return Fingertip(header=Header(stamp=stamp), position=p, covariance=np.eye(3) * 1e-8, valid=valid,
                     predicted_position=p, exposure_stamp=stamp)


def test_node_deforms_and_rejects_bad_input():
    async def scenario():
        async with __import__("flexsheet.runtime.testing",
                              fromlist=["NodeHarness"]).NodeHarness(FemNode, params=PARAMS) as h:
            h.inject(topics.FINGERTIP, _tip([-0.005, 0.0, 0.0], stamp=12.5))
            out = await h.wait_for(topics.DEFORMATION, n=1, timeout=20.0)
            d = out[-1]
            assert d.valid and d.status == "ok"
            assert abs(d.depth - 0.005) < 1e-9
            assert d.contact_force > 0 and d.stiffness > 0
            assert d.source_stamp == 12.5
            assert d.vertices.dtype == np.float32 and d.vertices.shape[1] == 3
            assert d.faces.max() < len(d.vertices)
            # the vertex under the finger moved by about the depth along -x
            i = np.argmin(np.linalg.norm(d.vertices - np.array([-0.005, 0, 0], np.float32), axis=1))
            assert abs(d.vertices[i, 0] + 0.005) < 1e-3
            # out of object (beyond the end face) and on the support half: rejected, node alive
            h.inject(topics.FINGERTIP, _tip([-0.005, 0.2, 0.0]))
            await h.settle(0.3)
            h.inject(topics.FINGERTIP, _tip([-0.2, 0.0, 0.0]))
            await h.settle(0.3)
            assert h.rejected(topics.FINGERTIP) == 2
            h.inject_raw(topics.FINGERTIP, [b"garbage"])
            await h.settle(0.2)
            assert h.rejected(topics.FINGERTIP) == 3
            # NaN position (built without validation, as a faulty sender would): rejected, not published
            nan = Fingertip.model_construct(header=Header(stamp=2.0), position=np.array([np.nan, 0.0, 0.0]),
                                            covariance=np.eye(3), valid=True,
                                            predicted_position=np.array([np.nan, 0.0, 0.0]),
                                            prediction_horizon=0.0,
                                            exposure_stamp=2.0, reprojection_px=0.0)
            try:
                h.inject(topics.FINGERTIP, nan)
            except ValueError:
                pass            # the codec refuses to encode it: also fine
            else:
                await h.settle(0.3)
                assert h.rejected(topics.FINGERTIP) == 4
            assert len(h.messages(topics.DEFORMATION)) == 1
            # lost marker: rest shape, invalid
            h.inject(topics.FINGERTIP, _tip([0.0, 0.0, 0.0], valid=False))
            out = await h.wait_for(topics.DEFORMATION, n=2, timeout=5.0)
            assert not out[-1].valid and out[-1].status.startswith("rejected")
            # still running: a good input after the bad ones is answered
            h.inject(topics.FINGERTIP, _tip([0.01, 0.0, 0.0]))
            out = await h.wait_for(topics.DEFORMATION, n=3, timeout=5.0)
            assert out[-1].valid and out[-1].contact_force == 0.0 and out[-1].depth == 0.0

    asyncio.run(scenario())


def test_node_serves_cached_nonlinear_snapshots_and_says_so(tmp_path):
    """A snapshot table in the cache (under the node's key) is attached at start-up: pushes inside it are
    answered by the snapshots (method "snapshots"), the diagnostics message says so; a push outside the
    table's azimuth range falls back to the linear model."""
    from test_snapshots import _analytic_table

    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, table_key
    from flexsheet.model.scene_parts import GENT_JM_RUBBER

    tab = _analytic_table([0.0, 10.0], [0.0, 0.01, 0.02])
    # the bare node's law is the paper scene's (Gent); a table
    # under that key in cache_dir wins over the shipped one
    from flexsheet.model.scenes import DEFAULT_SCENE_FILE, load_scene

    law = load_scene(DEFAULT_SCENE_FILE).finger.contact         # the table is looked up under the scene's law
    key = table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, Material().nu, 0.008, law, GENT_JM_RUBBER)
    ArrayCache(str(tmp_path)).save("snapshots", key, tab)
    params = dict(PARAMS, cache_dir=str(tmp_path), model="snapshots")

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=params) as h:
            assert "snapshots loaded from cache" in h.node.state_message
            c, r = np.array([-0.025 * np.sqrt(2.0), 0.0, 0.0]), 0.025 * np.sqrt(2.0) - 0.010
            h.inject(topics.FINGERTIP, _tip(c + r * np.array([np.cos(0.5), 0.0, np.sin(0.5)]), stamp=4.0))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=20.0))[-1]
            assert d.method != "snapshots" and abs(d.depth - 0.010) < 1e-6   # 29 deg: outside the table
            h.inject(topics.FINGERTIP, _tip([0.0, 0.0, 0.0], valid=False))  # lift: forget the held contact
            await h.wait_for(topics.DEFORMATION, n=2, timeout=5.0)
            h.inject(topics.FINGERTIP, _tip([-0.010, 0.0, 0.0], stamp=3.0))
            d = (await h.wait_for(topics.DEFORMATION, n=3, timeout=20.0))[-1]
            assert d.method == "snapshots" and d.valid and d.status == "ok"
            assert abs(d.contact_force - 100.0 * 0.010) < 1e-6            # the table's force, E as tabulated

    asyncio.run(scenario())


def test_node_without_cached_snapshots_serves_linear_and_says_so(tmp_path):
    """The cylinder made neo-Hookean again (cylinder.yaml's comment): no table is shipped or cached for that
    law, so the node serves the linear model and says how to build the table."""
    from flexsheet.model.scenes import SCENES_DIR

    text = (SCENES_DIR / "cylinder.yaml").read_text()
    assert "{model: gent, E: 10000.0, nu: 0.45, Jm: 97.2}" in text
    scene = tmp_path / "cylinder_neo_hookean.yaml"
    scene.write_text(text.replace("{model: gent, E: 10000.0, nu: 0.45, Jm: 97.2}",
                                  "{model: neo_hookean, E: 10000.0, nu: 0.45}"))

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=dict(PARAMS, model="snapshots", scene=str(scene))) as h:
            assert ("LINEAR" in h.node.state_message
                    and "experiment fem --node-table --nu 0.45 --Jm inf" in h.node.state_message)
            h.inject(topics.FINGERTIP, _tip([-0.005, 0.0, 0.0]))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=20.0))[-1]
            assert d.method == "condensed" and d.valid

    asyncio.run(scenario())


def test_node_solves_the_scene_it_is_given_and_names_it():
    """``scene`` = the sphere: the node meshes and solves the sphere (not the cylinder), every message carries
    the sphere's key; without a scene the key is the paper's cylinder's; a bad scene file is a params
    error."""
    import pytest

    from flexsheet.model.scenes import SCENES_DIR, load_scene, paper_scene
    from nodes.fem.params import FemParams

    sphere = load_scene(SCENES_DIR / "sphere.yaml")
    c, R = sphere.center, sphere.object.radius

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=dict(PARAMS, scene=str(SCENES_DIR / "sphere.yaml"))) as h:
            assert "scene 'sphere'" in h.node.state_message
            # 6 mm into the sphere at 40 deg up its crown (a point the cylinder does not have: z = R sin 40°)
            n = np.array([np.cos(0.7), 0.0, np.sin(0.7)])
            h.inject(topics.FINGERTIP, _tip(c + (R - 0.006) * n, stamp=5.0))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=30.0))[-1]
            assert d.scene_key == sphere.key() and d.valid and d.contact_force > 0 and d.stiffness > 0
            assert abs(d.depth - 0.006) < 2e-4
            assert np.linalg.norm(d.contact_point - (c + R * n)) < 3e-4
            # the rendered surface is the sphere's: its held back half is at rest on the sphere; the front is
            # pushed in under the finger and bulges (ν = 0.45) by < 1 mm around it
            r = np.linalg.norm(d.vertices - c, axis=1)
            back = d.vertices[:, 0] < c[0] - 1e-3
            assert back.sum() > 50 and np.abs(r[back] - R).max() < 1e-6
            assert r.min() < R - 0.004 and r.max() < R + 0.001
            h.inject(topics.FINGERTIP, _tip(c, valid=False))       # lift: forget the held contact point
            await h.wait_for(topics.DEFORMATION, n=2, timeout=5.0)
            h.inject(topics.FINGERTIP, _tip(c - 0.9 * R * np.array([1.0, 0.0, 0.0])))
            await h.settle(0.3)
            assert h.rejected(topics.FINGERTIP) == 1              # on the held back half: refused, node alive

    asyncio.run(scenario())

    async def cylinder():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=PARAMS) as h:
            h.inject(topics.FINGERTIP, _tip([-0.005, 0.0, 0.0]))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=20.0))[-1]
            assert d.scene_key == paper_scene().key() and d.valid

    asyncio.run(cylinder())
    with pytest.raises(ValueError, match="scene"):
        FemParams(scene=str(SCENES_DIR / "no_such_scene.yaml"))


def test_node_on_the_default_scene_serves_the_shipped_nonlinear_snapshots():
    """launch/scenes/cylinder.yaml on a machine that never solved anything (no disk cache): the node attaches
    the Gent snapshot table shipped in flexsheet/fem/data and answers a push on the stroke (30 deg, 20 mm)
    with it: the table's force there, and the rendered surface moved about the push depth under the fingertip,
    nowhere more."""
    from flexsheet.fem.snapshots import DEFAULT_GRID
    from flexsheet.model.scenes import SCENES_DIR

    params = dict(PARAMS, scene=str(SCENES_DIR / "cylinder.yaml"), cache_dir="", arc_deg=60.0)

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=params) as h:
            assert "snapshots loaded from the shipped store" in h.node.state_message, h.node.state_message
            snap = h.node.model.snapshots
            assert np.degrees(snap.angle_max) == pytest.approx(60.0) and snap.depth_max == pytest.approx(0.05)
            c, R = np.array([-0.025 * np.sqrt(2.0), 0.0, 0.0]), 0.025 * np.sqrt(2.0)
            n = np.array([np.cos(np.pi / 6), 0.0, np.sin(np.pi / 6)])
            h.inject(topics.FINGERTIP, _tip(c + (R - 0.020) * n, stamp=2.0))      # the fingertip, 20 mm in
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=20.0))[-1]
            assert d.method == "snapshots" and d.valid and abs(d.depth - 0.020) < 1e-6
            ia = list(DEFAULT_GRID.angles_deg).index(30.0)
            jd = int(np.argmin(np.abs(DEFAULT_GRID.depths() - 0.020)))
            hertz = (4.0 / 3.0 * 1e4 / (1 - 0.45 ** 2) * np.sqrt(np.sqrt(0.008 / (1 + 0.008 / R) * 0.008))
                     * 0.020 ** 1.5)
            assert abs(d.contact_force - snap.force[ia, jd]) < 1e-6      # the table's force, E as tabulated
            # Hertz's order (Johnson §4.2)
            assert 0.5 * hertz < d.contact_force < 1.5 * hertz, (d.contact_force, hertz)
            # the material under the fingertip went in with it; nothing else moved farther
            u = np.linalg.norm(np.asarray(d.vertices, float) - h.node.model._rest.astype(float), axis=1)
            assert 0.8 * 0.020 < u.max() < 1.3 * 0.020, u.max()

    asyncio.run(scenario())


def test_node_on_the_sphere_serves_its_nonlinear_table_when_cached(tmp_path):
    """A sphere table under the key the node looks up (here the closed-form dent of
    tests/unit/fem/test_sphere_snapshots.py, 0-60° every 10°, 0-10 mm): the node on sphere.yaml attaches it,
    says so, and answers a push at 35° up the crown with it — the force is the table's bilinear value at the
    measured depth, the vertex under the finger moved by about the depth; a push beyond the table's 60° is the
    linear model's."""
    from test_sphere_snapshots import _table

    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.sphere_snapshots import SphereGrid, sphere_frame, sphere_table_key
    from flexsheet.model.scenes import SCENES_DIR, load_scene

    sc = load_scene(SCENES_DIR / "sphere.yaml")
    fr = sphere_frame(sc)
    ArrayCache(str(tmp_path)).save("spheresnap", sphere_table_key(sc), _table(fr, SphereGrid(depth_max=0.01,
                                                                                               depth_step=0.005)))
    params = dict(PARAMS, scene=str(SCENES_DIR / "sphere.yaml"), cache_dir=str(tmp_path))

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=params) as h:
            assert (
                "nonlinear sphere snapshots loaded from cache" in h.node.state_message), h.node.state_message
            n = fr.direction(np.radians(35.0))
            h.inject(topics.FINGERTIP, _tip(fr.center + (fr.radius - 0.006) * n, stamp=5.0))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=30.0))[-1]
            assert d.valid and abs(d.depth - 0.006) < 3e-4
            # the table's force at the radial push through the fingertip (35°, 6 mm; table E = the scene's E)
            alpha, wd = np.radians(35.0), (0.006 - 0.005) / 0.005
            force = (1 + alpha) * ((1 - wd) * 0.005 ** 1.5 + wd * 0.01 ** 1.5)
            assert d.contact_force == pytest.approx(force, rel=1e-6)
            i = int(np.argmin(np.linalg.norm(d.vertices - (fr.center + fr.radius * n), axis=1)))
            assert abs(np.linalg.norm(d.vertices[i] - fr.center) - (fr.radius - d.depth)) < 1.5e-3
            h.inject(topics.FINGERTIP, _tip(fr.center, valid=False))             # lift
            await h.wait_for(topics.DEFORMATION, n=2, timeout=5.0)
            n70 = fr.direction(np.radians(70.0))
            h.inject(topics.FINGERTIP, _tip(fr.center + (fr.radius - 0.006) * n70, stamp=6.0))
            d70 = (await h.wait_for(topics.DEFORMATION, n=3, timeout=30.0))[-1]
            assert d70.valid and d70.contact_force > 0 and d70.contact_force != pytest.approx(
                (1 + np.radians(60.0)) * 0.006 ** 1.5, rel=0.2)

    asyncio.run(scenario())


def test_node_on_a_scene_without_symmetry_serves_its_path_table_when_cached(tmp_path):
    """A path table (flexsheet/fem/path_snapshots.py, here a closed-form one) under the key the node looks up
    for a scene no sphere table applies to (the sphere with a sticking finger and a 4° stroke): the node
    attaches it, says so, and its answer on the stroke is the model's table answer (linear solve + correction,
    force scaled by the table's ratio), not the linear one."""
    import yaml
    from test_path_snapshots import _table
    from unit.conftest import _scene

    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.mesh import MeshSpec
    from flexsheet.fem.path_snapshots import path_table_key
    from flexsheet.fem.scene_model import SceneModel

    sc = _scene()
    path = tmp_path / "sticky_sphere.yaml"
    path.write_text(yaml.safe_dump(sc.model_dump(mode="json")))
    m = SceneModel(sc, MeshSpec(0.012, 0.006, 0.012), order=1, cache_dir=str(tmp_path))
    ArrayCache(str(tmp_path)).save("pathsnap", path_table_key(m.scene_key, m.cache_key), _table(m))
    q, n = sc.stroke_at([0.6])
    tip = q[0] - 0.003 * n[0]
    linear = m.update(tip)
    m.reset()
    m.attach_path_table(_table(m))
    served = m.update(tip)
    assert served.method == "path_snapshots" and linear.method == "condensed"
    assert served.force > 1.1 * linear.force
    params = dict(PARAMS, scene=str(path), cache_dir=str(tmp_path))

    async def scenario():
        from flexsheet.runtime.testing import NodeHarness

        async with NodeHarness(FemNode, params=params) as h:
            assert "nonlinear path table loaded from cache: 3 stations" in h.node.state_message, \
                h.node.state_message
            h.inject(topics.FINGERTIP, _tip(tip, stamp=5.0))
            d = (await h.wait_for(topics.DEFORMATION, n=1, timeout=30.0))[-1]
            assert d.valid and abs(d.depth - served.depth) < 1e-9
            assert d.contact_force == pytest.approx(served.force, rel=1e-9)
            assert np.abs(np.asarray(d.vertices) - served.vertices).max() < 1e-7

    asyncio.run(scenario())


def test_removed_params_are_refused_naming_the_scene_field():
    """E, nu and finger_radius are the scene file's: a launch file that still sets one gets an error naming
    the param, its value and the scene file's field that holds it now."""
    import re

    from nodes.fem.params import FemParams

    for name, value, field in (("E", 5000.0, "material: E"), ("nu", 0.4, "material: nu"),
                               ("finger_radius", 0.01, "finger: radius")):
        with pytest.raises(ValueError, match=re.escape(f"fem param {name!r} (= {value!r}) was "
                                                       "removed")) as exc:
            FemParams(**{name: value, "arc_deg": 60.0})
        assert f"set {field!r} in the scene file" in str(exc.value)
    assert FemParams(arc_deg=60.0).fem_config().arc_deg == 60.0
