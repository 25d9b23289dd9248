"""Launch files: validated YAML describing hosts and nodes, and one asyncio supervisor that runs them.

A launch file (``launch/*.yaml``) is the single source of truth for hosts and ports::

    name: sim
    clock: sim                       # sim: one process on simulated time (flexsheet.runtime.lockstep); wall
                                     # or {type: sim, rtf: 1.0}: simulated time paced at 1.0 x wall time
      hosts: main: {address: 127.0.0.1} base_port: 7100                  # nodes without a port get base_port
      + their index nodes: talker: type: talker                 # a node type: an entry point of
      flexsheet.nodes (pyproject.toml) host: main params: {rate: 10.0}         # validated against the node's
      Params model remaps: {/chatter: /chatter2} respawn: {policy: on-failure, delay: 0.5, max_restarts: 5}
      required: false              # true: when it exits by itself, the whole launch stops container: vision
      # share one process (and loop) with the other nodes of this container security:                        #
      ZeroMQ CURVE (docs/deploy.md); keys from `flexsheet keys generate` curve: true public_keys_file:
      $(keys)/public_keys.yaml
    # plus the top-level sections of the installed launch extensions (flexsheet.runtime.extensions)

Every node publishes on ``tcp://<host address>:<port>`` (or an explicit ``endpoint:``) and subscribes to every
node endpoint of the file, so the same file serves one machine (127.0.0.1) and the lab's three PCs;
``flexsheet launch FILE --host NAME`` starts only that host's share. ``external: [/topic, …]`` names the
topics a tool or another launch file feeds (:mod:`flexsheet.runtime.graph_builder` asks no node to publish
them). Strings in params may use ``$(out)`` (the ``--out`` folder) and ``$(launch_dir)``; the security paths
may use ``$(keys)`` (the keys folder: ``$FLEXSHEET_KEYS``, else ``security.keys_dir``, else
~/.flexsheet/keys) and ``$(launch_dir)``.
:mod:`flexsheet.runtime.launch_check` checks a file against this machine (``flexsheet launch FILE --check``)
and ``flexsheet launch`` runs that check before it starts anything.

The supervisor starts each node as its own OS process (``python -m flexsheet run …``) — or, for the nodes of
one ``container:`` on one host, one process for them all (``python -m flexsheet run --container NAME …``,
:mod:`flexsheet.runtime.container`: messages between them are passed as objects; the container restarts a
crashed node itself, the supervisor restarts the container process) — prefixes every output line with the node
(or container) name as it arrives (line-buffered, never batched), respawns by policy (never a node that exits
with :data:`~flexsheet.runtime.config.EXIT_CONFIG`, a configuration error), watches the heartbeats of every
node of the file (all hosts) and reports a node or host that goes silent, and on Ctrl-C/SIGTERM stops all
children in reverse order with escalation SIGINT → SIGTERM → SIGKILL. Children get ``PR_SET_PDEATHSIG`` so
that not even a ``kill -9`` of the launcher leaves orphans. With ``--out`` it samples each child's CPU time
(``/proc/<pid>/stat``) and writes ``$(out)/cpu.json`` when it stops. ``clock: sim`` (default ``wall``) runs
the whole graph on simulated time: every node in one container, :data:`SIM_CONTAINER`, driven by
:func:`flexsheet.runtime.lockstep.run_live` (the file's nodes must share one host; a node's own ``container:``
is then ignored); ``--duration`` counts simulated seconds. ``clock: {type: sim,
rtf: X}`` (or ``flexsheet launch --rtf X``) caps simulated time at X times wall time (Gazebo's
``real_time_factor``); unset, it runs as fast as the host allows. Pacing changes no published byte. A
``--set hosts.NAME.address=ADDR`` override (:mod:`flexsheet.runtime.launch_sets`) moves a host, e.g. the lab's
three hosts onto loopback addresses of one machine. What each node and tool takes from a file (its
:class:`~flexsheet.runtime.config.NodeConfig`, its CURVE keys) is :mod:`flexsheet.runtime.launch_config`.
Errors: :class:`LaunchError` naming the file, the key and the wrong value.
Source: ros2/launch ``launch_service.py`` (minus its substitution layer), supervisord's policies.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from flexsheet.runtime.domain import domain_id, shift_port
from flexsheet.runtime.extensions import sections as launch_sections
from flexsheet.runtime.plugins import node_types, unknown_node_type
from flexsheet.yamlio import UniqueKeyLoader

__all__ = ["LaunchError", "LaunchFile", "NodeSpec", "HostSpec", "SecuritySpec", "RespawnSpec", "load_launch",
           "identities", "keys_dir", "substitutions", "substitute", "keygen_command", "short_repr",
           "TOPLEVEL_ENV",
           "CORE_SET", "SIM_CONTAINER", "DEFAULT_KEYS_DIR", "PUBLIC_KEYS_FILE", "MAX_LAUNCH_BYTES"]

#: where ``flexsheet keys generate`` writes and CURVE looks when neither ``$FLEXSHEET_KEYS`` nor
#: ``security.keys_dir`` says otherwise
DEFAULT_KEYS_DIR = "~/.flexsheet/keys"
#: the container that holds every node of a ``clock: sim`` launch file
SIM_CONTAINER = "sim_clock"
#: the host → public key YAML that ``flexsheet keys generate`` writes into the keys folder
PUBLIC_KEYS_FILE = "public_keys.yaml"


class LaunchError(ValueError):
    """A launch file that cannot be used: the message names the file, the key and the wrong value.

    ``lines``: every error found (one line each; the message is the first), for ``flexsheet launch --check``.
    """

    def __init__(self, message: str, lines: list[str] | None = None) -> None:
        super().__init__(message)
        self.lines = list(lines) if lines else [message]


#: a launch file larger than this (bytes) is refused before it is parsed
MAX_LAUNCH_BYTES = 1 << 20


def short_repr(value: Any, limit: int = 120) -> str:
    """Bounded one-line repr of ``value`` (``reprlib``), at most ``limit`` characters, for error messages: a
    YAML alias bomb or a deep structure must not make the error message itself exponential in time and
    memory."""
    import reprlib

    r = reprlib.Repr()
    r.maxlevel, r.maxlist, r.maxdict, r.maxtuple, r.maxset, r.maxstring, r.maxother = (3, 6, 6, 6, 6, limit,
                                                                                       limit)
    return " ".join(r.repr(value).split())[:limit]


class HostSpec(BaseModel):
    """A host of the graph: ``address`` is the IP/name its nodes bind to and others connect to."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    address: str = "127.0.0.1"


