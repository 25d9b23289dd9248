"""Shared fixtures: free TCP ports, demo launch files, process helpers."""

from __future__ import annotations

import logging
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))          # the shared helpers (netns_util, viz_watch) for every folder
for _folder in sorted((ROOT / "tests").glob("**/")):   # a test module may import another's helpers by name
    if _folder.name not in ("data",
                            "__pycache__") and "data" not in _folder.relative_to(ROOT / "tests").parts:
        sys.path.append(str(_folder))

from flexsheet.runtime.domain import domain_id, shift_port  # noqa: E402
from flexsheet.runtime.ports import free_port  # noqa: E402  (tests import it from here; ports below the ephemeral range)

#: phase 2 runs on two pytest-xdist workers (tests/run.sh sets FLEXSHEET_TEST_DOMAINS):
#: each worker's graphs run in a domain of their own (flexsheet/runtime/domain.py), 1 +
#: the worker's number, so two launches of one file never share a port, and their tools
#: discover only their own graph (tests/system/test_domains.py uses 3-5)
if os.environ.get("FLEXSHEET_TEST_DOMAINS") and os.environ.get("PYTEST_XDIST_WORKER", "").startswith("gw"):
    os.environ["FLEXSHEET_DOMAIN_ID"] = str(1 + int(os.environ["PYTEST_XDIST_WORKER"][2:]))

#: the fewest valid fingertips (or planner targets while touching, or world finger samples) per second of a
#: launched stroke: 5 Hz, a sixth of the camera's 30 fps. Not a speed test (flexsheet bench is):
#: enough samples for a mean Δθ and for binning along the stroke. A quiet 2-core machine gives 25-30
#: Hz; a loaded CI run gave 19 Hz on the shared sim run's 10 s stroke (193) and 21 Hz of /world/finger
#: (207, from a 200 Hz timer) on the sphere's, with the suite's other phase-2 work beside it.
MIN_TIPS_HZ = 5.0


def private_ports(src: Path, dst: Path, offset: int | None = None, split_containers: bool = False) -> Path:
    """Write ``src`` (a launch file) to ``dst`` with its ports moved by ``offset`` (default from this process
    id), so that this run cannot collide with another sim run on the same machine: its ZeroMQ ports from
    ``base_port`` and the controller twins' and bridges' ``port`` params. The ports stay below 32768, the
    ephemeral range, where a restarted node's port can be taken by a reconnect's TCP self-connect
    (:mod:`flexsheet.runtime.ports`). ``split_containers``: every node its own process (no composable
    containers). Returns ``dst``."""
    import yaml

    offset = 100 * (1 + os.getpid() % 120) if offset is None else offset
    lf = yaml.safe_load(src.read_text())
    lf["base_port"] = 20000 + offset
    for spec in lf["nodes"].values():
        if split_containers:
            spec.pop("container", None)
        if spec.get("type") in ("arm_controller_sim", "arm_bridge") and "port" in spec.get("params", {}):
            spec["params"]["port"] = spec["params"]["port"] + offset
    dst.write_text(yaml.safe_dump(lf, sort_keys=False))
    return dst


@pytest.fixture
def demo_launch(tmp_path: Path):
    """Write a talker/listener(/recorder) launch file on free ports; returns a factory(extra_nodes_yaml)."""

    def make(extra: str = "", listener_qos: str = "keep_all", rate: float = 20.0) -> Path:
        base = free_port(span=10)
        text = f"""
name: demo
hosts:
  main: {{address: 127.0.0.1}}
base_port: {base}
shutdown_timeout: 2.0
nodes:
  talker: {{type: talker, host: main, params: {{rate: {rate}}}, respawn: {{policy: on-failure, delay: 0.2}}}}
  listener: {{type: listener, host: main, params: {{qos: {listener_qos}}}}}
{extra}"""
        path = tmp_path / "demo.yaml"
        path.write_text(text)
        return path

    return make


