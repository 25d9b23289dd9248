"""Local graph discovery: how the run-time tools find the nodes running on this machine without a launch file.

Every node with a TCP endpoint announces itself while it runs: one small JSON file per node, ``NAME-PID.json``
(``{"node", "endpoint", "pid", "curve", "domain"}``), in :func:`graph_dir` (``$FLEXSHEET_GRAPH_DIR``, else
``$XDG_RUNTIME_DIR/flexsheet/graph``, else ``/tmp/flexsheet-graph-UID``), removed when it stops. An entry
whose process is gone is stale and dropped. This plays the part of ROS 2's discovery on one host
(``ros2 topic list`` with no arguments): a launched graph, a lone ``flexsheet run`` node and a
``flexsheet bag play`` are found alike. A graph on other hosts, or one running CURVE (whose keys only its
launch file names), is reached with ``--launch FILE`` as before.

:func:`resolve_graph` picks the graph a tool talks to: ``--launch FILE``, else ``--endpoint`` addresses, else
``$FLEXSHEET_LAUNCH``, else the nodes announced here; with none it raises :class:`LookupError` saying which
file or flag is needed.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from flexsheet.runtime.domain import domain_id
from flexsheet.runtime.launch import load_launch
from flexsheet.runtime.launch_config import curve_config

__all__ = ["graph_dir", "announce", "withdraw", "discover", "resolve_graph", "Graph"]


def graph_dir() -> Path:
    """The folder where this machine's nodes announce themselves (see the module docstring)."""
    if os.environ.get("FLEXSHEET_GRAPH_DIR"):
        return Path(os.environ["FLEXSHEET_GRAPH_DIR"])
    if os.environ.get("XDG_RUNTIME_DIR"):
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "flexsheet" / "graph"
    return Path(tempfile.gettempdir()) / f"flexsheet-graph-{os.getuid()}"


def announce(node: str, endpoint: str, curve: bool) -> Path | None:
    """Write this process's entry for ``node`` publishing on ``endpoint`` (``tcp://HOST:PORT``); returns its
    path, or None when the endpoint is not TCP or the folder cannot be written (discovery is a convenience:
    a node never fails for it)."""
    if not endpoint.startswith("tcp://"):
        return None
    folder = graph_dir()
    path = folder / f"{node}-{os.getpid()}.json"
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(
            json.dumps({"node": node, "endpoint": endpoint, "pid": os.getpid(), "curve": bool(curve),
                        "domain": domain_id()}))
        tmp.replace(path)
    except OSError:
        return None
    return path


def withdraw(path: Path | None) -> None:
    """Remove an entry :func:`announce` wrote (None: nothing to do)."""
    if path is not None:
        try:
            path.unlink()
        except OSError:
            pass


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def discover() -> list[dict]:
    """The live entries of :func:`graph_dir` in this process's domain
    (:func:`~flexsheet.runtime.domain.domain_id`; an entry without one is domain 0), sorted by node name
    (stale and unreadable ones are removed)."""
    found = []
    domain = domain_id()
    try:
        files = sorted(graph_dir().glob("*.json"))
    except OSError:
        return []
    for f in files:
        try:
            e = json.loads(f.read_text())
            ok = (isinstance(e, dict) and isinstance(e.get("pid"), int)
                  and str(e.get("endpoint", "")).startswith("tcp"))
        except (OSError, ValueError):
            ok = False
        if ok and _alive(e["pid"]):
            if e.get("domain", 0) == domain:
                found.append(e)
        else:
            withdraw(f)
    return sorted(found, key=lambda e: (e["node"], e["pid"]))


@dataclass
class Graph:
    """The graph a tool talks to: the publisher ``peers`` (endpoints), the tool's CURVE config (None: plain),
    the node ``names`` expected (empty: unknown), the launch file if one named it, and ``source``, a phrase
    for messages ("the graph of launch/sim.yaml", "3 nodes found on this machine")."""

    peers: list[str]
    curve: object = None
    names: set[str] = field(default_factory=set)
    launch: object = None
    source: str = ""


def resolve_graph(launch: str | None, endpoints: list[str] | None = None) -> Graph:
    """The :class:`Graph` for ``--launch`` / ``--endpoint`` (see the module docstring). Raises
    :class:`~flexsheet.runtime.launch.LaunchError` for an unusable launch file and :class:`LookupError` (one
    line naming what to give) when nothing is found."""
    launch = launch or (None if endpoints else os.environ.get("FLEXSHEET_LAUNCH"))
    if launch:
        lf = load_launch(launch)
        return Graph(list(lf.endpoints().values()), curve_config(lf, None), set(lf.nodes), lf,
                     f"the graph of {launch}")
    if endpoints:
        bad = [e for e in endpoints if not e.startswith("tcp://") or ":" not in e[6:]]
        if bad:
            raise LookupError(f"--endpoint {bad[0]!r}: expected tcp://HOST:PORT")
        return Graph(list(endpoints), source=f"endpoint(s) {', '.join(endpoints)}")
    found = discover()
    plain = [e for e in found if not e.get("curve")]
    if found and not plain:
        raise LookupError(f"the graph on this machine runs CURVE ({', '.join(e['node'] for e in found)}): "
                          "give --launch FILE, its launch file, for its keys")
    if not plain:
        raise LookupError(f"no flexsheet node is running on this machine in domain {domain_id()} (none "
                          f"announced in {graph_dir()}): start "
                          "one (flexsheet launch FILE, flexsheet bag play BAG), or give --launch FILE for a "
                          "graph on other hosts, or --endpoint tcp://HOST:PORT")
    names = {e["node"] for e in plain}
    return Graph(sorted({e["endpoint"] for e in plain}), None, names, None,
                 f"{len(names)} node(s) found on this machine")