class RespawnSpec(BaseModel):
    """Respawn policy: ``never``, ``on-failure`` (non-zero exit or signal) or ``always``."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    policy: Literal["never", "on-failure", "always"] = "on-failure"
    delay: float = Field(default=0.5, ge=0.0, description="s before a restart")
    max_restarts: int = Field(default=10, ge=0, description="restarts allowed in the whole run")


class SecuritySpec(BaseModel):
    """ZeroMQ CURVE for the whole graph. Every node has its own keypair (its publisher proves it, its
    subscribers present it) and every host one more, for the tools run there (``topic echo``, the launcher's
    heartbeat watch). The allowed keys are identity (node or host name) → Z85 public key (40 chars), given
    inline (``public_keys``) or, so that no key is pasted into a launch file, read from ``public_keys_file``
    (a YAML mapping written by ``flexsheet keys generate --launch FILE``; ``$(keys)``, ``$(launch_dir)`` and
    ``~`` expand); both may be used if they agree. ``keys_dir``: where each host finds ``<name>.key_secret``
    of itself and of its nodes (``$FLEXSHEET_KEYS`` overrides it; ``~`` and ``$(launch_dir)`` expand).
    ``publishers``: guarded topic → the nodes allowed to publish it (SROS2-style per-node policy): a
    subscriber takes that topic only from those nodes' endpoints, proven by their keys
    (:class:`~flexsheet.runtime.zmq.subscriber.SubLinks`); any other topic comes from any node of the
    graph."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    curve: bool = False
    keys_dir: str = DEFAULT_KEYS_DIR
    public_keys: dict[str, str] = Field(default_factory=dict)
    public_keys_file: str | None = None
    publishers: dict[str, list[str]] = Field(default_factory=dict)

    @field_validator("public_keys")
    @classmethod
    def _z85(cls, v: dict[str, str]) -> dict[str, str]:
        for host, key in v.items():
            if not isinstance(key, str) or len(key) != 40:
                raise ValueError(f"public key of host {host!r} must be 40 Z85 characters, got {key!r}")
        return v