def pid_alive(pid: int) -> bool:
    """True if /proc/<pid> exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.split(")")[-1].split()[0] != "Z"


os.environ.setdefault("FLEXSHEET_LOG", "INFO")


@pytest.fixture(autouse=True)
def _library_loggers_restored():
    """A command's ``main`` run in-process shows its library's lines
    (``flexsheet.runtime.console.show_lines``: its own handler, ``propagate`` off); put the library's loggers
    back after each test, so a later test's ``caplog`` on the same worker still hears them."""
    saved = [(lg, lg.handlers[:], lg.propagate, lg.level)
             for lg in (logging.getLogger("flexsheet"), logging.getLogger("flexsheet.console"))]
    yield
    for lg, handlers, propagate, level in saved:
        lg.handlers[:] = handlers
        lg.propagate = propagate
        lg.setLevel(level)


@pytest.fixture
def netns():
    """Namespaces <prefix>-{main,arm1,arm2} on a bridge inside a 4th 'switch' namespace
    (:func:`netns_util.three_hosts`); fails with the reason if they cannot be made (needs root, iproute2)."""
    from netns_util import three_hosts

    try:
        with three_hosts() as names:
            yield names
    except RuntimeError as exc:
        pytest.fail(str(exc))


def warm_sim_fem(launch_file: Path = ROOT / "launch" / "sim.yaml") -> bool:
    """Precompute (or load) the FEM node's model of ``launch_file``'s ``fem`` params and scene (none: the
    default scene, the paper's cylinder) in the node's default disk cache, in this process; True on a cache
    hit.

    On a machine that never ran the display the FEM node precomputes it at start-up (~10 s alone on the 2-core
    machine, over 60 s inside a running graph that starves it), so a launch's FEM would not be up for the
    first part of the run. It is built as the node builds it (:func:`flexsheet.fem.served.build_model`), so
    the launched node hits the same cache key."""
    import yaml

    from flexsheet.fem.served import build_model
    from flexsheet.model.scenes import DEFAULT_SCENE_FILE, load_scene
    from nodes.fem.params import FemParams

    spec = yaml.safe_load(launch_file.read_text())
    p = FemParams(**spec["nodes"]["fem"].get("params", {}))
    scene = spec.get("scene") or p.scene or DEFAULT_SCENE_FILE
    m, _ = build_model(load_scene(scene), p.fem_config())
    return m.cache_hit


@pytest.fixture(scope="session")
def sim_fem_cache() -> bool:
    """Once per session: the FEM node's model for launch/sim.yaml (and lab_sim.yaml, same params) in the disk
    cache before a test launches the graph (:func:`warm_sim_fem`); True when it was cached already."""
    return warm_sim_fem()


@pytest.fixture(scope="session")
def lab_run(tmp_path_factory, sim_fem_cache):
    """launch/lab_sim.yaml on three network namespaces, once per session (:func:`netns_util.run_lab`: the
    three-host loop, a 2 s cable cut to arm1, arm2 going away); fails with the reason if the namespaces cannot
    be made (needs root, iproute2). Returns run_lab's dict with ``out``, main's ``--out`` folder."""
    from netns_util import run_lab

    out = tmp_path_factory.mktemp("lab")
    try:
        r = run_lab(out)
    except RuntimeError as exc:
        pytest.fail(str(exc))
    r["out"] = out
    return r


#: the shared sim run's script: the paper's 10 s stroke (Table I) and a 4 s stroke with a 10 mm push
SIM_SCRIPT = ("world.script=[{mode: stroke, moving_time: 10}, {mode: stroke_push, moving_time: 4, "
              "push_depth: 0.01}]")


#: a launcher's line for a node or container killed by a signal: shown first in a graph fixture's failure (a
#: crash fails the test; nothing is run again)
KILLED = re.compile(r"^\s*\[\s*(\S+?)\s*\] exited with code -(\d+)\s*$", re.M)


