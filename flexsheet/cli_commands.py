"""The ``flexsheet`` commands that run nodes: ``run`` (one node, or a container of several), ``launch`` (a
launch file's graph) and ``keys`` (CURVE key pairs). The parsers and the dispatch are :mod:`flexsheet.cli`."""

from __future__ import annotations

import argparse
import asyncio
import inspect
import json
import logging
import os
import sys
import time
from pathlib import Path

import yaml

from flexsheet import registry
from flexsheet.runtime.plugins import node_class, node_types, unknown_node_type

__all__ = ["cmd_run", "cmd_launch", "cmd_keys", "parse_params", "setup_logging"]


def parse_params(items: list[str]) -> dict:
    """``--param key=value`` items → {key: YAML value}; exits with one line naming a malformed item."""
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"flexsheet: --param expects key=value, got {item!r}")
        params[key] = yaml.safe_load(value) if value else ""
    return params


def setup_logging(name: str = "") -> None:
    """Log INFO (or ``$FLEXSHEET_LOG``) and above on stdout, each line with its level and logger."""
    logging.basicConfig(level=os.environ.get("FLEXSHEET_LOG", "INFO"),
                        format="%(levelname)s %(name)s: %(message)s", stream=sys.stdout)


# ----------------------------------------------------------------------------------------------- run
def cmd_run(args: argparse.Namespace) -> int:
    """Run one node. Exit status: 0 after a clean stop, 1 on a transport error, 2 for an unknown node type,
    :data:`~flexsheet.runtime.config.EXIT_CONFIG` (78) for a configuration error (a bad param, a launch-file
    or key problem, a ``ValueError`` from the node's setup): the launcher does not respawn those."""
    from pydantic import ValidationError

    from flexsheet.runtime.config import EXIT_CONFIG, ConfigError, NodeConfig
    from flexsheet.runtime.launch import LaunchError, load_launch
    from flexsheet.runtime.launch_config import node_config

    if args.container:
        return _run_container(args)
    if args.node_type is None:
        print("flexsheet run: give a node type (or --container NAME --launch FILE)", file=sys.stderr)
        return 2
    if args.node_type not in node_types():
        print(f"flexsheet run: {unknown_node_type(args.node_type)}", file=sys.stderr)
        return 2
    overrides = parse_params(args.param)
    if args.launch:
        try:
            lf = load_launch(args.launch)
            config = node_config(lf, args.name or args.node_type, out=args.out, overrides=overrides)
        except LaunchError as exc:
            print(f"flexsheet run: configuration error: {exc}", file=sys.stderr)
            return EXIT_CONFIG
    else:
        config = NodeConfig(name=args.name or args.node_type, node_type=args.node_type,
                            endpoint=args.endpoint,
                            peers=args.peer or [], params=overrides)
    setup_logging()
    cls = node_class(args.node_type)
    try:
        node = cls(config)
    except ValidationError as exc:
        for err in exc.errors():
            print(f"flexsheet run {config.name}: configuration error: param '{'.'.join(map(str, err['loc']))}"
                  f"': {err['msg']} (value {err.get('input')!r:.200})", file=sys.stderr)
        return EXIT_CONFIG
    from flexsheet.runtime.transport import TransportError
    try:
        asyncio.run(node.run())
    except ConfigError as exc:
        print(f"flexsheet run {config.name}: configuration error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    except TransportError as exc:   # an endpoint that cannot be bound or connected: not fixed by a restart
        print(f"flexsheet run {config.name}: configuration error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    return 0


def _run_container(args: argparse.Namespace) -> int:
    """``flexsheet run --container NAME --launch FILE [--host H] [--set NODE.KEY=VALUE]``: the nodes of one
    composable container in this process (:mod:`flexsheet.runtime.container`)."""
    from flexsheet.runtime.config import EXIT_CONFIG
    from flexsheet.runtime.console import show_lines
    from flexsheet.runtime.container import run_container

    if not args.launch:
        print("flexsheet run --container: needs --launch FILE (the container's nodes come from "
              "it)", file=sys.stderr)
        return EXIT_CONFIG
    if args.node_type or args.param:
        print("flexsheet run --container: give node params as --set NODE.KEY=VALUE, not a node type or "
              "--param",
              file=sys.stderr)
        return 2
    overrides: dict[str, dict] = {}
    for item in args.set or []:
        node, dot, kv = item.partition(".")
        if not dot or "=" not in kv:
            print(f"flexsheet run --container: --set {item!r}: expected NODE.KEY=VALUE", file=sys.stderr)
            return EXIT_CONFIG
        overrides.setdefault(node, {}).update(parse_params([kv]))
    setup_logging()
    show_lines()   # the container's own lines, bare (the launcher prefixes them)
    return run_container(args.launch, args.container, host=args.host, out=args.out, overrides=overrides,
                         sim_until=args.sim_duration)


# ----------------------------------------------------------------------------------------------- launch
def cmd_launch(args: argparse.Namespace) -> int:
    """Check the launch file for this host (every error one line on stderr, exit 78 when any), then, unless
    ``--check``, run its nodes under the :class:`~flexsheet.runtime.supervisor.Supervisor`."""
    from flexsheet.runtime.config import EXIT_CONFIG
    from flexsheet.runtime.console import show_lines
    from flexsheet.runtime.extensions import extensions
    from flexsheet.runtime.launch import TOPLEVEL_ENV, LaunchError, load_launch
    from flexsheet.runtime.launch_check import check_launch
    from flexsheet.runtime.launch_sets import parse_toplevel_set, split_sets
    from flexsheet.runtime.supervisor import Supervisor

    out = str(Path(args.out).resolve()) if args.out else None
    show_lines()   # the launcher's lines, its extensions' (a twin registration) and the nodes' output, bare
    try:
        node_names = set(load_launch(args.file).nodes)
        toplevel, parsed = split_sets(args.set, node_names)
        overrides: dict[str, list[str]] = {}     # the node items as written: each node process parses its own
        for item in args.set:
            if parse_toplevel_set(item, node_names) is None:
                node, _, kv = item.partition(".")
                overrides.setdefault(node, []).append(kv)
        if args.rtf is not None:
            toplevel["rtf"] = args.rtf
        if toplevel:  # the launcher's own load_launch and every node process read these (launch.TOPLEVEL_ENV)
            os.environ[TOPLEVEL_ENV] = json.dumps(toplevel)
        lf = load_launch(args.file)
        for ext in extensions():   # e.g. the display's twin registration (flexsheet.display.launch)
            if ext.before_launch is None:
                continue
            extra = ext.before_launch(lf, args.check)
            if extra:
                toplevel.update(extra)
                os.environ[TOPLEVEL_ENV] = json.dumps(toplevel)
    except LaunchError as exc:
        for line in exc.lines or [str(exc)]:   # a line that names the file already is not prefixed again
            named = line.startswith(f"{args.file}:") or line.startswith(f"{Path(args.file)}:")
            print(f"flexsheet launch: {line}" if named else f"flexsheet launch: {args.file}: "
                                                            f"{line}", file=sys.stderr)
        return EXIT_CONFIG
    result = check_launch(args.file, host=args.host, out=out, overrides=parsed, probe=args.probe)
    for line in result.warnings:
        print(line, file=sys.stderr)
    for line in result.errors:
        print(line, file=sys.stderr)
    what = f"host {args.host}" if args.host else f"all hosts ({', '.join(result.hosts)})"
    if args.check and args.json:        # one JSON document on stdout (the lines stay on stderr), same status
        print(
            json.dumps({"file": str(args.file), "hosts": result.hosts, "nodes": result.nodes,
                        "ok": not result.errors,
                        "errors": result.errors, "warnings": result.warnings}))
        return EXIT_CONFIG if result.errors else 0
    if result.errors:
        print(f"flexsheet launch: {len(result.errors)} error(s) in {args.file} for {what}; nothing started",
              file=sys.stderr)
        return EXIT_CONFIG
    if args.check:
        print(f"{args.file}: OK for {what}: {result.nodes} node(s); params, hosts, ports, files, keys "
              "and the graph checked")
        return 0
    try:
        lf = load_launch(args.file)
        if out:
            Path(out).mkdir(parents=True, exist_ok=True)
        sup = Supervisor(lf, host=args.host, out=out, duration=args.duration, overrides=overrides)
    except (LaunchError, OSError) as exc:
        print(f"flexsheet launch: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    started = time.time()
    code = asyncio.run(sup.run())
    if lf.report and out and args.host in (None, "main", next(iter(lf.hosts))):
        report = registry.load(lf.report)
        # a report that takes ``since`` reads only this run's
        # files (a reused --out folder keeps earlier runs')
        kw = {"since": started - 1.0} if "since" in inspect.signature(report).parameters else {}
        code = max(code, int(report(out, lf, **kw) or 0))
    return code


# ----------------------------------------------------------------------------------------------- table
def cmd_keys(args: argparse.Namespace) -> int:
    from flexsheet.runtime.keys import PUBLIC_KEYS_FILE, default_keys_dir, generate
    from flexsheet.runtime.launch import LaunchError, identities, load_launch

    folder = Path(os.path.expanduser(args.output)) if args.output else default_keys_dir()
    try:
        lf = load_launch(args.launch)
    except LaunchError as exc:
        print(f"flexsheet keys: {exc}", file=sys.stderr)
        return 2
    known = identities(lf)
    unknown = [n for n in args.names if n not in known]
    if unknown:
        print(f"flexsheet keys: {unknown[0]!r} is no host or node of {args.launch} (hosts: "
              f"{', '.join(lf.hosts)}; nodes: {', '.join(lf.nodes)})", file=sys.stderr)
        return 2
    try:
        status = generate(args.names or known, folder, force=args.force)
    except (ValueError, OSError) as exc:
        print(f"flexsheet keys: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({"folder": str(folder), "public_keys": str(folder / PUBLIC_KEYS_FILE),
                          "keys": {n: {"status": w, "secret": str(folder / (n + ".key_secret"))}
                                   for n, w in status.items()},
                          "hosts": {h: [str(folder / (n + ".key_secret")) for n in identities(lf, h)]
                                    for h in lf.hosts}}))
        return 0
    for name, what in status.items():
        print(f"{name}: "
              f"{'new keypair' if what == 'new' else 'kept the existing keypair (--force to replace)'}: "
              f"{folder / (name + '.key_secret')}")
    print(f"public keys of all hosts and nodes: {folder / PUBLIC_KEYS_FILE}")
    print("Each host needs public_keys.yaml and the secret keys of itself and its nodes in its keys folder "
          "(never another host's), e.g.:")
    for host in list(lf.hosts)[1:4]:
        files = " ".join(str(folder / (n + ".key_secret")) for n in identities(lf, host))
        print(f"  ssh {host} 'mkdir -p -m 700 ~/.flexsheet/keys' && scp -p {files} "
              f"{folder / PUBLIC_KEYS_FILE} {host}:.flexsheet/keys/")
    if folder != default_keys_dir():
        print(f"launch files find them with: export FLEXSHEET_KEYS={folder}")
    return 0
