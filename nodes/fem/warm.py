"""Install-time warm-up of the FEM node: ``python3 -m nodes.fem.warm [--out DIR]``.

Runs the FEM node's own setup, in this process, for the ``fem`` params of ``launch/sim.yaml`` on the paper's
cylinder and on every scene of ``launch/scenes/``, with ``cache_dir`` = ``DIR`` (default
:data:`flexsheet.fem.cache.INSTALL_DIR`, which every FEM cache searches read-only). A node started later, on
any ``HOME``, then loads its model instead of precomputing it (the capacitance matrices: ~12 s for the
cylinder on the 2-core machine). ``docker/install.sh`` runs it; idempotent (a second run only loads).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

import yaml

from flexsheet.fem.cache import INSTALL_DIR
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.transport import InProcTransport
from nodes.fem.node import FemNode

ROOT = Path(__file__).resolve().parents[2]


def param_sets(root: Path = ROOT) -> list[dict]:
    """The FEM params to warm: launch/sim.yaml's fem node alone and with each scene file."""
    base = dict(yaml.safe_load((root / "launch" / "sim.yaml").read_text())["nodes"]["fem"].get("params", {}))
    return [base] + [{**base, "scene": str(p)} for p in sorted((root / "launch" / "scenes").glob("*.yaml"))]


async def _warm(params: dict) -> None:
    """The node's setup to its end (however long it takes), then its teardown."""
    node = FemNode(NodeConfig(name="fem", node_type="fem", params=params), transport=InProcTransport())
    await node.setup()
    await node.teardown()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m nodes.fem.warm", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: python3 -m nodes.fem.warm --out /tmp/fem_cache")
    ap.add_argument("--out", default=INSTALL_DIR, help=f"cache folder to fill (default {INSTALL_DIR})")
    args = ap.parse_args(argv)
    for params in param_sets():
        t = time.monotonic()
        what = Path(params.get("scene") or "the paper's cylinder").name
        try:
            asyncio.run(_warm({**params, "cache_dir": args.out}))
        except Exception as exc:  # noqa: BLE001 - one scene failing must not stop the rest; said plainly
            print(f"[fem warm] {what}: FAILED ({type(exc).__name__}: {exc})", flush=True)
            continue
        print(f"[fem warm] {what}: ready in {time.monotonic() - t:.1f} s ({args.out})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
