"""Manifests of the shipped data tables (``flexsheet/fem/data/``, ``flexsheet/model/sheet_tables/``): for each
file its cache key, SHA-256, size in bytes and the command that wrote it, in ``MANIFEST.json`` beside them.
A table is replaced, not added beside its old version: :func:`record` drops the entries of the same kind."""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import sys
from pathlib import Path

__all__ = ["MANIFEST", "record", "verify", "sha256_of"]

MANIFEST = "MANIFEST.json"


def sha256_of(path: str | Path) -> str:
    """Hex SHA-256 of the file at ``path``. Raises ``OSError`` when it cannot be read."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read(folder: Path) -> dict:
    p = folder / MANIFEST
    return json.loads(p.read_text()) if p.is_file() else {}


def record(path: str | Path, command: str | None = None, replaces: str | None = None) -> dict:
    """Enter the table at ``path`` (``<kind>_<key>.npz``) in its folder's manifest; with ``replaces`` (a file
    name prefix such as ``"snapshots_"``), first delete the older files of that prefix and their entries.
    ``command``: what wrote it (default: this process's command line). Returns the entry."""
    path = Path(path)
    folder = path.parent
    entries = _read(folder)
    if replaces:
        for name in [n for n in entries if n.startswith(replaces) and n != path.name]:
            (folder / name).unlink(missing_ok=True)
            del entries[name]
    kind, _, key = path.stem.partition("_")
    entries[path.name] = {"kind": kind, "key": key, "sha256": sha256_of(path), "size": path.stat().st_size,
                          "command": command
                          or " ".join(shlex.quote(a) for a in ["flexsheet", *sys.argv[1:]])}
    tmp = folder / f"{MANIFEST}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(dict(sorted(entries.items())), indent=1) + "\n")
    os.replace(tmp, folder / MANIFEST)
    return entries[path.name]


def verify(folder: str | Path) -> list[str]:
    """Problems with the shipped tables in ``folder``: a file not in the manifest, an entry without its file,
    or a size or SHA-256 that differs. Empty when all is well."""
    folder = Path(folder)
    entries = _read(folder)
    problems = []
    files = {p.name for p in folder.glob("*.npz")}
    for name in sorted(files - set(entries)):
        problems.append(f"{folder / name}: not in {MANIFEST}")
    for name, e in sorted(entries.items()):
        p = folder / name
        if name not in files:
            problems.append(f"{p}: in {MANIFEST} but missing")
        elif p.stat().st_size != e["size"]:
            problems.append(f"{p}: size {p.stat().st_size} B, manifest says {e['size']} B")
        elif sha256_of(p) != e["sha256"]:
            problems.append(f"{p}: SHA-256 differs from {MANIFEST}")
    return problems
