"""The topic map of docs/architecture.md is generated: every topic of ``messages/topics.py`` with the nodes of
``launch/sim.yaml`` that publish and subscribe it, read with ``ast`` from each node type's module (its
``self.publisher(...)`` and ``self.subscribe(...)`` calls; the arm topics by the node's ``arm`` param), from
its port's source (the module of the entry point its ``source`` param names: its ``subscribe`` calls and its
``inputs``) and from the recorder's ``topics`` param. The Foxglove bridge (``viz``) subscribes to what a
viewer opens, so it is not listed.

On a mismatch, the test prints the table to paste between the doc's ``topics:begin``/``topics:end`` markers.
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import yaml

from messages import topics as T

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / "launch" / "sim.yaml"
DOC = ROOT / "docs" / "architecture.md"
BEGIN, END = "<!-- topics:begin -->", "<!-- topics:end -->"
#: node types whose topics come from the launch file or from a viewer, not from their code
DYNAMIC = {"recorder", "player", "viz"}
ARMS = ("left", "right")
#: node type -> the entry-point group of its port's sources (its ``source`` param, default ``sim``, names one)
PORTS = {"camera": "flexsheet.camera_sources", "head_camera": "flexsheet.head_camera_sources"}


def _entry_files(group: str) -> dict[str, Path]:
    """entry name -> the file of its module (the ``group`` entry points of pyproject.toml)."""
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"][group]
    return {k: ROOT / (v.split(":")[0].replace(".", "/") + ".py") for k, v in eps.items()}


def _type_files() -> dict[str, Path]:
    """node type -> the file of its class (the ``flexsheet.nodes`` entry points)."""
    return _entry_files("flexsheet.nodes")


def _topic_of(arg: ast.expr, arm: str | None) -> list[str]:
    """The topic names an endpoint call's first argument names: ``T.NAME``, ``topics.arm_state(p.arm)`` (this
    node's arm), ``…(other)`` (the other arm), ``…(side)`` (both)."""
    if isinstance(arg, ast.Attribute) and isinstance(getattr(T, arg.attr, None), T.Topic):
        return [getattr(T, arg.attr).name]
    if isinstance(arg, ast.Call) and isinstance(arg.func, ast.Attribute) and arg.func.attr in ("arm_state",
                                                                                                 "arm_target"):
        make = getattr(T, arg.func.attr)
        a = arg.args[0]
        if isinstance(a, ast.Attribute) and a.attr == "arm" and arm:
            sides = [arm]
        elif isinstance(a, ast.Name) and a.id == "other" and arm:
            sides = [s for s in ARMS if s != arm]
        else:
            sides = list(ARMS)
        return [make(s).name for s in sides]
    return []


def _endpoints(source: str, arm: str | None) -> tuple[set[str], set[str]]:
    """(published, subscribed) topic names of a node module's source."""
    pub: set[str] = set()
    sub: set[str] = set()
    for n in ast.walk(ast.parse(source)):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.args:
            if n.func.attr == "publisher":
                pub.update(_topic_of(n.args[0], arm))
            elif n.func.attr in ("subscribe", "sample"):     # a sampled topic is subscribed too
                sub.update(_topic_of(n.args[0], arm))
        elif (
            isinstance(n, ast.Assign)
            and [getattr(t, "id", "") for t in n.targets] == ["inputs"]
            and isinstance(n.value, ast.Tuple)
        ):  # a port source's inputs: its node subscribes them
            for e in n.value.elts:
                sub.update(_topic_of(e, arm))
    return pub, sub


def topic_table(launch: dict, files: dict[str, Path]) -> str:
    """The markdown table: topic, message type, publishers, subscribers (launch node names, sorted)."""
    pubs: dict[str, set[str]] = {t.name: set() for t in T.ALL}
    subs: dict[str, set[str]] = {t.name: set() for t in T.ALL}
    for name, node in launch["nodes"].items():
        params = node.get("params") or {}
        if node["type"] == "recorder":
            for t in params.get("topics", ()):
                subs.setdefault(t, set()).add(name)
        if node["type"] in DYNAMIC:
            continue
        pub, sub = _endpoints(files[node["type"]].read_text(), params.get("arm"))
        if node["type"] in PORTS:
            port_pub, port_sub = _endpoints(
                _entry_files(PORTS[node["type"]])[params.get("source", "sim")].read_text(),
                                            params.get("arm"))
            pub, sub = pub | port_pub, sub | port_sub
        for t in pub:
            pubs[t].add(name)
        for t in sub:
            subs[t].add(name)
    rows = ["| topic | message | published by | subscribed by |", "|---|---|---|---|"]
    for t in T.ALL:
        by = "every node" if t is T.DIAGNOSTICS else ", ".join(sorted(pubs[t.name])) or "—"
        rows.append(f"| `{t.name}` | `{t.type.__name__}`{' (latched)' if t.latched else ''} | {by} | "
                    f"{', '.join(sorted(subs[t.name])) or '—'} |")
    return "\n".join(rows)


def _doc_table(text: str) -> str:
    m = re.search(re.escape(BEGIN) + r"\n(.*?)\n" + re.escape(END), text, re.S)
    assert m, f"docs/architecture.md has no {BEGIN} … {END} block"
    return m.group(1).strip()


def test_the_topic_map_in_the_architecture_doc_is_the_generated_one():
    want = topic_table(yaml.safe_load(LAUNCH.read_text()), _type_files())
    assert _doc_table(DOC.read_text()) == want, "docs/architecture.md's topic map is stale; paste:\n" + want


def test_the_generator_reads_endpoints_and_sees_a_planted_one():
    """The planner publishes /sheet/target and the right bridge its own joint state and subscribes to the
    left's; a planted publisher in a fake node type shows up."""
    files = _type_files()
    pub, sub = _endpoints(files["arm_bridge"].read_text(), "right")
    assert "/arm/right/joint_state" in pub and "/arm/left/joint_state" in sub and "/arm/right/target" in sub
    assert "/sheet/target" in _endpoints(files["planner"].read_text(), None)[0]
    got = _endpoints("class N:\n    def f(self):\n        self.publisher(T.EYE_POSE)\n"
                     "        self.subscribe(topics.arm_state(side), h)\n", None)
    assert got == ({"/eye/pose"}, {"/arm/left/joint_state", "/arm/right/joint_state"})
