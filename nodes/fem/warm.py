"""Install-time warm-up of the FEM node: ``python3 -m nodes.fem.warm [--out DIR]``.

Runs the FEM node as it runs in a graph (its loop, setup and first publications, then its teardown), in this
process on an in-process transport, for the ``fem`` params of ``launch/sim.yaml`` on every scene of
``launch/scenes/`` (``--scene NAME`` for some of them; ``cylinder.yaml`` is also what a launch file without a
``scene:`` serves), with ``cache_dir`` = ``DIR`` (default :data:`flexsheet.fem.cache.INSTALL_DIR`: the
machine's data folder as root, ``/usr/local/share/flexsheet/fem``, else the user's,
``~/.local/share/flexsheet/fem``; ``$FLEXSHEET_DATA/fem`` when set; every FEM cache searches these read-only).
``launch/`` is the checkout's, or the current folder's for an installed package (the image's
``/opt/flexsheet``). A node started later, on any ``HOME``, then loads its model instead of precomputing it
(the capacitance matrices: ~12 s for the cylinder on the 2-core machine). ``docker/install.sh`` runs it;
idempotent (a second run only loads). Exit status 1 when any model failed (each failure has its own ``FAILED``
line), 0 when every one is ready.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

import yaml

from flexsheet.dirs import launch_dir
from flexsheet.fem.cache import INSTALL_DIR
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.transport import InProcTransport
from nodes.fem.node import FemNode


def launch_root() -> Path:
    """The folder holding ``launch/sim.yaml`` (:func:`flexsheet.dirs.launch_dir`'s parent: the checkout, else
    the current folder). Raises ``FileNotFoundError`` naming it when it has no ``launch/sim.yaml``."""
    launch = launch_dir()
    if not (launch / "sim.yaml").is_file():
        raise FileNotFoundError(f"{launch / 'sim.yaml'}: not found; run from the checkout or from the folder "
                                "that holds launch/")
    return launch.parent


def param_sets(root: Path | None = None) -> list[dict]:
    """The FEM params to warm: launch/sim.yaml's fem node's with each scene file (``root``: default
    :func:`launch_root`)."""
    root = root or launch_root()
    base = dict(yaml.safe_load((root / "launch" / "sim.yaml").read_text())["nodes"]["fem"].get("params", {}))
    return [{**base, "scene": str(p)} for p in sorted((root / "launch" / "scenes").glob("*.yaml"))]


async def _warm(params: dict) -> None:
    """Run the node until its setup has ended (however long it takes), then shut it down. Raises what its
    setup raised (``RuntimeError`` when it stopped without being ready)."""
    node = FemNode(NodeConfig(name="fem", node_type="fem", params=params), transport=InProcTransport())
    task = asyncio.get_running_loop().create_task(node.run(install_signals=False))
    while not node.ready and not task.done():
        await asyncio.sleep(0.05)
    if not task.done():
        node.shutdown()
    await task                                  # re-raises the setup's error
    if not node.ready:
        raise RuntimeError("the FEM node stopped before it was ready (its log says why)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m nodes.fem.warm", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: python3 -m nodes.fem.warm --out /tmp/fem_cache")
    ap.add_argument("--out", default=INSTALL_DIR, help=f"cache folder to fill (default {INSTALL_DIR})")
    ap.add_argument("--scene", action="append", default=None, metavar="NAME",
                    help="warm only these (repeatable): a file name of launch/scenes/ such as sphere.yaml "
                         "(default: all)")
    args = ap.parse_args(argv)
    sets = param_sets()
    names = [Path(p["scene"]).name for p in sets]
    unknown = sorted(set(args.scene or []) - set(names))
    if unknown:
        ap.error(f"--scene: unknown {', '.join(unknown)}; known: {', '.join(names)}")
    failed = 0
    for name, params in zip(names, sets, strict=True):
        if args.scene and name not in args.scene:
            continue
        t = time.monotonic()
        try:
            asyncio.run(_warm({**params, "cache_dir": args.out}))
        except Exception as exc:  # noqa: BLE001 - one scene failing must not stop the rest; said plainly
            print(f"[fem warm] {name}: FAILED ({type(exc).__name__}: {exc})", flush=True)
            failed += 1
            continue
        print(f"[fem warm] {name}: ready in {time.monotonic() - t:.1f} s ({args.out})", flush=True)
    if failed:
        print(f"[fem warm] {failed} model(s) FAILED (lines above)", file=sys.stderr, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
