"""``flexsheet launch FILE --check [--host H]``: everything a launch needs, checked before any process starts.

One line per problem, each naming the file, the node, the key and the value; ``flexsheet launch`` runs the
same check first and starts nothing when it finds an error. What is checked:

- **structure**: the launch file itself (:func:`flexsheet.runtime.launch.load_launch`, every error);
- **params**: every node's params (with ``--set`` overrides and ``$(out)``/``$(launch_dir)`` substituted)
  against its node type's ``Params`` model (``Params.model_validate``; the node is not constructed);
- **hosts**: ``--host`` is a host of the file; every address is an IP address (not 0.0.0.0) or a name that
  resolves here; the address of each checked host (``--host``, else every host) is one of this machine's (a
  socket binds to it, port 0: its nodes could not bind their endpoints otherwise); a ``host`` param (a
  device's address) is an IP address or a valid host name. Nothing is pinged;
- **ports**: no two listening sockets on one machine (node endpoints, and the ports the launch extensions'
  device twins listen on) share a port;
- **files** named by the nodes of the checked host(s): inputs
  (:func:`~flexsheet.runtime.machine_checks.is_input_file_key`) exist and, where a launch extension knows a
  reader, parse; glob patterns match a file; output folders (:data:`OUTPUT_PARAMS` and the extensions') can be
  created and lie in a data folder: not under ``/proc``, ``/sys`` or ``/dev``, not on a kernel pseudo
  filesystem (:data:`~flexsheet.runtime.machine_checks.PSEUDO_FS`), and an output file that exists is a
  regular file;
- **extensions**: each launch extension's own rules (:mod:`flexsheet.runtime.extensions`; the display's:
:mod:`flexsheet.display.launch`);
- **CURVE keys** (``security.curve: true``): the keys folder exists, the public keys cover every host and
  node, and on each checked host ``<name>.key_secret`` of the host and of each of its nodes is there, matches
  its public key and is private (mode 0600). A missing key names the command that writes it,
  ``flexsheet keys generate --launch FILE``.

- **containers**: a player with ``mode: lockstep`` is in a container with other nodes.
- **graph**: the whole file's graph (every host) through
  :meth:`~flexsheet.runtime.graph_builder.GraphBuilder.build`: each source fits its node's clock, each
  required input has a publisher (or is ``external:``), the values two node types share agree.

Warnings (printed, not failing): CURVE off on a graph whose hosts are not all loopback; a node type that
cannot be imported on this machine for a node of another host; the nodes of one container asking for different
``nice`` or ``rt_priority`` (one process has one); a node's TCP port inside this machine's ephemeral port
range (:func:`flexsheet.runtime.ports.ephemeral_port_range`): while that node restarts, a subscriber's ZeroMQ
reconnect to the dead port can be given that same port as its own source port and connect to itself (a TCP
self-connect), and the respawned node then cannot bind (seen in CI: a renderer used all its restarts on
"Address already in use").
"""

from __future__ import annotations

import functools
import importlib.util
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from flexsheet.runtime.domain import domain_id, shift_params
from flexsheet.runtime.extensions import extensions
from flexsheet.runtime.extensions import sections as launch_sections
from flexsheet.runtime.graph_builder import GraphBuilder, GraphRefused
from flexsheet.runtime.launch import (
    LaunchError,
    LaunchFile,
    identities,
    keygen_command,
    keys_dir,
    load_launch,
    short_repr,
    substitute,
    substitutions,
)
from flexsheet.runtime.launch_config import public_keys
from flexsheet.runtime.machine_checks import (
    GLOB_PARAMS,
    address_problem,
    check_file_param,
    is_input_file_key,
    loopback,
    not_local,
    output_problem,
)
from flexsheet.runtime.plugins import node_class
from flexsheet.runtime.ports import ephemeral_port_range
from flexsheet.runtime.zmq.curve import load_curve_keys

__all__ = ["CheckResult", "check_launch", "OUTPUT_PARAMS"]

#: node type → (address param, port param) of a socket the node *listens* on besides its publisher
#: (node type, param) → "file" (a file the node writes: its folder must be creatable) or "dir"
OUTPUT_PARAMS: dict[tuple[str, str], str] = {("recorder", "output"): "file"}


@functools.cache
def _output_params() -> dict[tuple[str, str], str]:
    return {**OUTPUT_PARAMS, **{k: v for ext in extensions() for k, v in ext.output_params.items()}}


@functools.cache
def _listen_params() -> dict[str, tuple[str, str]]:
    return {k: v for ext in extensions() for k, v in ext.listen_params.items()}


