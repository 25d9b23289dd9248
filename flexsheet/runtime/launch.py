"""Launch files: validated YAML describing hosts and nodes, and one asyncio supervisor that runs them.

A launch file (``launch/*.yaml``) is the single source of truth for hosts and ports::

    name: sim
    hosts:
      main: {address: 127.0.0.1}
    base_port: 7100                  # nodes without a port get base_port + their index
    nodes:
      talker:
        type: talker                 # a key of flexsheet.registry.NODES
        host: main
        params: {rate: 10.0}         # validated against the node's Params model
        remaps: {/chatter: /chatter2}
        respawn: {policy: on-failure, delay: 0.5, max_restarts: 5}
        required: false              # true: when it exits by itself, the whole launch stops
        container: vision            # share one process (and loop) with the other nodes of this container
    security:                        # ZeroMQ CURVE (docs/deploy.md); keys from `flexsheet keys generate`
      curve: true
      public_keys_file: $(keys)/public_keys.yaml
    # plus the top-level sections of the installed launch extensions (flexsheet.runtime.extensions)

Every node publishes on ``tcp://<host address>:<port>`` (or an explicit ``endpoint:``) and subscribes to
every node endpoint of the file, so the same file serves one machine (127.0.0.1) and the lab's three PCs;
``flexsheet launch FILE --host NAME`` starts only that host's share. Strings in params may use ``$(out)`` (the ``--out`` folder) and ``$(launch_dir)``; the security paths may
use ``$(keys)`` (the keys folder: ``$FLEXSHEET_KEYS``, else ``security.keys_dir``, else ~/.flexsheet/keys)
and ``$(launch_dir)``. :mod:`flexsheet.runtime.launch_check` checks a file against this machine
(``flexsheet launch FILE --check``) and ``flexsheet launch`` runs that check before it starts anything.

The supervisor starts each node as its own OS process (``python -m flexsheet run …``) — or, for the nodes of
one ``container:`` on one host, one process for them all (``python -m flexsheet run --container NAME …``,
:mod:`flexsheet.runtime.container`: messages between them are passed as objects; the container restarts a
crashed node itself, the supervisor restarts the container process) — prefixes every
output line with the node (or container) name as it arrives (line-buffered, never batched), respawns by policy
(never a node that exits with :data:`~flexsheet.runtime.node.EXIT_CONFIG`, a configuration error), watches
the heartbeats of every node of the file (all hosts) and reports a node or host that goes silent, and on
Ctrl-C/SIGTERM stops all children in reverse order with escalation SIGINT → SIGTERM → SIGKILL. Children
get ``PR_SET_PDEATHSIG`` so that not even a ``kill -9`` of the launcher leaves orphans. With ``--out`` it samples
each child's CPU time (``/proc/<pid>/stat``) and writes ``$(out)/cpu.json`` when it stops.
Errors: :class:`LaunchError` naming the file, the key and the wrong value.
Source: ros2/launch ``launch_service.py`` (minus its substitution layer), supervisord's policies.
"""

from __future__ import annotations

import asyncio
import ctypes
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, field_validator

from flexsheet import registry
from flexsheet.runtime.extensions import sections as launch_sections
from flexsheet.runtime.node import EXIT_CONFIG, NodeConfig
from flexsheet.runtime.transport import CurveConfig
from flexsheet.yamlio import UniqueKeyLoader

__all__ = ["LaunchError", "LaunchFile", "NodeSpec", "HostSpec", "SecuritySpec", "load_launch", "node_config",
           "curve_config", "keys_dir", "public_keys", "substitutions", "substitute", "keygen_command",
           "TOPLEVEL_ENV", "parse_toplevel_set",
           "DEFAULT_KEYS_DIR", "PUBLIC_KEYS_FILE", "Supervisor", "container_spec",
           "children_of"]

#: where ``flexsheet keys generate`` writes and CURVE looks when neither ``$FLEXSHEET_KEYS`` nor
#: ``security.keys_dir`` says otherwise
DEFAULT_KEYS_DIR = "~/.flexsheet/keys"
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


