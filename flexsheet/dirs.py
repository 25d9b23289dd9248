"""Where flexsheet keeps what it computes (platformdirs): the user's cache, and the install-time data that the
installer precomputes (``python3 -m nodes.fem.warm``), never inside the installed package.

* :func:`cache_root`: ``$FLEXSHEET_CACHE``, else the user's cache folder (Linux: ``~/.cache/flexsheet``, or
``$XDG_CACHE_HOME/flexsheet``);
* :func:`data_dirs`: the install-time data folders, searched read-only in this order: ``$FLEXSHEET_DATA`` if
  set, the user's data folder (Linux: ``~/.local/share/flexsheet``), the machine's
  (``/usr/local/share/flexsheet``, the first of ``$XDG_DATA_DIRS``);
* :func:`install_data_dir`: where an installer writes: ``$FLEXSHEET_DATA``, else the machine's folder when
  this user may write there (root, the image's build), else the user's;
* :func:`launch_dir`: the launch files and shipped scenes (``launch/``): the checkout's, else the current
  folder's (a non-editable install, e.g. the image's ``/opt/flexsheet/launch``).
"""

from __future__ import annotations

import os
from pathlib import Path

import platformdirs

__all__ = ["APP", "cache_root", "data_dirs", "install_data_dir", "launch_dir"]

APP = "flexsheet"


def cache_root() -> str:
    """The cache folder (absolute path, str): ``$FLEXSHEET_CACHE`` or the user's cache folder for
    flexsheet."""
    return os.path.abspath(os.path.expanduser(os.environ.get("FLEXSHEET_CACHE")
                                              or platformdirs.user_cache_dir(APP)))


def data_dirs() -> list[str]:
    """The install-time data folders (absolute paths), most specific first, without repeats (module
    docstring)."""
    dirs = [os.environ.get("FLEXSHEET_DATA") or "", platformdirs.user_data_dir(APP),
            platformdirs.site_data_dir(APP)]
    return list(dict.fromkeys(os.path.abspath(os.path.expanduser(d)) for d in dirs if d))


def _writable(path: str) -> bool:
    """True if ``path`` exists and is writable, or could be created by this user (its nearest existing
    parent)."""
    p = path
    while not os.path.exists(p):
        parent = os.path.dirname(p)
        if parent == p:
            return False
        p = parent
    return os.access(p, os.W_OK)


def install_data_dir() -> str:
    """Where an installer writes its data (absolute path): ``$FLEXSHEET_DATA``, else the machine's data folder
    if writable, else the user's."""
    if os.environ.get("FLEXSHEET_DATA"):
        return os.path.abspath(os.path.expanduser(os.environ["FLEXSHEET_DATA"]))
    site = os.path.abspath(platformdirs.site_data_dir(APP))
    return site if _writable(site) else os.path.abspath(platformdirs.user_data_dir(APP))


#: the checkout this package lives in (an installed package: its site-packages, which has no launch/)
_CHECKOUT = Path(__file__).resolve().parents[1]


def launch_dir() -> Path:
    """The folder of the launch files and shipped scenes (absolute ``Path`` to a ``launch/``): the checkout's
    when this package runs from a checkout (editable or ``python -m``), else ``launch/`` of the current folder
    (a non-editable install run where the launch files are, e.g. the image's ``/opt/flexsheet``). Resolved on
    each call, never raising: a missing folder is named by the loader that reads from it."""
    own = _CHECKOUT / "launch"
    if (own / "sim.yaml").is_file():
        return own
    return Path.cwd().resolve() / "launch"
