"""The graph builder (flexsheet.runtime.graph_builder): every shipped launch file builds; a source off its
clock, a required input nobody publishes and a shared value that disagrees are each refused with one line
naming the node, the field and the fix; ``flexsheet launch --check`` and the graph bench go through it; the
display's topic declarations match the node types' code."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import yaml
from test_topic_map import topic_table

from flexsheet.benches.graph import ARM_PATH, CONTROLLERS, RENDER_PATH, bench_graph
from flexsheet.display.graph_topics import NODE_TOPICS
from flexsheet.runtime.graph_builder import GraphBuilder, GraphRefused, NodeTopics
from flexsheet.runtime.launch import load_launch
from flexsheet.runtime.launch_check import check_launch

ROOT = Path(__file__).resolve().parents[3]
LAUNCH = ROOT / "launch"
SHIPPED = sorted(LAUNCH.glob("*.yaml"))


def _builder(name: str, drop: tuple[str, ...] = (), **sets: dict) -> GraphBuilder:
    """The builder of launch/NAME.yaml without the ``drop`` nodes, each ``sets[node]`` merged into its
    params."""
    lf = load_launch(LAUNCH / f"{name}.yaml")
    for n in drop:
        del lf.nodes[n]
    return GraphBuilder.from_launch(lf, lambda n: {**lf.nodes[n].params, **sets.get(n, {})})


def _refused(b: GraphBuilder) -> GraphRefused:
    with pytest.raises(GraphRefused) as info:
        b.build()
    return info.value


def test_the_shipped_launch_files_are_all_here():
    assert {p.stem for p in SHIPPED} >= {"sim", "lab", "lab_sim", "replay", "sim_composed"}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_every_shipped_launch_file_builds(path):
    lf = load_launch(path)
    graph = GraphBuilder.from_launch(lf).build()
    assert list(graph.nodes) == list(lf.nodes) and graph.clock == lf.clock


def test_the_replay_in_lockstep_builds_and_runs_its_nodes_on_a_simulated_clock():
    b = _builder("replay", player={"mode": "lockstep"})
    b.build()
    assert b.node_clock("planner") == "sim" and b.node_clock("recorder") == "sim"
    assert _builder("replay").node_clock("planner") == "wall"


# ------------------------------------------------------------------------------------------------ clock
def test_an_in_process_controller_twin_on_the_wall_clock_is_refused_naming_the_fix():
    err = _refused(_builder("sim_composed", arm_left={"source": "sim"}))
    assert len(err.lines) == 1 and [p.kind for p in err.problems] == ["clock"]
    line = err.lines[0]
    assert line.startswith("node arm_left: params.source = 'sim' does not run on clock wall: ")
    assert "clock: sim" in line and "source: tcp" in line     # the two fixes


def test_a_network_controller_on_the_simulated_clock_is_refused_naming_the_fix():
    err = _refused(_builder("sim", arm_right={"source": "tcp"}))
    assert len(err.lines) == 1
    assert err.lines[0].startswith("node arm_right: params.source = 'tcp' does not run on clock sim: ")
    assert "use source: sim" in err.lines[0]


def test_a_lockstep_player_puts_its_container_on_the_simulated_clock():
    def graph(mode: str) -> GraphBuilder:
        return (GraphBuilder(clock="wall")
                .add("player", "player", {"file": "x.mcap", "topics": ["/arm/left/target"], "mode": mode},
                     container="c")
                .add("arm", "arm_bridge", {"arm": "left", "source": "tcp"}, container="c"))
    graph("realtime").build()
    err = _refused(graph("lockstep"))
    assert len(err.lines) == 1 and err.lines[0].startswith("node arm: params.source = 'tcp' does not run on "
                                                           "clock sim")


# ------------------------------------------------------------------------------------------------ inputs
def test_an_input_nobody_publishes_is_refused_once_per_node_and_topic():
    err = _refused(_builder("sim", drop=("camera",)))
    assert [p.kind for p in err.problems] == ["input", "input"]
    by_topic = {line.split(": ")[1]: line for line in err.lines}
    assert set(by_topic) == {"input /camera/calibration", "input /camera/stereo"}
    for line in err.lines:
        assert line.startswith("node triangulator: input /camera/")
        assert "add a node of type camera" in line and "external: [/camera/" in line


def test_a_missing_planner_leaves_both_bridges_without_their_target():
    err = _refused(_builder("sim", drop=("planner",)))
    assert sorted(err.lines) == sorted(
        f"node arm_{s}: input /arm/{s}/target: no node of graph sim publishes it; add a node of type "
        f"planner, or declare it external (launch file: external: [/arm/{s}/target]) when a tool or another "
        f"launch file feeds it" for s in ("left", "right"))


def test_an_external_topic_needs_no_publisher_and_a_remap_is_followed():
    b = _builder("sim", drop=("camera",)).external("/camera/stereo", "/camera/calibration")
    b.build()
    lf = load_launch(LAUNCH / "sim.yaml")
    lf.nodes["triangulator"].remaps["/camera/stereo"] = "/camera2/stereo"
    err = _refused(GraphBuilder.from_launch(lf))
    assert len(err.lines) == 1 and err.lines[0].startswith("node triangulator: input /camera2/stereo: ")


def test_a_node_that_may_publish_anything_silences_the_input_check():
    """A player of every topic of its bag (no ``topics``) may feed any input."""
    base = GraphBuilder(clock="wall").add("fem", "fem", {})
    assert "node fem: input /fingertip" in str(_refused(base))
    base.add("player", "player", {"file": "x.mcap"})
    base.build()
    GraphBuilder(clock="wall").add("fem", "fem", {}).add(
        "src", cls=object, topics=NodeTopics(outputs=frozenset({"/fingertip"}))).build()


def test_a_node_type_that_cannot_be_imported_here_still_declares_its_topics(monkeypatch):
    """On an arm PC the main PC's renderer may not import (no GL): the inputs are still checked."""
    from flexsheet.runtime import graph_builder

    real = graph_builder.node_class

    def node_class(name: str) -> type:
        if name == "renderer":
            raise ImportError("no GL here")
        return real(name)
    monkeypatch.setattr(graph_builder, "node_class", node_class)
    err = _refused(_builder("sim", drop=("camera",)))
    assert sorted(p.kind for p in err.problems) == ["input", "input", "type"]
    types = [p.line for p in err.problems if p.kind == "type"]
    assert types == ["node renderer: type = 'renderer': no GL here; install it or fix the type"]


