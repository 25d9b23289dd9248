"""What a launch check (:mod:`flexsheet.runtime.launch_check`) asks of this machine about one value: an input
file (:func:`check_file_param`), an output path (:func:`output_problem`), an address (:func:`address_problem`,
:func:`not_local`, :func:`loopback`)."""

from __future__ import annotations

import concurrent.futures
import functools
import glob
import ipaddress
import os
import re
from collections.abc import Callable
from pathlib import Path

from flexsheet.runtime.extensions import extensions

__all__ = ["is_input_file_key", "check_file_param", "output_problem", "address_problem", "not_local",
           "loopback",
           "GLOB_PARAMS", "SYSTEM_DIRS", "PSEUDO_FS"]

#: params whose value is a glob pattern of input files (at least one must match)
GLOB_PARAMS = frozenset({"files_left", "files_right"})
_INPUT_NAMES = frozenset({"file", "files_csv"})
_HOSTNAME = re.compile(
    r"^(?=.{1,253}$)([A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}"
                       r"[A-Za-z0-9])?)*\.?$")
_RESOLVE_TIMEOUT_S = 2.0
#: folders whose files are the kernel's or devices, never data: an output there is refused
SYSTEM_DIRS = ("/proc", "/sys", "/dev")
#: kernel pseudo filesystems (``/proc/self/mounts`` types): an output there is refused wherever it is mounted
PSEUDO_FS = frozenset({"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "tracefs",
                       "securityfs",
                       "configfs", "fusectl", "bpf", "pstore", "mqueue", "hugetlbfs", "efivarfs",
                       "binfmt_misc",
                       "autofs", "selinuxfs", "rpc_pipefs", "nsfs"})


def is_input_file_key(key: str) -> bool:
    """True for a param that names an existing input file: ``file``, ``files_csv``, any ``*_file``, and the
    launch extensions' ``file_readers`` and ``input_params`` (the display's: ``display_calib``, ``scene``)."""
    return (key in _INPUT_NAMES or key.endswith("_file") or key in _file_readers()
            or any(key in ext.input_params for ext in extensions()))


@functools.cache
def _file_readers() -> dict[str, Callable[[str], None]]:
    """Param name → reader that raises ``ValueError``/``OSError`` for a file it cannot use (launch
    extensions)."""
    return {k: r for ext in extensions() for k, r in ext.file_readers.items()}


def check_file_param(key: str, value: str) -> str | None:
    """The problem with input-file param ``key`` = ``value`` (a path, substitutions done), or None."""
    if key in GLOB_PARAMS:
        return None if glob.glob(os.path.expanduser(value)) else "no file matches this pattern"
    path = os.path.expanduser(value)
    if not os.path.exists(path):
        return "no such file"
    if not os.path.isfile(path):
        return "not a file"
    if not os.access(path, os.R_OK):
        return "not readable"
    reader = _file_readers().get(key)
    if reader is not None:
        try:
            reader(path)
        except (ValueError, OSError) as exc:
            return "unusable: " + " ".join(str(exc).split())[:300]
    return None


def _mount_type(path: Path) -> str:
    """The filesystem type of the mount that holds ``path`` (an existing path), from ``/proc/self/mounts``
    ("" when unknown)."""
    best, kind = "", ""
    try:
        lines = Path("/proc/self/mounts").read_text().splitlines()
    except OSError:
        return ""
    target = str(path)
    for line in lines:
        f = line.split()
        if len(f) < 3:
            continue
        mnt = f[1].replace("\\040", " ")
        if (target == mnt or target.startswith(mnt.rstrip("/") + "/")) and len(mnt) > len(best):
            best, kind = mnt, f[2]
    return kind


def output_problem(value: str, kind: str) -> str | None:
    """The problem with output param value ``value`` (``kind``: "file", whose folder must be creatable, or
    "dir"), or None: it must lie in a writable data folder (not under :data:`SYSTEM_DIRS`, not on a
    :data:`PSEUDO_FS` filesystem), and an existing output file must be a regular file."""
    target = Path(os.path.realpath(os.path.expanduser(value)))
    for d in SYSTEM_DIRS:
        if target == Path(d) or str(target).startswith(d + "/"):
            return (
                f"{target} is under {d}, not a data folder (the kernel's or devices' files); write to a "
                f"folder on a disk, e.g. $(out)"
            )
    if kind == "file" and target.exists() and not target.is_file():
        return f"{target} exists and is not a regular file"
    folder = target if kind == "dir" else target.parent
    problem = _creatable(folder)
    if problem:
        return problem
    p = folder
    while not p.exists():
        p = p.parent
    fs = _mount_type(p)
    if fs in PSEUDO_FS:
        return f"{p} is on a {fs} filesystem, not a data folder; write to a folder on a disk, e.g. $(out)"
    return None


def _creatable(path: Path) -> str | None:
    p = path
    while not p.exists():
        if p.parent == p:
            return "no existing parent folder"
        p = p.parent
    if not p.is_dir():
        return f"{p} is not a folder"
    if not os.access(p, os.W_OK | os.X_OK):
        return f"folder {p} is not writable"
    return None


def _resolves(name: str) -> bool:
    import socket

    pool = concurrent.futures.ThreadPoolExecutor(1)
    try:
        return bool(pool.submit(socket.getaddrinfo, name, None).result(timeout=_RESOLVE_TIMEOUT_S))
    except (OSError, concurrent.futures.TimeoutError):
        return False
    finally:
        pool.shutdown(wait=False)


def address_problem(addr: str, resolve: bool) -> str | None:
    """Why ``addr`` cannot be a host's address (not an IP address or a host name, one that does not resolve
    here when ``resolve``, the unspecified or a multicast address), or None."""
    try:
        ip = ipaddress.ip_address(addr)
    except ValueError:
        if not _HOSTNAME.match(addr):
            return "not an IP address or a host name"
        if resolve and not _resolves(addr):
            return "is not an IP address and does not resolve on this machine"
        return None
    if ip.is_unspecified:
        return "the unspecified address: other hosts cannot connect to it; give the host's own address"
    if ip.is_multicast:
        return "a multicast address"
    return None


def not_local(addr: str) -> str | None:
    """Why no socket binds to ``addr`` on this machine (port 0), or None when one does."""
    import socket

    try:
        infos = socket.getaddrinfo(addr, 0, type=socket.SOCK_STREAM)
    except OSError as exc:
        return str(exc)
    reason = "no address"
    for family, kind, proto, _, sockaddr in infos:
        with socket.socket(family, kind, proto) as s:
            try:
                s.bind(sockaddr)
                return None
            except OSError as exc:
                reason = exc.strerror or str(exc)
    return reason


def loopback(address: str) -> bool:
    """True for a loopback IP address or ``localhost``."""
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return address == "localhost"
