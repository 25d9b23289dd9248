"""One disk cache for every precomputed FEM array set (capacitance matrices, corotational table, nonlinear
snapshots, reference solutions). Pure: numpy ``.npz`` files, no pickles.

A cache entry is ``<cache_dir>/<kind>_<key>.npz`` where ``key`` is the first 24 hex digits of the SHA-256 of
the *parts* that determine its content (mesh spec, gmsh version, material, finger radius, solver parameters, a
version string). Writes are atomic (temporary file + ``os.replace``), so a crash or a concurrent writer never
leaves a half-written entry; an unreadable entry is reported and recomputed.

``cache_dir`` defaults to :data:`DEFAULT_CACHE_DIR`, the user's cache folder (``~/.cache/flexsheet/fem`` on
Linux, :mod:`flexsheet.dirs`). Also searched, read-only, after ``cache_dir``: ``flexsheet/fem/data/`` (entries
shipped with the repository), then :data:`INSTALL_DIRS` (``fem/`` of each install-time data folder of
:func:`flexsheet.dirs.data_dirs`: what the installer precomputed for the shipped launch files and scenes,
``python3 -m nodes.fem.warm``, into :data:`INSTALL_DIR`), so a fresh ``HOME`` starts without precomputing.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from collections.abc import Callable

import numpy as np
import platformdirs

from flexsheet.dirs import APP, data_dirs, install_data_dir
from flexsheet.manifest import record

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_CACHE_DIR", "SHIPPED_DIR", "INSTALL_DIR", "INSTALL_DIRS", "cache_key", "ArrayCache"]

#: the user's FEM cache (not moved by ``$FLEXSHEET_CACHE``:
#: a graph started with it still finds its models here)
DEFAULT_CACHE_DIR = os.path.join(platformdirs.user_cache_dir(APP), "fem")
SHIPPED_DIR = os.path.join(os.path.dirname(__file__), "data")
#: where the installer's warm-up writes (the machine's data folder as root, else the user's)
INSTALL_DIR = os.path.join(install_data_dir(), "fem")
#: the install-time folders every cache searches read-only, in order
INSTALL_DIRS = tuple(os.path.join(d, "fem") for d in data_dirs())


def cache_key(*parts) -> str:
    """24-hex-digit SHA-256 key of ``parts`` (their ``str()`` joined by "|"; floats as ``repr``)."""
    text = "|".join(repr(p) if isinstance(p, float) else str(p) for p in parts)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


class ArrayCache:
    """Named array sets on disk. ``cache_dir`` None or "" disables writing (and reading from it);
    ``shipped_dir`` the read-only store searched after it (default :data:`SHIPPED_DIR`; None: none); what it
    does is logged (INFO; a cache it cannot use, WARNING). ``kind`` must be a simple word (letters, digits,
    _)."""

    def __init__(self, cache_dir: str | None, shipped_dir: str | None = ""):
        self.cache_dir = cache_dir or None
        # "" (the default): the module's SHIPPED_DIR as it is now (tests point it elsewhere); None: none
        self.shipped_dir = SHIPPED_DIR if shipped_dir == "" else shipped_dir
        self.install_dirs = INSTALL_DIRS if shipped_dir == "" else ()   # the installer's precomputed entries
        #: the file the last successful :meth:`load` read (in ``cache_dir`` or ``shipped_dir``), else None
        self.source: str | None = None

    @staticmethod
    def _name(kind: str, key: str) -> str:
        if not kind.replace("_", "").isalnum():
            raise ValueError(f"cache kind must be letters, digits and '_', got {kind!r}")
        return f"{kind}_{key}.npz"

    def path(self, kind: str, key: str) -> str | None:
        """Where the entry is written (None when the cache is disabled)."""
        return os.path.join(self.cache_dir, self._name(kind, key)) if self.cache_dir else None

    def load(self, kind: str, key: str) -> dict[str, np.ndarray] | None:
        """The stored arrays, or None when absent or unreadable (logged)."""
        name = self._name(kind, key)
        for d in (self.cache_dir, self.shipped_dir, *self.install_dirs):
            if not d:
                continue
            p = os.path.join(d, name)
            if not os.path.exists(p):
                continue
            try:
                with np.load(p, allow_pickle=False) as z:
                    out = {k: z[k] for k in z.files}
                self.source = p
                return out
            except (OSError, ValueError, KeyError) as exc:
                log.warning(f"fem: cache {p} unusable ({exc}); recomputing")
        return None

    def shipped(self) -> bool:
        """Whether the last successful :meth:`load` read the read-only shipped store (``flexsheet/fem/data/``)
        rather than this machine's cache."""
        return bool(self.source and self.shipped_dir
                    and os.path.dirname(os.path.abspath(self.source)) == os.path.abspath(self.shipped_dir))

    def save(self, kind: str, key: str, arrays: dict[str, np.ndarray]) -> str | None:
        """Store ``arrays`` atomically; returns the path, or None when disabled or the write failed
        (logged)."""
        p = self.path(kind, key)
        if p is None:
            return None
        tmp = f"{p}.{os.getpid()}.tmp.npz"
        try:
            os.makedirs(self.cache_dir, exist_ok=True)
            np.savez(tmp, **arrays)
            os.replace(tmp, p)
            return p
        except OSError as exc:
            log.warning(f"fem: could not write cache {p}: {exc}")
            try:
                os.remove(tmp)
            except OSError:
                pass
            return None

    def ship(self, kind: str, key: str, arrays: dict[str, np.ndarray]) -> str:
        """Write an entry into ``shipped_dir`` (the repository's read-only store, ``flexsheet/fem/data/``),
        zlib compressed (``numpy.savez_compressed``), atomically; returns its path. For entries a fresh
        machine should not have to compute (the FEM node's snapshot table: hours of CPU), entered in the
        folder's manifest (:func:`flexsheet.manifest.record`, which deletes an older table of the same kind).
        Raises ``ValueError`` when there is no shipped directory, ``OSError`` when it cannot be written."""
        if not self.shipped_dir:
            raise ValueError("this cache has no shipped directory to write into")
        os.makedirs(self.shipped_dir, exist_ok=True)
        p = os.path.join(self.shipped_dir, self._name(kind, key))
        if os.path.exists(p):  # the same arrays again: keep the file (a zip's bytes carry its write time)
            try:
                with np.load(p, allow_pickle=False) as z:
                    if set(z.files) == set(arrays) and all(
                            np.asarray(arrays[k]).dtype == z[k].dtype and np.array_equal(arrays[k], z[k])
                            for k in z.files):
                        return p
            except (OSError, ValueError):
                pass
        tmp = f"{p}.{os.getpid()}.tmp.npz"
        try:
            np.savez_compressed(tmp, **arrays)
            os.replace(tmp, p)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        # one table per kind, except the path tables (one per scene): the old version is deleted, not kept
        record(p, replaces=None if kind == "pathsnap" else f"{kind}_")
        return p

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], dict[str, np.ndarray]],
                       what: str = "") -> tuple[dict[str, np.ndarray], bool, float]:
        """(arrays, hit, seconds): load the entry or run ``compute()`` and store its result."""
        t = time.perf_counter()
        z = self.load(kind, key)
        if z is not None:
            where = f"the shipped store {self.shipped_dir}" if self.shipped() else "cache"
            log.info(f"fem: {what or kind} loaded from {where} ({kind}_{key})")
            return z, True, time.perf_counter() - t
        z = compute()
        self.save(kind, key, z)
        return z, False, time.perf_counter() - t