def _short(value: Any, limit: int = 120) -> str:
    """Bounded one-line repr (``reprlib``): a YAML alias bomb or a deep structure must not make the error
    message itself exponential in time and memory."""
    import reprlib

    r = reprlib.Repr()
    r.maxlevel, r.maxlist, r.maxdict, r.maxtuple, r.maxset, r.maxstring, r.maxother = 3, 6, 6, 6, 6, limit, limit
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
    """ZeroMQ CURVE for the whole graph. The allowed keys are host → Z85 public key (40 chars), given inline
    (``public_keys``) or, so that no key is pasted into a launch file, read from ``public_keys_file`` (a YAML
    mapping written by ``flexsheet keys generate``; ``$(keys)``, ``$(launch_dir)`` and ``~`` expand); both may
    be used if they agree. ``keys_dir``: where each host finds its own ``<host>.key_secret``
    (``$FLEXSHEET_KEYS`` overrides it; ``~`` and ``$(launch_dir)`` expand)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    curve: bool = False
    keys_dir: str = DEFAULT_KEYS_DIR
    public_keys: dict[str, str] = Field(default_factory=dict)
    public_keys_file: str | None = None

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
                             description="SCHED_FIFO priority for a hard-periodic loop (needs root/CAP_SYS_NICE; "
                                         "0 = normal scheduling; Linux RT throttling keeps 5 % for the rest; "
                                         "processes the node starts run in the normal class: reset on fork)")
    container: str | None = Field(default=None, pattern=r"^[A-Za-z_][A-Za-z0-9_-]{0,63}$",
                                  description="composable container: the nodes of one container and host run in "
                                              "one process and one event loop (flexsheet.runtime.container)")

    @field_validator("type")
    @classmethod
    def _known_type(cls, v: str) -> str:
        if v not in registry.NODES:
            raise ValueError(f"unknown node type {v!r}; known: {', '.join(sorted(registry.NODES))}")
        return v


#: environment variable carrying top-level overrides (``--set twin.truth_seed=3``, ``--set scene=FILE``) from
#: ``flexsheet launch`` to :func:`load_launch` in the launcher and in every node process it starts (JSON)
TOPLEVEL_ENV = "FLEXSHEET_LAUNCH_SET"


class LaunchFile(BaseModel):
    """A whole launch file: hosts, nodes and graph-wide settings."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    name: str = "graph"
    description: str = ""
    hosts: dict[str, HostSpec] = Field(default_factory=lambda: {"localhost": HostSpec()})
    base_port: int = Field(default=7100, ge=1024, le=65000)
    heartbeat_period: float = Field(default=1.0, gt=0.0)
    shutdown_timeout: float = Field(default=3.0, gt=0.0, description="s per escalation step")
    report: str | None = Field(default=None, description="'module:function' called after the run with --out")
    security: SecuritySpec = Field(default_factory=SecuritySpec)
    sections: dict[str, Any] = Field(default_factory=dict, description="the top-level sections launch "
                                     "extensions add (flexsheet.runtime.extensions), validated by them")
    nodes: dict[str, NodeSpec]

    path: Path | None = None

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
        key = ".".join([prefix] * bool(prefix) + [str(p) for p in err["loc"]]).encode("unicode_escape").decode("ascii")
        lines.append(f"{path}: key '{key}': {err['msg']:.300} (value {_short(err.get('input'))})")
    return lines


def load_launch(path: str | Path) -> LaunchFile:
    """Read and validate a launch file. Raises :class:`LaunchError` naming file, key and value."""
    path = Path(path)
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
    raw = _apply_toplevel_env(raw, path)
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
    for name, spec in lf.nodes.items():
        if spec.host not in lf.hosts:
            lines.append(f"{path}: key 'nodes.{name}.host': unknown host {spec.host!r}; hosts: {', '.join(lf.hosts)}")
    if not lines:
        seen: dict[str, str] = {}
        for name, ep in lf.endpoints().items():
            if lf.nodes[name].endpoint is None and int(ep.rsplit(":", 1)[1]) > 65535:
                lines.append(f"{path}: key 'nodes.{name}.port': base_port {lf.base_port} + node index gives port "
                             f"{ep.rsplit(':', 1)[1]} > 65535; lower base_port or give the node a port")
            elif ep in seen:
                lines.append(f"{path}: key 'nodes.{name}.port': endpoint {ep} already used by node {seen[ep]!r}")
            seen[ep] = name
    for name, spec in lf.nodes.items():
        if spec.container is not None and spec.container in lf.nodes:
            lines.append(f"{path}: key 'nodes.{name}.container': container name {spec.container!r} is also a node "
                         "name; give the container its own name")
    if lf.security.curve and lf.security.public_keys_file is None:  # a keys file is read when used (check)
        missing = [h for h in lf.hosts if h not in lf.security.public_keys]
        if missing:
            lines.append(f"{path}: key 'security.public_keys': curve is on but no public key for host(s) "
                         f"{', '.join(missing)} (run: flexsheet keys generate {' '.join(lf.hosts)}, or name "
                         f"the file it writes: security.public_keys_file: $(keys)/{PUBLIC_KEYS_FILE})")
    if lines:
        raise LaunchError(lines[0], lines)
    lf.path = path
    return lf