class NodeSpec(BaseModel):
    """One node of a launch file (see the module docstring)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    type: str
    host: str = "localhost"
    port: int | None = Field(default=None, ge=1, le=65535)
    endpoint: str | None = Field(default=None, pattern=r"^(tcp|ipc|inproc)://\S+$",
                                 description="explicit bound endpoint, e.g. tcp://10.0.0.2:7501")
    params: dict[str, Any] = Field(default_factory=dict)
    remaps: dict[str, str] = Field(default_factory=dict)
    respawn: RespawnSpec = Field(default_factory=RespawnSpec)
    required: bool = False
    nice: int = Field(default=0, ge=-20, le=19, description="process niceness (negative needs root)")
    rt_priority: int = Field(default=0, ge=0, le=90,
                             description="SCHED_FIFO priority for a hard-periodic loop (needs "
                                         "root/CAP_SYS_NICE; 0 = normal scheduling; Linux RT throttling "
                                         "keeps 5 % for the rest; processes the node starts run in the "
                                         "normal class: reset on fork)")
    container: str | None = Field(default=None, pattern=r"^[A-Za-z_][A-Za-z0-9_-]{0,63}$",
                                  description="composable container: the nodes of one container and host run "
                                              "in one process and one event loop "
                                              "(flexsheet.runtime.container)")

    @field_validator("type")
    @classmethod
    def _known_type(cls, v: str) -> str:
        if v not in node_types():
            raise ValueError(unknown_node_type(v))
        return v


#: environment variable carrying top-level overrides (``--set twin.truth_seed=3``, ``--set scene=FILE``) from
#: ``flexsheet launch`` to :func:`load_launch` in the launcher and in every node process it starts (JSON)
TOPLEVEL_ENV = "FLEXSHEET_LAUNCH_SET"


class LaunchFile(BaseModel):
    """A whole launch file: hosts, nodes and graph-wide settings."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    name: str = "graph"
    description: str = ""
    clock: Literal["sim", "wall"] = Field(default="wall", description="sim: the whole graph in one process "
                                          "on simulated time (deterministic); wall: the host's clock")
    rtf: float | None = Field(default=None, gt=0.0, le=1000.0,
                              description="clock: sim only: cap simulated time at rtf x wall time (1.0: real "
                                          "speed); None: as fast as the host allows. Written clock: {type: "
                                          "sim, rtf: X} in the file, or flexsheet launch --rtf X")
    hosts: dict[str, HostSpec] = Field(default_factory=lambda: {"localhost": HostSpec()})
    base_port: int = Field(default=7100, ge=1024, le=65000)
    heartbeat_period: float = Field(default=1.0, gt=0.0)
    shutdown_timeout: float = Field(default=3.0, gt=0.0, description="s per escalation step")
    report: str | None = Field(default=None, description="'module:function' called after the run with --out")
    security: SecuritySpec = Field(default_factory=SecuritySpec)
    external: list[str] = Field(default_factory=list, description="topics a tool or another launch file "
                                "feeds: the graph check asks no node of this file to publish them")
    sections: dict[str, Any] = Field(default_factory=dict, description="the top-level sections launch "
                                     "extensions add (flexsheet.runtime.extensions), validated by them")
    nodes: dict[str, NodeSpec]

    path: Path | None = None

    @model_validator(mode="before")
    @classmethod
    def _clock_mapping(cls, data: Any) -> Any:
        """``clock: {type: sim, rtf: 1.0}`` → ``clock: sim`` + ``rtf: 1.0`` (the mapping's only keys)."""
        if isinstance(data, dict) and isinstance(data.get("clock"), dict):
            data = dict(data)
            clock = dict(data.pop("clock"))
            unknown = sorted(set(clock) - {"type", "rtf"})
            if unknown:
                raise ValueError(f"clock: unknown key {unknown[0]!r} (a mapping has type: sim|wall and rtf: "
                                 "X)")
            data["clock"] = clock.get("type", "sim")
            if clock.get("rtf") is not None:
                data["rtf"] = clock["rtf"]
        return data

    def section(self, key: str) -> Any:
        """The value of top-level section ``key`` (None when the file has none)."""
        return self.sections.get(key)

    def endpoint_of(self, name: str) -> str:
        """Bound endpoint of node ``name`` (explicit ``endpoint``, else tcp://address:port)."""
        spec = self.nodes[name]
        if spec.endpoint:
            return spec.endpoint
        port = spec.port if spec.port is not None else self.base_port + list(self.nodes).index(name) + 1
        return f"tcp://{self.hosts[spec.host].address}:{port}"

    def endpoints(self) -> dict[str, str]:
        """Node name → endpoint for every node of the file."""
        return {n: self.endpoint_of(n) for n in self.nodes}