def test_optional_inputs_are_not_refused():
    """The planner and the FEM replayed from a bag's fingertips (no bridges, no camera, no head camera)."""
    (GraphBuilder(clock="wall")
     .add("player", "player", {"file": "x.mcap", "topics": ["/fingertip", "/camera/calibration"]})
     .add("planner", "planner", {}).add("fem", "fem", {})).build()


# ------------------------------------------------------------------------------------------------ shared
def test_a_planner_copy_that_differs_from_the_bridges_is_refused_naming_the_value_to_set():
    err = _refused(_builder("sim", planner={"arm_accel_scale": 4.0}))
    assert [p.kind for p in err.problems] == ["shared"]
    line = err.lines[0]
    assert line.startswith("node planner: params.arm_accel_scale = 4.0: the arm_bridge nodes' accel_scale is "
                           "6.0 (arm_left, arm_right; ")
    assert line.endswith("set planner.arm_accel_scale=6.0 or change their accel_scale")
    _builder("sim", planner={"arm_accel_scale": 3.0}, arm_left={"accel_scale": 3.0},
             arm_right={"accel_scale": 3.0}).build()


def test_bridges_that_disagree_with_each_other_are_refused():
    err = _refused(_builder("sim_composed", arm_right={"speed_scale": 0.25}))
    assert len(err.lines) == 1
    assert err.lines[0].startswith("node arm_right: params.speed_scale = 0.25: node arm_left has 0.5, ")
    assert err.lines[0].endswith("give every arm_bridge node one speed_scale")