def keygen_command(lf: LaunchFile) -> str:
    """The command that writes every key ``lf`` needs: ``flexsheet keys generate <its hosts>``."""
    return "flexsheet keys generate " + " ".join(lf.hosts)


def _launch_dir(lf: LaunchFile) -> str:
    return str(lf.path.parent.resolve()) if lf.path else "."


def keys_dir(lf: LaunchFile | None = None) -> Path:
    """The keys folder: ``$FLEXSHEET_KEYS``, else ``lf.security.keys_dir`` (``$(launch_dir)``, ``~`` expanded),
    else :data:`DEFAULT_KEYS_DIR`. The folder need not exist."""
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
    """``value`` with every ``$(k)`` in its strings (recursively through dicts and lists) replaced by ``subs[k]``."""
    if isinstance(value, str):
        for k, v in subs.items():
            value = value.replace(f"$({k})", v)
        return value
    if isinstance(value, dict):
        return {k: substitute(v, subs) for k, v in value.items()}
    if isinstance(value, list):
        return [substitute(v, subs) for v in value]
    return value


def public_keys(lf: LaunchFile) -> dict[str, str]:
    """Host → Z85 public key allowed on ``lf``'s graph: ``security.public_keys`` merged with the YAML mapping in
    ``security.public_keys_file``. Raises :class:`LaunchError` naming the file or host (a missing file names
    the ``flexsheet keys generate`` command that writes it)."""
    sec = lf.security
    keys = dict(sec.public_keys)
    if sec.public_keys_file is None:
        return keys
    path = Path(os.path.expanduser(substitute(sec.public_keys_file, substitutions(lf))))
    where = f"{lf.path}: key 'security.public_keys_file' = {str(path)!r}"
    try:
        with open(path, "rb") as f:
            data = f.read(1 << 16)
        raw = yaml.safe_load(data.decode("utf-8"))
    except FileNotFoundError:
        raise LaunchError(f"{where}: no such file (run: {keygen_command(lf)})") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise LaunchError(f"{where}: unreadable ({' '.join(str(exc).split())[:200]})") from None
    if not isinstance(raw, dict):
        raise LaunchError(f"{where}: expected a mapping host: public key, got {type(raw).__name__} "
                          f"(run: {keygen_command(lf)})")
    for host, key in raw.items():
        if not isinstance(host, str) or not isinstance(key, str) or len(key) != 40:
            raise LaunchError(f"{where}: entry {_short(host)}: {_short(key)} is not host: <40 Z85 characters>")
        if host in keys and keys[host] != key:
            raise LaunchError(f"{where}: host {host!r} differs from security.public_keys.{host}")
        keys[host] = key
    return keys


def curve_config(lf: LaunchFile, host: str | None) -> CurveConfig | None:
    """The :class:`CurveConfig` of ``host`` under ``lf``'s security settings (None when CURVE is off).

    ``host`` None picks the first host whose secret key is present in the keys folder (tools).
    Raises :class:`LaunchError` naming the missing key file or host and the command that writes it.
    """
    sec = lf.security
    if not sec.curve:
        return None
    from flexsheet.runtime.transport import load_curve_keys

    kdir = keys_dir(lf)
    keys = public_keys(lf)
    missing = [h for h in lf.hosts if h not in keys]
    if missing:
        raise LaunchError(f"{lf.path}: key 'security.public_keys': curve is on but no public key for host(s) "
                          f"{', '.join(missing)} (run: {keygen_command(lf)})")
    hosts = [host] if host else [h for h in lf.hosts if (kdir / f"{h}.key_secret").exists()]
    if not hosts:
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': no <host>.key_secret in {kdir} "
                          f"(run: {keygen_command(lf)})")
    secret_file = kdir / f"{hosts[0]}.key_secret"
    if not secret_file.exists():
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': no secret key for host {hosts[0]!r} at "
                          f"{secret_file} (run: {keygen_command(lf)}, and copy {hosts[0]}.key_secret there)")
    try:
        public, secret = load_curve_keys(secret_file)
    except (OSError, ValueError) as exc:
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': unreadable key file {secret_file}: {exc}") from None
    if secret is None or public.decode() != keys.get(hosts[0]):
        raise LaunchError(f"{lf.path}: key 'security.public_keys.{hosts[0]}': does not match {secret_file}")
    server_keys = {lf.endpoint_of(n): keys[spec.host].encode() for n, spec in lf.nodes.items()}
    return CurveConfig(public_key=public, secret_key=secret, server_keys=server_keys,
                       allowed_clients=[k.encode() for h, k in keys.items() if h in lf.hosts])


