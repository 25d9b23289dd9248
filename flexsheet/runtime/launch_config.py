"""What a launch file gives each process: a node's :class:`~flexsheet.runtime.config.NodeConfig`
(:func:`node_config`) and the CURVE keys of a node or of a host's tools (:func:`curve_config`, from the keys
folder and the allowed public keys, :func:`public_keys`)."""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.domain import domain_id, shift_params
from flexsheet.runtime.extensions import sections as launch_sections
from flexsheet.runtime.launch import (
    LaunchError,
    LaunchFile,
    identities,
    keygen_command,
    keys_dir,
    short_repr,
    substitute,
    substitutions,
)
from flexsheet.runtime.plugins import node_class
from flexsheet.runtime.zmq.curve import CurveConfig, load_curve_keys

__all__ = ["node_config", "curve_config", "public_keys"]


def public_keys(lf: LaunchFile) -> dict[str, str]:
    """Identity (host or node name) → Z85 public key allowed on ``lf``'s graph: ``security.public_keys``
    merged with the YAML mapping in ``security.public_keys_file``. Raises :class:`LaunchError` naming the file
    or the identity (a missing file names the ``flexsheet keys generate`` command that writes it)."""
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
            raise LaunchError(f"{where}: entry {short_repr(host)}: {short_repr(key)} is not name: <40 Z85 "
                              "characters>")
        if host in keys and keys[host] != key:
            raise LaunchError(f"{where}: host {host!r} differs from security.public_keys.{host}")
        keys[host] = key
    return keys


def curve_config(lf: LaunchFile, host: str | None, node: str | None = None) -> CurveConfig | None:
    """The :class:`CurveConfig` of ``node`` (its own keypair), else of ``host``'s tools, under ``lf``'s
    security settings (None when CURVE is off).

    ``host`` None picks the first host whose secret key is present in the keys folder (tools). Publishers are
    pinned to their nodes' keys; subscribers admitted are every identity of the file; guarded topics come from
    ``security.publishers``. Raises :class:`LaunchError` naming the missing key file or identity and the
    command that writes it.
    """
    sec = lf.security
    if not sec.curve:
        return None

    kdir = keys_dir(lf)
    keys = public_keys(lf)
    missing = [h for h in identities(lf) if h not in keys]
    if missing:
        raise LaunchError(f"{lf.path}: key 'security.public_keys': curve is on but no public key for "
                          f"{', '.join(missing)} (run: {keygen_command(lf)})")
    if node is not None:
        names = [node]
    else:
        names = [host] if host else [h for h in lf.hosts if (kdir / f"{h}.key_secret").exists()]
    if not names:
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': no <host>.key_secret in {kdir} "
                          f"(run: {keygen_command(lf)})")
    who = names[0]
    secret_file = kdir / f"{who}.key_secret"
    if not secret_file.exists():
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': no secret key for {who!r} at "
                          f"{secret_file} (run: {keygen_command(lf)}, and copy {who}.key_secret there)")
    try:
        public, secret = load_curve_keys(secret_file)
    except (OSError, ValueError) as exc:
        raise LaunchError(f"{lf.path}: key 'security.keys_dir': unreadable key file {secret_file}: "
                          f"{exc}") from None
    if secret is None or public.decode() != keys.get(who):
        raise LaunchError(f"{lf.path}: key 'security.public_keys.{who}': does not match {secret_file}")
    server_keys = {lf.endpoint_of(n): keys[n].encode() for n in lf.nodes}
    guards = {t: [lf.endpoint_of(n) for n in names] for t, names in sec.publishers.items()}
    return CurveConfig(public_key=public, secret_key=secret, server_keys=server_keys,
                       allowed_clients=[keys[k].encode() for k in identities(lf)], topic_publishers=guards,
                       tool_keys=[keys[h].encode() for h in lf.hosts if h in keys])


def node_config(lf: LaunchFile, name: str, out: str | None = None,
                overrides: dict | None = None) -> NodeConfig:
    """The :class:`NodeConfig` of node ``name`` in ``lf`` (params merged with ``overrides``, substituted).

    Graph-wide settings reach the nodes that take them: for each top-level section of a launch extension
    (:mod:`flexsheet.runtime.extensions`) whose node value is not None, a node whose ``Params`` has a field of
    that name that its params leave unset gets the value there. Raises :class:`LaunchError` (unknown node,
    CURVE keys).
    """
    if name not in lf.nodes:
        raise LaunchError(f"{lf.path}: no node named {name!r}; nodes: {', '.join(lf.nodes)}")
    spec = lf.nodes[name]
    params = shift_params(substitute({**spec.params, **(overrides or {})}, substitutions(lf, out)),
                          domain_id())
    graph_wide = {key: sec.node_value(lf.section(key), lf, out) for key, sec in launch_sections().items()}
    if any(v is not None and k not in params for k, v in graph_wide.items()):
        try:
            fields = node_class(spec.type).Params.model_fields
        except (ImportError, AttributeError, LookupError):
            fields = {}
        for key, value in graph_wide.items():
            if value is not None and key not in params and key in fields:
                params[key] = value
    return NodeConfig(name=name, node_type=spec.type, host=spec.host, endpoint=lf.endpoint_of(name),
                      peers=list(lf.endpoints().values()), params=params, remaps=spec.remaps,
                      heartbeat_period=lf.heartbeat_period, curve=curve_config(lf, spec.host, name))