def _error_lines(path: Path, exc: ValidationError, prefix: str = "") -> list[str]:
    """One line per validation error, naming the file, the key path and the value."""
    lines = []
    for err in exc.errors():
        # a key with control characters (a YAML key "\n") is shown escaped
        key = ".".join([prefix] * bool(prefix)
                       + [str(p) for p in err["loc"]]).encode("unicode_escape").decode("ascii")
        lines.append(f"{path}: key '{key}': {err['msg']:.300} (value {short_repr(err.get('input'))})")
    return lines


def load_launch(path: str | Path) -> LaunchFile:
    """Read and validate a launch file. Raises :class:`LaunchError` naming file, key and value."""
    path = Path(path)
    raw = _apply_toplevel_env(_read_mapping(path), path)
    lf = _validate(raw, path)
    try:
        domain = domain_id()
    except ValueError as exc:
        raise LaunchError(f"{path}: {exc}") from None
    if domain:  # this machine's domain (flexsheet.runtime.domain): the file's ports move
        lf.base_port = shift_port(lf.base_port, domain)
        for spec in lf.nodes.values():
            if spec.port is not None:
                spec.port = shift_port(spec.port, domain)
    lines = _graph_problems(lf, path)
    if lines:
        raise LaunchError(lines[0], lines)
    lf.path = path
    return lf


