"""CURVE keys for a launch graph: ``flexsheet keys generate --launch launch/lab.yaml``.

Writes, into the keys folder (``-o``, else ``$FLEXSHEET_KEYS``, else ``~/.flexsheet/keys``; mode 0700):

- ``<name>.key`` (public) and ``<name>.key_secret`` (mode 0600) for each identity of the launch file: every
  node (its publisher and subscribers prove it) and every host (the tools run there), ZeroMQ's certificate
  format (``zmq.auth.create_certificates``);
- ``public_keys.yaml``: name → Z85 public key for every identity of the folder, the file a launch file names
  with ``security: {curve: true, public_keys_file: $(keys)/public_keys.yaml}`` (as ``launch/lab.yaml``
  does), so no key is pasted into a launch file.

An identity whose secret key already exists keeps it (a second run must not lock out a deployed arm PC);
``--force`` makes new ones. Each host needs only its own and its nodes' ``<name>.key_secret`` and
``public_keys.yaml``. Errors: ``ValueError`` naming the identity or file.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import yaml

from flexsheet.runtime.launch import DEFAULT_KEYS_DIR, PUBLIC_KEYS_FILE
from flexsheet.runtime.zmq.curve import create_curve_keypair, load_curve_keys

__all__ = ["default_keys_dir", "generate", "read_public_keys"]

_HOST = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,62}$")


def default_keys_dir() -> Path:
    """``$FLEXSHEET_KEYS``, else ``~/.flexsheet/keys`` (expanded; need not exist)."""
    return Path(os.path.expanduser(os.environ.get("FLEXSHEET_KEYS") or DEFAULT_KEYS_DIR))


def read_public_keys(path: Path) -> dict[str, str]:
    """The host → Z85 public key mapping of ``path`` ({} when it does not exist). Raises ``ValueError``."""
    if not path.exists():
        return {}
    raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    if raw is None:
        return {}
    if (not isinstance(raw, dict)
        or not all(isinstance(k, str) and isinstance(v, str) for k, v in raw.items())):
        raise ValueError(f"{path}: not a mapping host: public key")
    return raw


def generate(hosts: list[str], folder: Path, force: bool = False) -> dict[str, str]:
    """Make (or keep) the keypair of each identity (node or host name) in ``folder`` and rewrite
    ``folder/public_keys.yaml``.

    Returns name → ``"new"`` or ``"kept"``. Raises ``ValueError`` for a name that is not a plain name
    (letters, digits, ``_.-``) or an unreadable existing key file.
    """
    for host in hosts:
        if not _HOST.match(host):
            raise ValueError(f"name {host!r}: use letters, digits, '_', '.', '-' (a host or node of the "
                             "launch file)")
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    status: dict[str, str] = {}
    for host in dict.fromkeys(hosts):
        secret_file = folder / f"{host}.key_secret"
        if secret_file.exists() and not force:
            status[host] = "kept"
            continue
        for f in (secret_file, folder / f"{host}.key"):
            f.unlink(missing_ok=True)
        _, secret_file = create_curve_keypair(folder, host)
        os.chmod(secret_file, 0o600)
        status[host] = "new"
    keys = read_public_keys(folder / PUBLIC_KEYS_FILE)
    for host in status:
        try:
            public, _ = load_curve_keys(folder / f"{host}.key_secret")
        except (OSError, ValueError) as exc:
            raise ValueError(f"{folder / f'{host}.key_secret'}: unreadable ({exc}); use --force to replace "
                             "it") \
                from None
        keys[host] = public.decode()
    text = ("# CURVE public keys of the launch graph's hosts and nodes, written by `flexsheet keys "
            "generate`.\n# Launch files name it: security: {curve: true, public_keys_file: "
            "$(keys)/public_keys.yaml}\n"
            + yaml.safe_dump(keys, sort_keys=False))
    tmp = folder / (PUBLIC_KEYS_FILE + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, folder / PUBLIC_KEYS_FILE)
    return status
