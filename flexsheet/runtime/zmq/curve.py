"""ZeroMQ CURVE security: a node's keys (:class:`CurveConfig`), the ZAP check of a publisher
(:class:`AllowList`, :func:`allow_list`) and the key files (:func:`create_curve_keypair`,
:func:`load_curve_keys`)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import zmq

__all__ = ["CurveConfig", "AllowList", "allow_list", "create_curve_keypair", "load_curve_keys"]

log = logging.getLogger(__name__)
_monotonic = time.monotonic


@dataclass
class CurveConfig:
    """ZeroMQ CURVE security for one node (RFC 26 CurveZMQ, via pyzmq's ``zmq.auth``).

    ``public_key``/``secret_key``: this host's Z85 keypair (from ``flexsheet keys generate``).
    ``server_keys``: peer endpoint → the Z85 public key its publisher must prove it owns; a peer whose
    publisher lacks that secret key fails the handshake and none of its messages arrive. ``allowed_clients``:
    Z85 public keys allowed to subscribe to this node's publisher (ZAP check); any other subscriber is
    refused. ``tool_keys``: the hosts' keys, the callers allowed a node's commanding services
    (:mod:`flexsheet.runtime.services`). ``topic_publishers``: guarded topic → the endpoints allowed to
    publish it (the launch file's ``security.publishers``, per node as SROS2 grants per participant): a
    guarded topic is received only on a SUB socket connected to those endpoints alone, each pinned to its
    node's key (:class:`~flexsheet.runtime.zmq.subscriber.SubLinks`).
    Source: pyzmq ``zmq.auth`` and ``examples/security``; SROS2 access control (``sros2/policy``).
    """

    public_key: bytes
    secret_key: bytes
    server_keys: dict[str, bytes] = field(default_factory=dict)
    allowed_clients: list[bytes] = field(default_factory=list)
    topic_publishers: dict[str, list[str]] = field(default_factory=dict)
    #: Z85 public keys of the hosts (the tools run there): the only callers a node's commanding services take
    tool_keys: list[bytes] = field(default_factory=list)


class AllowList:
    """The ZAP check of a CURVE publisher: admits the listed client keys; refusals are counted (``refused``)
    and logged at most once per :data:`LOG_EVERY_S` s with the count since the last line (a handshake flood
    wrote one warning per refusal: 1 106 lines, and the logging slowed the node)."""

    LOG_EVERY_S = 5.0

    def __init__(self, keys: list[bytes]) -> None:
        self.keys = set(keys)
        self.refused = 0
        self._logged_at = -1e9
        self._unlogged = 0

    def callback(self, domain: str, key: bytes) -> bool:
        ok = key in self.keys
        if not ok:
            self.refused += 1
            self._unlogged += 1
            now = _monotonic()
            if now - self._logged_at >= self.LOG_EVERY_S:
                log.warning("CURVE: refused %d subscriber handshake(s) with an unlisted public key since the "
                            "last line (last key %s; %d in "
                            "all)", self._unlogged, key.decode(errors="replace"),
                            self.refused)
                self._logged_at, self._unlogged = now, 0
        return ok


def allow_list(ctx: zmq.Context, curve: CurveConfig):
    """Start a ZAP authenticator on ``ctx`` that admits ``curve.allowed_clients`` (returns it and its
    list)."""
    from zmq.auth.thread import ThreadAuthenticator

    auth = ThreadAuthenticator(ctx, log=log)
    auth.start()
    allow = AllowList(curve.allowed_clients)
    auth.configure_curve_callback("*", credentials_provider=allow)
    return auth, allow


def create_curve_keypair(folder: str | Path, name: str) -> tuple[Path, Path]:
    """Write ``folder/name.key`` (public) and ``folder/name.key_secret`` (both); returns their paths."""
    import zmq.auth

    public, secret = zmq.auth.create_certificates(str(folder), name)
    return Path(public), Path(secret)


def load_curve_keys(path: str | Path) -> tuple[bytes, bytes | None]:
    """``(public, secret)`` Z85 keys of a certificate file (``secret`` is None for a public-only file).
    Raises ``OSError``/``ValueError`` for a missing or malformed file."""
    import zmq.auth

    return zmq.auth.load_certificate(str(path))