@pytest.fixture(scope="session")
def sim_run(tmp_path_factory, sim_fem_cache):
    """One launch of launch/sim.yaml (:data:`SIM_SCRIPT`, ``--set viz.port=PORT``: a free port), read by
    tests/system/test_integration_sim.py (Table I, latency budget, outputs; the replay of its bag) and
    tests/system/test_viz_live.py (an independent Foxglove client connected while it runs, until it has seen
    the FEM's mesh and the finger on the object: :func:`viz_watch.watch`). One launch instead of two (~11 s).

    Returns ``out`` (the launch's ``--out``), ``stdout`` (its output, stderr merged), ``code`` (exit code, or
    "timeout" after 240 s) and ``viz`` (watch's (channels, SceneUpdate, fingertips) or the exception it
    raised). A launch whose container was killed by a signal (:data:`KILLED`) fails its tests, the kill's line
    first."""
    import asyncio
    import signal
    import subprocess

    from viz_watch import watch

    out = tmp_path_factory.mktemp("sim")
    log = out.parent / f"{out.name}_launch.log"
    port = free_port()
    with open(log, "w") as f:
        proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--out",
                                 str(out),
                                 "--set", SIM_SCRIPT, "--set", f"viz.port={port}"],
                                cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        try:
            viz = asyncio.run(watch(shift_port(port, domain_id()), proc))  # the launch moves it to its domain
        except (TimeoutError, OSError) as exc:
            viz = exc
        try:
            code = proc.wait(timeout=240)
        except subprocess.TimeoutExpired:
            code = "timeout"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)          # Ctrl-C: the launch stops its nodes
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    return {"out": out, "stdout": log.read_text(), "code": code, "viz": viz}


#: The folder decides the CI phase (tests/run.sh): ``tests/unit/`` (and tests/test_layout.py) hold pure
#: computation — no node, process, socket, window or tight time bound — run first on two pytest-xdist workers
#: (marker ``cpu``); ``tests/nodes/`` (the node harness) and ``tests/system/``
#: (launched graphs) run after, one by one, with the machine to themselves,
#: because a test that judges a live loop against the clock needs it.
SERIAL_FOLDERS = ("nodes", "system")


def is_cpu_test(path: Path) -> bool:
    """True for a test module of phase 1: under tests/ but not under tests/nodes/ or tests/system/."""
    rel = Path(path).resolve().relative_to(ROOT / "tests")
    return rel.parts[0] not in SERIAL_FOLDERS


def pytest_configure(config):
    config.addinivalue_line("markers", "cpu: pure computation, safe to run beside another test "
                                       "(tests/run.sh)")
    config.addinivalue_line("markers", "serial: starts nodes or a graph although its module is in a phase-1 "
                                       "folder: phase 2 (tests/run.sh)")
    config.addinivalue_line("markers", "slow: end-to-end work of over a minute a test: the slow tier, "
                                       "tests/run.sh --slow (CI runs both tiers)")
    config.addinivalue_line("markers", "alone: judges a live loop against the wall clock, needs the machine "
                                       "to itself: phase 3, one by one (tests/run.sh)")


def group(path: Path) -> str:
    """A test module's xdist group: its path under tests/ without ``.py`` (``unit/twin/test_registration``),
    unique where stems are not (``unit/model/test_scenes`` and ``unit/experiments/test_scenes``)."""
    return Path(path).resolve().relative_to(ROOT / "tests").with_suffix("").as_posix()