# ------------------------------------------------------------------------------------------------ API
def test_bad_params_and_unknown_types_are_refused_and_duplicates_raise():
    err = _refused(GraphBuilder().add("a", "arm_bridge", {"source": "carrier_pigeon"}).add("x", "no_such"))
    assert [p.kind for p in err.problems] == ["params", "type"]
    assert err.lines[0].startswith("node a: params.source = 'carrier_pigeon': ")
    assert "unknown node type 'no_such'" in err.lines[1]
    with pytest.raises(ValueError, match="node a: added twice"):
        GraphBuilder().add("a", "fem").add("a", "fem")
    with pytest.raises(ValueError, match="clock = 'lunar'"):
        GraphBuilder(clock="lunar")


def test_launch_check_goes_through_the_builder():
    res = check_launch(LAUNCH / "sim_composed.yaml", overrides={"arm_left": {"source": "sim"}})
    hits = [e for e in res.errors if "node arm_left: params.source = 'sim' does not run on clock wall" in e]
    assert not res.ok and len(hits) == 1 and hits[0].startswith(str(LAUNCH / "sim_composed.yaml"))
    assert check_launch(LAUNCH / "sim_composed.yaml").ok


def test_a_launch_files_external_topics_need_no_publisher(tmp_path):
    path = tmp_path / "tri.yaml"
    text = "name: tri\nhosts: {{main: {{address: 127.0.0.1}}}}\nbase_port: 21300\n{ext}nodes:\n" \
           "  triangulator: {{type: triangulator, host: main}}\n"
    path.write_text(text.format(ext=""))
    assert [e.split(": ", 1)[1] for e in check_launch(path).errors] == [
        f"node triangulator: input {t}: no node of graph tri publishes it; add a node of type camera, or "
        f"declare it external (launch file: external: [{t}]) when a tool or another launch file feeds it"
        for t in ("/camera/calibration", "/camera/stereo")]
    path.write_text(text.format(ext="external: [/camera/stereo, /camera/calibration]\n"))
    assert check_launch(path).errors == []
    path.write_text(text.format(ext="external: [camera/stereo]\n"))
    assert "key 'external': 'camera/stereo' is not a topic (/name)" in check_launch(path).errors[0]


def test_the_graph_bench_builds_both_paths_on_the_wall_clock_with_network_controllers():
    arm, render = bench_graph(ARM_PATH), bench_graph(RENDER_PATH)
    assert arm.clock == "wall"
    assert {arm.nodes[n].params["source"] for n in ("arm_left", "arm_right")} == {"tcp"}
    # each bridge reaches its controller twin, which runs in a process of its own (benches.graph.controllers)
    assert [arm.nodes[n].params["port"] for n in ("arm_left", "arm_right")] == list(CONTROLLERS.values())
    assert list(arm.nodes) == ["player", *ARM_PATH, "sink"] and list(render.nodes) == ["player", *RENDER_PATH,
                                                                                          "sink"]
    assert len(arm.members()) == len(arm.nodes)


# ---------------------------------------------------------------------------------------------- declarations
def test_the_display_declarations_match_the_node_types_code():
    """Each node of launch/sim.yaml publishes what its type's code publishes (tests/test_topic_map.py reads it
    with ast), and each required input is one its code subscribes."""
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["flexsheet.nodes"]
    files = {k: ROOT / (v.split(":")[0].replace(".", "/") + ".py") for k, v in eps.items()}
    launch = yaml.safe_load((LAUNCH / "sim.yaml").read_text())
    pubs: dict[str, set[str]] = {}
    subs: dict[str, set[str]] = {}
    for row in topic_table(launch, files).splitlines()[2:]:
        topic, _, by, to = (c.strip().strip("`") for c in row.strip("|").split("|"))
        for n in by.split(", "):
            pubs.setdefault(n, set()).add(topic)
        for n in to.split(", "):
            subs.setdefault(n, set()).add(topic)
    checked = 0
    for name, node in launch["nodes"].items():
        if node["type"] not in NODE_TOPICS:
            continue
        declared = NODE_TOPICS[node["type"]](node.get("params") or {})
        assert declared.outputs == pubs.get(name, set()), name
        assert declared.required <= subs.get(name, set()), name
        checked += 1
    assert checked >= 10