@dataclass
class CheckResult:
    """What :func:`check_launch` found: ``errors`` and ``warnings`` (one line each), the hosts checked."""

    path: Path
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    hosts: list[str] = field(default_factory=list)
    nodes: int = 0

    @property
    def ok(self) -> bool:
        return not self.errors


class _Checker:
    def __init__(self, lf: LaunchFile, host: str | None, out: str | None, overrides: dict[str, dict],
                 probe: bool = False) -> None:
        self.lf, self.host, self.out, self.overrides, self.probe = lf, host, out, overrides, probe
        self.res = CheckResult(lf.path)
        self.subs = substitutions(lf, out)
        self.hosts = [host] if host else list(lf.hosts)
        self.res.hosts = self.hosts
        #: the launch extensions' values for the nodes that take them (not None), as node_config hands them on
        self.graph_wide = {k: v for k, sec in launch_sections().items()
                           if (v := sec.node_value(lf.section(k), lf, out)) is not None}
        #: each node's params as checked (overrides, substitutions, graph-wide values), for the graph check
        self.node_params: dict[str, dict] = {}

    def err(self, where: str, value: Any, msg: str) -> None:
        self.res.errors.append(f"{self.lf.path}: {where} = {short_repr(value)}: {msg}")

    def warn(self, msg: str) -> None:
        self.res.warnings.append(f"{self.lf.path}: warning: {msg}")

    def run(self) -> CheckResult:
        self.check_hosts()
        self.check_ports()
        self.check_security()
        for ext in extensions():
            if ext.check is not None:
                ext.check(self)
        self.check_report()
        self.check_nodes()
        self.check_containers()
        self.check_graph()
        self.res.errors = [_one_line(x) for x in self.res.errors]
        self.res.warnings = [_one_line(x) for x in self.res.warnings]
        return self.res

    # ---------------------------------------------------------------------------------------------- hosts
    def check_hosts(self) -> None:
        for name, spec in self.lf.hosts.items():
            problem = address_problem(spec.address, resolve=True)
            if problem:
                self.err(f"hosts.{name}.address", spec.address, problem)
            elif name in self.hosts and any(s.host == name for s in self.lf.nodes.values()):
                reason = not_local(spec.address)
                if reason:
                    self.err(f"hosts.{name}.address", spec.address,
                             f"not an address of this machine ({reason}): host {name}'s nodes cannot bind "
                             f"their endpoints here; run this on {name} itself (--host {name}), or give "
                             f"{name} this machine's address")

    # ---------------------------------------------------------------------------------------------- ports
    def _machine(self, host: str) -> str:
        """Hosts that share an address are one machine."""
        return self.lf.hosts[host].address

    def check_ports(self) -> None:
        used: dict[tuple[str, int], str] = {}
        lo, hi = ephemeral_port_range()
        ephemeral: list[str] = []

        def claim(host: str, port: int, who: str, where: str) -> None:
            key = (self._machine(host), port)
            if key in used:
                self.err(where, port, f"port {port} on host {host} is already used by {used[key]}")
            else:
                used[key] = who

        for name, spec in self.lf.nodes.items():
            ep = self.lf.endpoint_of(name)
            if ep.startswith("tcp://"):
                try:
                    port = int(ep.rsplit(":", 1)[1])
                except ValueError:
                    continue
                claim(spec.host, port, f"node {name}'s publisher ({ep})", f"node {name}: port")
                if lo <= port <= hi:
                    ephemeral.append(f"{name} ({port})")
        for name, spec in self.lf.nodes.items():
            keys = _listen_params().get(spec.type)
            if keys is None:
                continue
            port = self.params(name).get(keys[1])
            if type(port) is int and 0 < port <= 65535:
                claim(spec.host, port, f"node {name}'s {keys[1]} param", f"node {name}: params.{keys[1]}")
                if lo <= port <= hi:
                    ephemeral.append(f"{name}.{keys[1]} ({port})")
        if ephemeral:
            self.warn(f"{len(ephemeral)} listening port(s) lie in this machine's ephemeral port range "
                      f"{lo}-{hi} ({', '.join(ephemeral[:3])}{', ...' if len(ephemeral) > 3 else ''}): while "
                      "such a node restarts, a client's reconnect can take its port (TCP self-connect) and "
                      f"the node cannot bind again; set base_port (and node ports) below {lo}")

    # ---------------------------------------------------------------------------------------------- keys
    def check_security(self) -> None:
        lf, sec = self.lf, self.lf.security
        if not sec.curve:
            remote = [h for h, s in lf.hosts.items() if not loopback(s.address)]
            if remote:
                self.warn("security.curve is off: anyone who reaches "
                          f"{', '.join(lf.hosts[h].address for h in remote)} can publish on the graph (arm "
                          "targets included); see docs/deploy.md")
            return
        cmd = keygen_command(lf)
        kdir = keys_dir(lf)
        origin = "$FLEXSHEET_KEYS" if os.environ.get("FLEXSHEET_KEYS") else "security.keys_dir"
        if not kdir.is_dir():
            self.err(origin, str(kdir), "no keys folder: CURVE is on and no keys were generated (run: "
                                        f"{cmd})")
            return
        try:
            keys = public_keys(lf)
        except LaunchError as exc:
            self.res.errors.append(str(exc))
            return
        missing = [h for h in identities(lf) if h not in keys]
        if missing:
            self.err("security.public_keys", sorted(keys), f"no public key for {', '.join(missing)} "
                                                          f"(run: {cmd})")

        for h in self.hosts:
            for who in identities(lf, h):
                secret = kdir / f"{who}.key_secret"
                if not secret.is_file():
                    self.err(origin, str(kdir), f"no secret key for {who} on host {h} ({secret.name}; run: "
                                                f"{cmd}, then copy {secret.name} and public_keys.yaml to "
                                                f"{h}'s keys folder)")
                    continue
                try:
                    public, secret_key = load_curve_keys(secret)
                except (OSError, ValueError) as exc:
                    self.err(origin, str(secret), f"unreadable secret key of {who}: {exc}")
                    continue
                if secret_key is None:
                    self.err(origin, str(secret), f"{secret.name} holds no secret key (run: {cmd} --force "
                                                  f"{who})")
                elif who in keys and public.decode() != keys[who]:
                    self.err(f"security.public_keys.{who}", keys[who],
                             f"does not match {secret} (keys generated "
                             f"twice? copy the newest public_keys.yaml)")
                mode = stat.S_IMODE(secret.stat().st_mode)
                if mode & 0o077:
                    self.err(origin, str(secret), f"secret key readable by others (mode {mode:o}); run: "
                                                  f"chmod 600 {secret}")

    # ---------------------------------------------------------------------------------------------- files
    def file_problem(self, key: str, value: str) -> str | None:
        """The problem with input file ``value`` of param ``key`` (:func:`check_file_param`), or None."""
        return check_file_param(key, value)

    def check_report(self) -> None:
        report = self.lf.report
        if report is None:
            return
        module, sep, attr = report.partition(":")
        try:
            found = bool(sep and attr and module and importlib.util.find_spec(module) is not None)
        except (ImportError, ValueError):
            found = False
        if not found:
            self.err("report", report, "no such 'module:function' (the report runs after the launch)")

    def params(self, name: str) -> dict:
        """Node ``name``'s params with the ``--set`` overrides and substitutions applied."""
        spec = self.lf.nodes[name]
        return shift_params(substitute({**spec.params, **self.overrides.get(name, {})}, self.subs),
                            domain_id())

    def check_nodes(self) -> None:
        for name in self.overrides:
            if name not in self.lf.nodes:
                self.err("--set", name, f"no such node; nodes: {', '.join(self.lf.nodes)}")
        for name, spec in self.lf.nodes.items():
            here = spec.host in self.hosts
            self.res.nodes += here
            params = self.params(name)
            where = f"node {name}"
            try:
                cls = node_class(spec.type)
                model: type[BaseModel] = cls.Params
            except (ImportError, AttributeError) as exc:
                msg = f"node type {spec.type} cannot be imported here: {' '.join(str(exc).split())[:200]}"
                if here:
                    self.err(f"{where}: type", spec.type, msg)
                else:
                    self.warn(f"node {name} (host {spec.host}): {msg}; its params are not checked")
                continue
            # graph-wide values, as node_config fills them in; each file is checked once, by its extension
            injected = {k for k in self.graph_wide if k in model.model_fields and k not in params}
            params.update({k: self.graph_wide[k] for k in injected})
            self.node_params[name] = dict(params)
            # a graph-wide value its extension already refused (a
            # missing scene file) is one error, not one per node
            bad = [str(self.graph_wide[k]) for k in injected
                   if any(line.startswith(f"{self.lf.path}: {k} = ") for line in self.res.errors)]
            try:
                validated = model.model_validate(params)
                if self.probe and here:         # the devices the node names, asked on this machine
                    for line in cls.probe(validated):
                        self.res.errors.append(f"{self.lf.path}: {where}: probe: {line}")
            except ValidationError as exc:
                for e in exc.errors():
                    key = ".".join(str(p) for p in e["loc"])
                    if any(v in e["msg"] or v == e.get("input") for v in bad):
                        continue
                    if not key:  # a check across params (a model validator): the message names them
                        self.res.errors.append(f"{self.lf.path}: {where}: params: {e['msg'][:300]}")
                    elif e["type"] == "extra_forbidden":
                        known = ", ".join(model.model_fields)
                        self.err(f"{where}: params.{key}", e.get("input"),
                                 f"not a parameter of node type {spec.type} (its params: {known[:400]})")
                    elif e["type"] == "missing":
                        self.res.errors.append(f"{self.lf.path}: {where}: params.{key}: required, not given")
                    else:
                        self.err(f"{where}: params.{key}", e.get("input"), e["msg"][:300])
            for key, value in params.items():
                if key == "host" and isinstance(value, str):
                    problem = address_problem(value, resolve=False)
                    if problem:
                        self.err(f"{where}: params.host", value, problem)
                if not here or not isinstance(value, str) or not value or key in injected:
                    continue
                kind = _output_params().get((spec.type, key))
                if kind is not None:
                    problem = output_problem(value, kind)
                    if problem:
                        self.err(f"{where}: params.{key}", value, f"cannot write here: {problem}")
                elif is_input_file_key(key) or key in GLOB_PARAMS:
                    problem = check_file_param(key, value)
                    if problem:
                        self.err(f"{where}: params.{key}", value, problem)


    # --------------------------------------------------------------------------------------------- containers
    def check_containers(self) -> None:
        """A lockstep player must share a container with the nodes it drives; the members of one container
        share one niceness and RT priority (warned when they ask for different ones)."""
        groups: dict[tuple[str, str], list[str]] = {}
        for name, spec in self.lf.nodes.items():
            if spec.container is not None and spec.host in self.hosts:
                groups.setdefault((spec.container, spec.host), []).append(name)
            if (spec.type == "player" and spec.host in self.hosts
                and self.params(name).get("mode") == "lockstep"):
                if spec.container is None:
                    self.err(f"node {name}: params.mode", "lockstep", "a lockstep player must be in a "
                             "container with the nodes it drives: give it and them 'container: NAME' "
                             "(docs/realtime.md)")
                elif len([n for n, s in self.lf.nodes.items() if s.container == spec.container
                          and s.host == spec.host]) < 2:
                    self.err(f"node {name}: container", spec.container,
                             "a lockstep player drives only the nodes "
                             "of its container, and this container holds no other node")
        for (cname, host), names in groups.items():
            specs = [self.lf.nodes[n] for n in names]
            for key, pick in (("nice", min), ("rt_priority", max)):
                values = {n: getattr(s, key) for n, s in zip(names, specs, strict=True)}
                if len(set(values.values())) > 1:
                    self.warn(f"container {cname} on host {host}: its nodes ask for different {key} "
                              f"({', '.join(f'{n}={v}' for n, v in values.items())}); one process runs at "
                              f"{key} {pick(values.values())}")


    # -------------------------------------------------------------------------------------------------- graph
    def check_graph(self) -> None:
        """The whole file's graph (every host) through :meth:`GraphBuilder.build`: a source that does not fit
        the clock, a required input no node publishes, a shared value two nodes disagree on. Its type and
        params problems are :meth:`check_nodes`' already."""
        builder = GraphBuilder.from_launch(self.lf, lambda n: self.node_params.get(n, self.params(n)))
        try:
            builder.build()
        except GraphRefused as refused:
            self.res.errors += [f"{self.lf.path}: {p.line}" for p in refused.problems
                                if p.kind not in ("type", "params")]


def _one_line(text: str) -> str:
    """``text`` with every non-printable character escaped as Python writes it (a param key or value may hold
    a newline: ``params: {"\\n": null}``, found by tests/unit/runtime/test_launch_check.py), so one problem is
             one line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def check_launch(path: str | Path, host: str | None = None, out: str | None = None,
                 overrides: dict[str, dict] | None = None, probe: bool = False) -> CheckResult:
    """Check launch file ``path`` for ``host`` (None: every host, all on this machine) with ``--out`` folder
    ``out`` and ``overrides`` (node → {param: value}, the ``--set`` values); with ``probe`` also ask each of
    the host's nodes whether the devices it names are there (:meth:`flexsheet.runtime.node.Node.probe`).
    Returns a :class:`CheckResult`; never raises for a bad file (its problems are the result's ``errors``)."""
    try:
        lf = load_launch(path)
    except LaunchError as exc:
        return CheckResult(Path(path), errors=exc.lines)
    if host is not None and host not in lf.hosts:
        return CheckResult(lf.path, errors=[f"{lf.path}: --host = {host!r}: not a host of the file; hosts: "
                                            f"{', '.join(lf.hosts)}"])
    return _Checker(lf, host, out, overrides or {}, probe).run()