#: modules that run in another's group, on one xdist worker after it: unit/twin/test_registration registers
#: the twin's three seeds and shares them with the cache that unit/experiments/test_correction loads (on two
#: workers it would redo them); the calibration estimators' modules share one package fixture (the twin's
#: board views and the camera pose from them, tests/unit/calibration/conftest.py), built once on one
#: worker; so do the FEM's: the coarse cylinder's models (tests/unit/fem/conftest.py), the quarter
#: reference model (tests/unit/fem/reference/conftest.py), the sphere's path-table model
#: (tests/unit/conftest.py) and the quick FEM run of the slow tier (tests/unit/experiments/fem/conftest.py)
SAME_WORKER = {"unit/experiments/test_correction": "unit/twin/test_registration",
               "unit/calibration/test_arms": "unit/calibration/test_camera_pose",
               "unit/calibration/test_projector": "unit/calibration/test_camera_pose",
               "unit/calibration/test_sources": "unit/calibration/test_camera_pose",
               "unit/fem/test_mesh": "unit/fem/test_solver",
               "unit/fem/test_realtime": "unit/fem/test_solver",
               "unit/fem/test_corotational": "unit/fem/test_solver",
               "unit/fem/reference/test_projected_tangent": "unit/fem/reference/test_hyperelastic",
               "unit/fem/reference/test_path_solver": "unit/fem/reference/test_hyperelastic",
               "unit/fem/reference/test_newton": "unit/fem/reference/test_hyperelastic",
               "unit/fem/test_scene_model": "unit/fem/test_path_snapshots",
               "unit/fem/reference/test_path_table": "unit/fem/test_path_snapshots",
               "unit/experiments/fem/test_outputs": "unit/experiments/fem/test_runs",
               "unit/experiments/fem/test_candidates": "unit/experiments/fem/test_runs",
               "unit/experiments/fem/studies/test_convergence": "unit/experiments/fem/test_runs",
               "unit/experiments/fem/studies/test_mirror": "unit/experiments/fem/test_runs",
               "unit/experiments/fem/studies/test_fold": "unit/experiments/fem/test_runs",
               "unit/experiments/fem/studies/test_material": "unit/experiments/fem/test_runs"}


#: the longest groups of phase 1, longest first (every-day tier: the twin's registrations and
#: correction 85 s and the docs' commands 37 s cold; the hyperelastic reference's modules 63 s,
#: the scenes' FEM experiment 25 s and the reference's meshes 15 s warm, beside another worker;
#: the slow tier's quick FEM run ~270 s), collected first so they start at once on the two workers
#: and the short modules fill in the tail (alphabetically a long one started last and ran alone)
LONGEST_FIRST = ("unit/experiments/fem/test_runs", "unit/twin/test_registration",
                 "unit/fem/reference/test_hyperelastic", "test_docs_run", "unit/experiments/test_fem_scene",
                 "unit/fem/reference/test_mesh")


#: phase 2: modules that share a session fixture run in one group (the shared sim run, ``sim_run``)
SAME_WORKER_2 = {"system/test_viz_live": "system/test_integration_sim"}

#: the modules of phase 3 (marker ``alone``): they judge a live loop against the wall clock (rates, jitter,
#: deadlines) and need the machine to themselves, or they set up network namespaces and lab hosts of fixed
#: names and addresses (the three hosts, the partition, the live registration) that two at once would share
ALONE = ("nodes/test_controller_strict", "nodes/test_arm_mxt", "nodes/test_mxt", "system/test_arm_mxt_sim",
         "system/test_load", "system/test_links_heal", "system/test_partition", "system/test_churn",
         "nodes/test_render_node", "nodes/test_camera_genicam", "nodes/test_twin_world",
         "system/test_faults_experiment", "system/test_simclock", "system/test_integration_netns",
         "system/test_live_registration", "system/test_faults", "system/test_experiments_quick")


@pytest.hookimpl(tryfirst=True)       # before pytest-xdist's own hook reads the xdist_group marks
def pytest_collection_modifyitems(config, items):
    for item in items:
        name = group(item.path)
        if is_cpu_test(item.path) and not item.get_closest_marker("serial"):
            item.add_marker(pytest.mark.cpu)
            # tests/run.sh distributes by group (--dist loadgroup): a module per worker, module fixtures once
            item.add_marker(pytest.mark.xdist_group(SAME_WORKER.get(name, name)))
        elif name in ALONE:
            item.add_marker(pytest.mark.alone)
        else:                 # phase 2: a module per worker too, each worker in its own domain
            item.add_marker(pytest.mark.xdist_group(SAME_WORKER_2.get(name, name)))
    rank = {g: i for i, g in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda it: rank.get(SAME_WORKER.get(group(it.path), group(it.path)), len(rank)))   # stable