def _apply_toplevel_env(raw: dict, path: Path) -> dict:
    """``raw`` with the top-level overrides of ``$FLEXSHEET_LAUNCH_SET`` applied (``twin`` merged key by key)."""
    text = os.environ.get(TOPLEVEL_ENV)
    if not text:
        return raw
    try:
        over = json.loads(text)
    except ValueError:
        raise LaunchError(f"{path}: ${TOPLEVEL_ENV} is not JSON: {text[:200]!r}") from None
    keys = launch_sections()
    if not isinstance(over, dict) or set(over) - set(keys):
        raise LaunchError(f"{path}: ${TOPLEVEL_ENV} may set only {', '.join(keys)}, got {text[:200]!r}")
    raw = dict(raw)
    for key, value in over.items():
        if keys[key].parse_set is None and isinstance(value, dict):   # a mapping section: merged key by key
            base = raw.get(key) if isinstance(raw.get(key), dict) else {}
            raw[key] = {**base, **value}
        else:
            raw[key] = value
    return raw


def parse_toplevel_set(item: str, node_names) -> tuple[str, Any] | None:
    """A ``--set`` item that overrides a top-level section of a launch extension: ``KEY=VALUE`` or, for a
    mapping section, ``KEY.SUB=VALUE`` (when no node is named KEY). Returns ``(key, value)`` (a mapping
    section's value as ``{SUB: VALUE}``, YAML-parsed), or ``None`` for a node override. Raises
    :class:`LaunchError` on a bad item."""
    known = launch_sections()
    head, dot, rest = item.partition(".")
    if dot and head in known and known[head].parse_set is None and head not in node_names:
        key, eq, value = rest.partition("=")
        if not eq or not key:
            raise LaunchError(f"--set {item!r}: expected {head}.KEY=VALUE")
        return head, {key: yaml.safe_load(value)}
    key, eq, value = item.partition("=")
    if eq and "." not in key:
        if key not in known or known[key].parse_set is None:
            forms = [f"{k}=VALUE" if s.parse_set else f"{k}.KEY=VALUE" for k, s in known.items()]
            raise LaunchError(f"--set {item!r}: a top-level override is one of {', '.join(forms)}; a node param "
                              "is NODE.KEY=VALUE")
        return key, known[key].parse_set(value)
    return None


def node_config(lf: LaunchFile, name: str, out: str | None = None, overrides: dict | None = None) -> NodeConfig:
    """The :class:`NodeConfig` of node ``name`` in ``lf`` (params merged with ``overrides``, substituted).

    Graph-wide settings reach the nodes that take them: for each top-level section of a launch extension
    (:mod:`flexsheet.runtime.extensions`) whose node value is not None, a node whose ``Params`` has a field of
    that name that its params leave unset gets the value there. Raises :class:`LaunchError` (unknown node, CURVE keys).
    """
    if name not in lf.nodes:
        raise LaunchError(f"{lf.path}: no node named {name!r}; nodes: {', '.join(lf.nodes)}")
    spec = lf.nodes[name]
    params = substitute({**spec.params, **(overrides or {})}, substitutions(lf, out))
    graph_wide = {key: sec.node_value(lf.section(key), lf, out) for key, sec in launch_sections().items()}
    if any(v is not None and k not in params for k, v in graph_wide.items()):
        try:
            fields = registry.load(registry.NODES[spec.type]).Params.model_fields
        except (ImportError, AttributeError, KeyError):
            fields = {}
        for key, value in graph_wide.items():
            if value is not None and key not in params and key in fields:
                params[key] = value
    return NodeConfig(name=name, node_type=spec.type, host=spec.host, endpoint=lf.endpoint_of(name),
                      peers=list(lf.endpoints().values()), params=params, remaps=spec.remaps,
                      heartbeat_period=lf.heartbeat_period, curve=curve_config(lf, spec.host))


def _child_setup(nice: int, rt_priority: int = 0):
    def setup() -> None:  # runs in the child between fork and exec
        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        except OSError:
            pass
        if nice:
            try:
                os.nice(nice)
            except OSError:  # negative niceness without root: run at the default priority
                pass
        if rt_priority:
            try:
                # reset on fork: a process the node starts (a table builder, a subprocess) begins in the normal
                # class, not at the node's real-time priority, where its imports alone would starve the graph
                os.sched_setscheduler(0, os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0),
                                      os.sched_param(rt_priority))
            except (OSError, AttributeError):  # no privilege: normal scheduling
                pass
    return setup