def _read_mapping(path: Path) -> dict:
    """The YAML mapping of launch file ``path`` (at most :data:`MAX_LAUNCH_BYTES`). Raises
    :class:`LaunchError`."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_LAUNCH_BYTES + 1)
        if len(data) > MAX_LAUNCH_BYTES:
            raise LaunchError(f"{path}: launch file larger than {MAX_LAUNCH_BYTES} bytes")
        raw = yaml.load(data.decode("utf-8"), Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except FileNotFoundError:
        raise LaunchError(f"{path}: launch file not found") from None
    except OSError as exc:
        raise LaunchError(f"{path}: cannot read launch file: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise LaunchError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except yaml.YAMLError as exc:
        raise LaunchError(f"{path}: not valid YAML: {' '.join(str(exc).split())[:300]}") from None
    except RecursionError:
        raise LaunchError(f"{path}: not valid YAML: nested too deeply") from None
    if not isinstance(raw, dict):
        raise LaunchError(f"{path}: top level must be a mapping with 'nodes', got {type(raw).__name__}")
    return raw


def _validate(raw: dict, path: Path) -> LaunchFile:
    """``raw`` validated as a :class:`LaunchFile`, the launch extensions' sections by their types. Raises
    :class:`LaunchError` with every error found."""
    known = launch_sections()
    found = {k: raw.pop(k) for k in list(raw) if k in known and k != "sections"}
    lines = []
    try:
        lf = LaunchFile.model_validate(raw)
    except ValidationError as exc:
        lines += _error_lines(path, exc)
    checked = {}
    for key, value in found.items():
        try:
            checked[key] = TypeAdapter(known[key].type).validate_python(value, strict=True)
        except ValidationError as exc:
            lines += _error_lines(path, exc, key)
    if lines:
        raise LaunchError(lines[0], lines) from None
    lf.sections = checked
    return lf


def _graph_problems(lf: LaunchFile, path: Path) -> list[str]:
    """The problems of the validated ``lf`` across its keys (hosts, endpoints, containers, clock, security),
    one line each. A ``clock: sim`` file's nodes are put in :data:`SIM_CONTAINER` here."""
    lines = []
    for name, spec in lf.nodes.items():
        if spec.host not in lf.hosts:
            lines.append(f"{path}: key 'nodes.{name}.host': unknown host {spec.host!r}; hosts: "
                         f"{', '.join(lf.hosts)}")
    if not lines:
        seen: dict[str, str] = {}
        for name, ep in lf.endpoints().items():
            if lf.nodes[name].endpoint is None and int(ep.rsplit(":", 1)[1]) > 65535:
                lines.append(f"{path}: key 'nodes.{name}.port': base_port {lf.base_port} + node index gives "
                             f"port {ep.rsplit(':', 1)[1]} > 65535; lower base_port or give the node a port")
            elif ep in seen:
                lines.append(f"{path}: key 'nodes.{name}.port': endpoint {ep} already used by node "
                             f"{seen[ep]!r}")
            seen[ep] = name
    for name, spec in lf.nodes.items():
        if spec.container is not None and spec.container in lf.nodes:
            lines.append(f"{path}: key 'nodes.{name}.container': container name {spec.container!r} is also a "
                         "node name; give the container its own name")
    if lf.rtf is not None and lf.clock != "sim":
        lines.append(f"{path}: key 'clock.rtf': {lf.rtf:g} paces simulated time; it needs clock: sim (this "
                     f"file runs on the wall clock)")
    if lf.clock == "sim":
        hosts = sorted({s.host for s in lf.nodes.values()})
        if len(hosts) > 1:
            lines.append(f"{path}: key 'clock': sim runs the graph in one process, but its nodes are on "
                         f"hosts {', '.join(hosts)}; put them on one host or use clock: wall")
        for spec in lf.nodes.values():
            spec.container = SIM_CONTAINER
    lines += [f"{path}: key 'external': {t!r} is not a topic (/name)" for t in lf.external
              if not t.startswith("/")]
    clash = sorted(set(lf.hosts) & set(lf.nodes))
    if lf.security.curve and clash:
        lines.append(f"{path}: key 'nodes.{clash[0]}': a node named like a host; under CURVE each has its "
                     f"own key of that name: rename the node")
    for topic, names in lf.security.publishers.items():
        unknown = [n for n in names if n not in lf.nodes]
        if not topic.startswith("/") or unknown or not names:
            lines.append(f"{path}: key 'security.publishers.{topic}': {names!r}: a topic (/name) and the "
                         f"nodes of this file allowed to publish it"
                         + (f"; no node named {unknown[0]!r}" if unknown else ""))
        elif not lf.security.curve:
            lines.append(f"{path}: key 'security.publishers': needs curve: true (the nodes prove who they "
                         f"are by their keys)")
            break
    if lf.security.curve and lf.security.public_keys_file is None:  # a keys file is read when used (check)
        missing = [h for h in identities(lf) if h not in lf.security.public_keys]
        if missing:
            lines.append(f"{path}: key 'security.public_keys': curve is on but no public key for "
                         f"{', '.join(missing)} (run: flexsheet keys generate --launch {path}, or name "
                         f"the file it writes: security.public_keys_file: $(keys)/{PUBLIC_KEYS_FILE})")
    return lines


def keygen_command(lf: LaunchFile) -> str:
    """The command that writes every key ``lf`` needs: ``flexsheet keys generate --launch <its file>``."""
    return f"flexsheet keys generate --launch {lf.path or '<launch file>'}"


def identities(lf: LaunchFile, host: str | None = None) -> list[str]:
    """The CURVE identities of ``lf`` (of ``host`` only, when given): each host (its tools), then each
    node."""
    hosts = [h for h in lf.hosts if host is None or h == host]
    return hosts + [n for n, spec in lf.nodes.items() if host is None or spec.host == host]


def _launch_dir(lf: LaunchFile) -> str:
    return str(lf.path.parent.resolve()) if lf.path else "."