class _Child:
    def __init__(self, name: str, spec: NodeSpec, members: list[str] | None = None) -> None:
        self.name, self.spec = name, spec
        self.members = members or []  # the nodes of a container child (empty: one node)
        self.proc: asyncio.subprocess.Process | None = None
        self.restarts = 0
        self.stopping = False
        self.exit_codes: list[int] = []
        self.cpu_s = 0.0          # CPU time of the ended incarnations, s
        self.cpu_live = 0.0       # CPU time of the running incarnation at the last sample, s
        self.cpu_warm: tuple[float, float] | None = None  # (monotonic time, CPU s) once warmed up
        self.pids: list[int] = []
        self.started_at = 0.0


def container_spec(lf: LaunchFile, members: list[str]) -> NodeSpec:
    """The process-level spec of a container whose nodes are ``members``: required if any member is; respawn
    ``always`` if any member's policy is, else ``on-failure`` if any is, else ``never``, with the smallest
    delay and the largest ``max_restarts``; the smallest ``nice`` and the largest ``rt_priority``."""
    specs = [lf.nodes[n] for n in members]
    policies = {s.respawn.policy for s in specs}
    policy = "always" if "always" in policies else ("on-failure" if "on-failure" in policies else "never")
    respawn = RespawnSpec(policy=policy, delay=min(s.respawn.delay for s in specs),
                          max_restarts=max(s.respawn.max_restarts for s in specs))
    return NodeSpec(type=specs[0].type, host=specs[0].host, respawn=respawn, required=any(s.required for s in specs),
                    nice=min(s.nice for s in specs), rt_priority=max(s.rt_priority for s in specs),
                    container=specs[0].container)


def children_of(lf: LaunchFile, host: str | None) -> list[_Child]:
    """One child process per node, or per container on one host (at its first member's place in the file)."""
    out: list[_Child] = []
    seen: set[tuple[str, str]] = set()
    for n, s in lf.nodes.items():
        if host is not None and s.host != host:
            continue
        if s.container is None:
            out.append(_Child(n, s))
            continue
        key = (s.container, s.host)
        if key in seen:
            continue
        seen.add(key)
        members = [m for m, t in lf.nodes.items() if t.container == s.container and t.host == s.host]
        hosts_of_name = {t.host for t in lf.nodes.values() if t.container == s.container}
        label = s.container if len(hosts_of_name) == 1 else f"{s.container}@{s.host}"
        out.append(_Child(label, container_spec(lf, members), members))
    return out