def keys_dir(lf: LaunchFile | None = None) -> Path:
    """The keys folder: ``$FLEXSHEET_KEYS``, else ``lf.security.keys_dir`` (``$(launch_dir)``, ``~``
    expanded), else :data:`DEFAULT_KEYS_DIR`. The folder need not exist."""
    raw = os.environ.get("FLEXSHEET_KEYS") or (lf.security.keys_dir if lf is not None else DEFAULT_KEYS_DIR)
    if lf is not None:
        raw = raw.replace("$(launch_dir)", _launch_dir(lf))
    return Path(os.path.expanduser(raw))


def substitutions(lf: LaunchFile, out: str | None = None) -> dict[str, str]:
    """The ``$(name)`` substitutions of ``lf``: ``out`` (``out``, else ``$FLEXSHEET_OUT``, else ``out``),
    ``launch_dir`` (the file's folder, absolute) and ``keys`` (:func:`keys_dir`)."""
    return {"out": out or os.environ.get("FLEXSHEET_OUT", "out"), "launch_dir": _launch_dir(lf),
            "keys": str(keys_dir(lf))}


def substitute(value: Any, subs: dict[str, str]) -> Any:
    """``value`` with every ``$(k)`` in its strings (recursively through dicts and lists) replaced by
    ``subs[k]``."""
    if isinstance(value, str):
        for k, v in subs.items():
            value = value.replace(f"$({k})", v)
        return value
    if isinstance(value, dict):
        return {k: substitute(v, subs) for k, v in value.items()}
    if isinstance(value, list):
        return [substitute(v, subs) for v in value]
    return value


#: launch-file keys of the core (not of an extension) that a top-level override may set: ``hosts`` (merged
#: host by host: ``--set hosts.main.address=127.0.0.1``), ``rtf`` (``flexsheet launch --rtf X``) and
#: ``base_port`` (``--set base_port=9400``: a second graph beside a running one)
CORE_SET = ("hosts", "rtf", "base_port")


def _apply_toplevel_env(raw: dict, path: Path) -> dict:
    """``raw`` with the top-level overrides of ``$FLEXSHEET_LAUNCH_SET`` applied (``twin`` merged key by key,
    ``hosts`` host by host). Raises :class:`LaunchError` for a host the file lacks."""
    text = os.environ.get(TOPLEVEL_ENV)
    if not text:
        return raw
    try:
        over = json.loads(text)
    except ValueError:
        raise LaunchError(f"{path}: ${TOPLEVEL_ENV} is not JSON: {text[:200]!r}") from None
    keys = launch_sections()
    allowed = [*keys, *CORE_SET]
    if not isinstance(over, dict) or set(over) - set(allowed):
        raise LaunchError(f"{path}: ${TOPLEVEL_ENV} may set only {', '.join(allowed)}, got {text[:200]!r}")
    raw = dict(raw)
    for key, value in over.items():
        if key == "hosts":
            raw["hosts"] = _merge_hosts(raw.get("hosts"), value, path)
        elif key == "base_port":
            raw["base_port"] = value
        elif key == "rtf":
            clock = raw.get("clock", "wall")
            raw["clock"] = {**(clock if isinstance(clock, dict) else {"type": clock}), "rtf": value}
        elif keys[key].parse_set is None and isinstance(value, dict):   # a mapping section: merged key by key
            base = raw.get(key) if isinstance(raw.get(key), dict) else {}
            raw[key] = {**base, **value}
        else:
            raw[key] = value
    return raw


def _merge_hosts(hosts: Any, over: dict, path: Path) -> dict:
    """The file's ``hosts`` with ``over`` (host → {key: value}) merged in; a host the file lacks is an
    error."""
    hosts = dict(hosts) if isinstance(hosts, dict) else {"localhost": {}}
    for name, spec in over.items():
        if name not in hosts:
            raise LaunchError(f"{path}: --set hosts.{name}: no host {name!r} in this file; hosts: "
                              f"{', '.join(hosts)}")
        base = hosts[name] if isinstance(hosts[name], dict) else {}
        hosts[name] = {**base, **spec}
    return hosts