def _proc_cpu_s(pid: int) -> float | None:
    """utime + stime of process ``pid`` (all its threads), s, from ``/proc/<pid>/stat``; None if gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    fields = data[data.rfind(b")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / _CLK_TCK


_CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class Supervisor:
    """Runs the nodes of one host of a launch file as child processes (see the module docstring).

    ``host`` None runs every node (all hosts on this machine). ``out`` is exported as ``FLEXSHEET_OUT`` and
    substituted for ``$(out)``. ``duration`` s stops the run after that long (None: until Ctrl-C or a
    required node exits). ``print_fn`` receives each prefixed output line.
    """

    def __init__(self, lf: LaunchFile, host: str | None = None, out: str | None = None,
                 duration: float | None = None, print_fn=None, python: str = sys.executable,
                 overrides: dict[str, list[str]] | None = None) -> None:
        if host is not None and host not in lf.hosts:
            raise LaunchError(f"{lf.path}: --host {host!r} is not a host of the file; hosts: {', '.join(lf.hosts)}")
        self.lf, self.host, self.out, self.duration = lf, host, out, duration
        self.print = print_fn or (lambda line: print(line, flush=True))
        self.python = python
        self.overrides = overrides or {}
        self.children = children_of(lf, host)
        self._stop = asyncio.Event()
        self.reason = ""
        self.lost_events: list[tuple[str, str]] = []
        self.config_errors: list[str] = []  # nodes that exited with EXIT_CONFIG (not respawned)
        width = max((len(c.name) for c in self.children), default=4)
        self._fmt = f"[{{:<{width}}}] {{}}"

    def _cmd(self, child: _Child) -> list[str]:
        if child.members:
            cmd = [self.python, "-u", "-m", "flexsheet", "run", "--container", child.spec.container, "--launch",
                   str(self.lf.path), "--host", child.spec.host]
            if self.out:
                cmd += ["--out", self.out]
            for node in child.members:
                for kv in self.overrides.get(node, []):
                    cmd += ["--set", f"{node}.{kv}"]
            return cmd
        cmd = [self.python, "-u", "-m", "flexsheet", "run", child.spec.type, "--launch", str(self.lf.path),
               "--name", child.name]
        if self.out:
            cmd += ["--out", self.out]
        for kv in self.overrides.get(child.name, []):
            cmd += ["--param", kv]
        return cmd

    async def _spawn(self, child: _Child) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", FLEXSHEET_LAUNCH=str(Path(self.lf.path).resolve()))
        if self.out:
            env["FLEXSHEET_OUT"] = self.out
        child.proc = await asyncio.create_subprocess_exec(
            *self._cmd(child), stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
            stdin=asyncio.subprocess.DEVNULL, env=env, start_new_session=True, preexec_fn=_child_setup(child.spec.nice, child.spec.rt_priority))

    async def _pump(self, child: _Child) -> None:
        assert child.proc is not None and child.proc.stdout is not None
        while True:
            line = await child.proc.stdout.readline()
            if not line:
                break
            self.print(self._fmt.format(child.name, line.decode(errors="replace").rstrip()))

    @staticmethod
    def _kill_group(pgid: int) -> None:
        """SIGKILL to what is left of an exited node's process group (its session: ``start_new_session``)."""
        try:
            os.killpg(pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass                             # the group is empty: nothing outlived the node

    async def _exit_code(self, child: _Child, pump: asyncio.Task) -> int:
        """The node's exit code as soon as its process exits, its output read to the end. Whatever is left in
        its process group then (a worker it started that had not yet tied itself to its parent,
        :mod:`flexsheet.runtime.background`) is killed: it would hold the node's output pipe open, and asyncio's
        ``wait()`` waits for that pipe too, so the launcher would report neither the exit nor respawn the node
        until the worker ended (the renderer's sheet table, ~30 s or more: a kill -9 during its worker's imports
        stalled the respawn, session 26). Output still held open 2 s after that is no longer read."""
        proc = child.proc
        loop = asyncio.get_running_loop()
        exited = loop.create_future()
        try:
            pidfd = os.pidfd_open(proc.pid)              # readable once the process has exited (Linux >= 5.3)
        except (AttributeError, OSError):
            pidfd = None                                 # already reaped, or no pidfd: the pipe's end decides
        if pidfd is not None:
            loop.add_reader(pidfd, lambda: exited.done() or exited.set_result(None))
        try:
            await asyncio.wait({exited, pump}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            if pidfd is not None:
                loop.remove_reader(pidfd)
                os.close(pidfd)
            exited.cancel()
        if pump.done():                      # the output closed first, as a node ends: the process is exiting
            code = await proc.wait()
            self._kill_group(proc.pid)
            return code
        for _ in range(200):                 # asyncio's child watcher reaps it a moment later
            if proc.returncode is not None:
                break
            await asyncio.sleep(0.005)
        if proc.returncode is None:          # not reaped within 1 s: wait for it (and its pipe) as before
            return await proc.wait()
        self._kill_group(proc.pid)
        try:
            await asyncio.wait_for(asyncio.shield(pump), timeout=2.0)
        except TimeoutError:
            pump.cancel()
            self.print(self._fmt.format(child.name, "output still held open by another process 2 s after "
                                                    "exit: no longer read"))
        return proc.returncode

    @staticmethod
    def _record_exit(child: _Child, code: int) -> None:
        """One incarnation's end: its exit code, and its CPU time added to the node's ended incarnations."""
        child.exit_codes.append(code)
        child.cpu_s += child.cpu_live
        child.cpu_live = 0.0

    async def _watch(self, child: _Child) -> None:
        while True:
            await self._spawn(child)
            child.pids.append(child.proc.pid)
            child.started_at = child.started_at or time.monotonic()
            self.print(self._fmt.format(child.name, f"started pid {child.proc.pid}"
                                        + (f" (container: {', '.join(child.members)})" if child.members else "")))
            code = await self._exit_code(child, asyncio.create_task(self._pump(child)))
            self._record_exit(child, code)
            if child.stopping or self._stop.is_set():
                return
            self.print(self._fmt.format(child.name, f"exited with code {code}"))
            if code == EXIT_CONFIG:  # bad params or a missing file: a restart would fail the same way
                self.print(self._fmt.format(child.name, "configuration error (see the line above): not respawned; "
                                                        f"check with: flexsheet launch {self.lf.path} --check"
                                                        + (f" --host {self.host}" if self.host else "")))
                self.config_errors.append(child.name)
                if child.spec.required:
                    self.reason = f"required node {child.name} has a configuration error"
                    self._stop.set()
                return
            if child.spec.required:
                self.reason = f"required node {child.name} exited ({code})"
                self._stop.set()
                return
            policy = child.spec.respawn
            if policy.policy == "never" or (policy.policy == "on-failure" and code == 0):
                return
            if child.restarts >= policy.max_restarts:
                self.print(self._fmt.format(child.name, f"not respawned: {policy.max_restarts} restarts used"))
                return
            child.restarts += 1
            self.print(self._fmt.format(child.name, f"respawning in {policy.delay:.1f} s "
                                                    f"(restart {child.restarts}/{policy.max_restarts})"))
            await asyncio.sleep(policy.delay)
            if self._stop.is_set():
                return

    async def _stop_child(self, child: _Child) -> None:
        child.stopping = True
        proc = child.proc
        if proc is None or proc.returncode is not None:
            return
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                return
            try:
                await asyncio.wait_for(proc.wait(), timeout=self.lf.shutdown_timeout)
                return
            except TimeoutError:
                self.print(self._fmt.format(child.name, f"did not stop on {sig.name}; escalating"))

    async def run(self) -> int:
        """Run until Ctrl-C, SIGTERM, ``duration`` or a required node's exit. Returns 0, or 1 if a node failed."""
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self._on_signal, sig)
        if not self.children:
            self.print(f"[launch] no nodes for host {self.host!r} in {self.lf.path}")
            return 0
        n_nodes = sum(len(c.members) or 1 for c in self.children)
        self.print(f"[launch] {self.lf.name}: starting {n_nodes} nodes"
                   + (f" in {len(self.children)} processes" if n_nodes != len(self.children) else "")
                   + (f" on host {self.host}" if self.host else ""))
        watchers = [loop.create_task(self._watch(c)) for c in self.children]
        monitor = loop.create_task(self._monitor())
        sampler = loop.create_task(self._sample_cpu())
        t0 = time.monotonic()
        try:
            if self.duration is not None:
                await asyncio.wait_for(self._stop.wait(), timeout=self.duration)
            else:
                await self._stop.wait()
        except TimeoutError:
            self.reason = f"duration {self.duration:g} s reached"
        self.print(f"[launch] stopping after {time.monotonic() - t0:.1f} s: {self.reason or 'stop requested'}")
        monitor.cancel()
        sampler.cancel()
        self._sample_now()
        await asyncio.gather(*(self._stop_child(c) for c in reversed(self.children)))
        await asyncio.wait(watchers, timeout=3.0)   # each records its node's exit (≤ 1 s reap + 2 s of output)
        for w in watchers:
            w.cancel()
        await asyncio.gather(*watchers, return_exceptions=True)
        for c in self.children:     # a watcher cancelled while it still read the stopped node's last output
            rc = c.proc.returncode if c.proc is not None else None    # never recorded that incarnation's exit:
            if rc is not None and len(c.exit_codes) < len(c.pids):    # a respawned node kept its kill's -9
                self._record_exit(c, rc)                              # and the run "failed" (session 27)
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        self.print("[launch] all nodes stopped")
        if self.out:
            self.write_cpu(Path(self.out) / "cpu.json", time.monotonic() - t0)
        failed = [c.name for c in self.children if c.exit_codes and c.exit_codes[-1] not in (0, -2, -15)]
        if failed:                           # name them: a run's exit 1 must say whose exit it is
            self.print("[launch] ended with a failure exit: " + ", ".join(
                f"{c.name} ({c.exit_codes[-1]})" for c in self.children if c.name in failed))
        if self.config_errors:
            return EXIT_CONFIG
        return 1 if failed and "required" in self.reason else 0

    def _on_signal(self, sig: signal.Signals) -> None:
        if self._stop.is_set():  # second Ctrl-C: stop faster
            self.lf.shutdown_timeout = min(self.lf.shutdown_timeout, 0.5)
        self.reason = f"{signal.Signals(sig).name} received"
        self._stop.set()

    async def _monitor(self) -> None:
        """Watch every node's heartbeat on ``/diagnostics`` (all hosts of the file) and report, once per
        transition, a node that goes silent for ``3 × heartbeat_period`` (its host is gone, partitioned or
        the node hangs) and when it comes back. Counts go into ``self.lost_events``."""
        from flexsheet.runtime.codec import DecodeError, decode
        from flexsheet.runtime.transport import ZmqTransport
        from messages import topics as T

        last: dict[str, float] = {}
        host_of = {n: s.host for n, s in self.lf.nodes.items()}
        lost: set[str] = set()

        def on_frames(frames: list) -> None:
            try:
                hb = decode(frames, T.DIAGNOSTICS)
            except DecodeError:
                return
            last[hb.node] = time.monotonic()
            if hb.node in lost:
                lost.discard(hb.node)
                self.print(f"[launch] node {hb.node} on host {host_of.get(hb.node, '?')} is back (heartbeat)")

        tr = ZmqTransport("", self.lf.endpoints().values(), curve=curve_config(self.lf, self.host or None))
        await tr.start(on_frames)
        tr.subscribe(T.DIAGNOSTICS.name)
        limit = 3.0 * self.lf.heartbeat_period
        try:
            while True:
                await asyncio.sleep(self.lf.heartbeat_period / 2)
                now = time.monotonic()
                for name, t in last.items():
                    if name in self.lf.nodes and name not in lost and now - t > limit:
                        lost.add(name)
                        self.lost_events.append((name, host_of.get(name, "?")))
                        self.print(f"[launch] node {name} on host {host_of.get(name, '?')} lost: no heartbeat "
                                   f"for {now - t:.1f} s")
        finally:
            tr.close()

    #: s after the start before the steady-state CPU share is measured (imports, precompute and caches excluded)
    cpu_warmup_s = 10.0

    def _sample_now(self) -> None:
        now = time.monotonic()
        for c in self.children:
            if c.proc is not None and c.proc.returncode is None:
                v = _proc_cpu_s(c.proc.pid)
                if v is not None:
                    c.cpu_live = v
            if c.cpu_warm is None and c.started_at and now - c.started_at >= self.cpu_warmup_s:
                c.cpu_warm = (now, c.cpu_s + c.cpu_live)

    async def _sample_cpu(self, period: float = 1.0) -> None:
        """Sample every child's CPU time each ``period`` s (a child that dies loses at most one period)."""
        while True:
            self._sample_now()
            await asyncio.sleep(period)

    def cpu_report(self, wall_s: float) -> dict:
        """Per node CPU use over the run: ``{"wall_s", "cores", "processes": {child: {"cpu_s", "cpu_percent",
        "steady_cpu_percent", "pids", "nodes", "restarts"}}, "nodes": {node: {"cpu_s", "cpu_percent",
        "process", "shared"}}}``. A node alone in its process: its process's CPU time
        (all its threads). A node in a container: its handlers' and timers' thread CPU time as the container
        measured it (``cpu_<container>.json``), ``shared`` naming the process whose total also holds the
        container's loop, decoding and worker threads. ``cpu_percent``: of one core, over ``wall_s``."""
        procs, nodes = {}, {}
        now = time.monotonic()
        for c in self.children:
            cpu = c.cpu_s + c.cpu_live
            procs[c.name] = {"cpu_s": round(cpu, 3), "cpu_percent": round(100.0 * cpu / wall_s, 2) if wall_s else 0.0,
                             "pids": c.pids, "nodes": c.members or [c.name], "restarts": c.restarts}
            if c.cpu_warm is not None and now - c.cpu_warm[0] > 1.0:
                procs[c.name]["steady_cpu_percent"] = round(100.0 * (cpu - c.cpu_warm[1]) / (now - c.cpu_warm[0]), 2)
            if not c.members:
                nodes[c.name] = {"cpu_s": round(cpu, 3), "cpu_percent": procs[c.name]["cpu_percent"],
                                 "process": c.name}
                if "steady_cpu_percent" in procs[c.name]:
                    nodes[c.name]["steady_cpu_percent"] = procs[c.name]["steady_cpu_percent"]
                continue
            inner: dict = {}
            if self.out:
                try:
                    inner = json.loads((Path(self.out) / f"cpu_{c.spec.container}.json").read_text()).get("nodes", {})
                except (OSError, ValueError):
                    inner = {}
            for n in c.members:
                v = float(inner.get(n, {}).get("handler_cpu_s", 0.0))
                nodes[n] = {"cpu_s": round(v, 3), "cpu_percent": round(100.0 * v / wall_s, 2) if wall_s else 0.0,
                            "process": c.name, "shared": True}
        return {"wall_s": round(wall_s, 3), "cores": os.cpu_count(), "processes": procs, "nodes": nodes,
                "note": "cpu_percent: of one core over the whole run, start-up included; steady_cpu_percent: from "
                        f"{self.cpu_warmup_s:g} s after the start to the stop; container nodes: handler+timer thread "
                        "CPU only, the rest of their process's cpu_s is shared (loop, decoding, async handlers, "
                        "worker threads)"}

    def write_cpu(self, path: Path, wall_s: float) -> None:
        """Write :meth:`cpu_report` as JSON to ``path`` (a failure is printed, never raised)."""
        try:
            path.write_text(json.dumps(self.cpu_report(wall_s), indent=1))
            self.print(f"[launch] per-node CPU: {path}")
        except OSError as exc:
            self.print(f"[launch] cannot write {path}: {exc}")

    def pids(self) -> list[int]:
        """PIDs of the running children."""
        return [c.proc.pid for c in self.children if c.proc is not None and c.proc.returncode is None]
