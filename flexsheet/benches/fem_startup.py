"""``flexsheet bench fem_startup [--scene FILE ...] [--json] [--out
DIR]``: how long the FEM node takes, on a fresh machine, from its process starting to serving its scene's
shipped table.

"Fresh": the node runs with an empty ``HOME`` (no user cache), so it reads only what ships in
``flexsheet/fem/data`` and what the install built (the machine's data folder,
``/usr/local/share/flexsheet/fem``, by ``python -m nodes.fem.warm`` in ``docker/install.sh``). "Serving": its
first heartbeat that lists its ``/fingertip`` subscription and whose message names the nonlinear table it
loaded (a node that fell back to the linear model is reported as such). Each scene is started twice; the
slower counts. Target: 10 s.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time

from flexsheet.runtime.ports import free_port
from flexsheet.runtime.tools import collect_heartbeats

__all__ = ["main", "startup_s"]

TARGET_S = 10.0
SCENES = ("launch/scenes/cylinder.yaml", "launch/scenes/sphere.yaml", "launch/scenes/rounded_box.yaml",
          "launch/scenes/organ.yaml")


def startup_s(scene: str, timeout: float = 120.0) -> dict:
    """Start ``flexsheet run fem`` on ``scene`` with an empty HOME; seconds until its heartbeat shows it
    serving, with that heartbeat's message. Raises ``TimeoutError`` (the node's last log lines) past
    ``timeout`` s."""
    port = free_port()
    ep = f"tcp://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as home:
        env = dict(os.environ, HOME=home)
        env.pop("FLEXSHEET_KEYS", None)
        log_path = os.path.join(home, "fem.log")
        log = open(log_path, "w")           # a file, not a pipe: a chatty node never blocks on a full pipe
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "run", "fem", "--param", f"scene={scene}",
                                 "--endpoint", ep], env=env, stdout=subprocess.DEVNULL, stderr=log, text=True)
        try:
            while time.monotonic() - t0 < timeout:
                hb = asyncio.run(collect_heartbeats([ep], 0.5, None, {"fem"})).get("fem")
                if hb is not None and any(s.topic == "/fingertip" for s in hb.subscriptions) and hb.message:
                    return {"scene": scene, "seconds": time.monotonic() - t0, "message": hb.message,
                            "table": "LINEAR" not in hb.message and "loaded" in hb.message}
                if proc.poll() is not None:
                    break
            log.flush()
            with open(log_path) as fh:
                tail = fh.read().splitlines()[-5:]
            raise TimeoutError(f"fem on {scene}: not serving after {time.monotonic() - t0:.0f} s: "
                               + " | ".join(tail))
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
            log.close()


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print one line per scene (one JSON object with ``--json``); 0 when every scene
    serves its table within the target, 1 otherwise."""
    ap = argparse.ArgumentParser(prog="flexsheet bench fem_startup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet bench fem_startup --scene "
                                        "launch/scenes/organ.yaml --json")
    ap.add_argument("--scene", action="append", default=[], help="scene file (default: the four shipped)")
    ap.add_argument("--repeats", type=int, default=2, help="starts per scene; the slowest counts (default 2)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--out", default="", help="also write DIR/fem_startup.json")
    args = ap.parse_args(argv)
    rows = []
    for scene in args.scene or SCENES:
        runs = [startup_s(scene) for _ in range(max(1, args.repeats))]
        worst = max(runs, key=lambda r: r["seconds"])
        rows.append({**worst, "all_seconds": [r["seconds"] for r in runs]})
        if not args.json:
            print(f"{scene}: serving in {worst['seconds']:.2f} s (worst of {len(runs)}): {worst['message']}",
                  flush=True)
    res = {"title": "FEM node start-up on a fresh machine (empty HOME)", "units": "s", "target_s": TARGET_S,
           "scenes": rows, "verdict": "met" if all(r["seconds"] <= TARGET_S and r["table"] for r in rows)
           else "MISSED"}
    if args.json:
        print(json.dumps(res, indent=1))
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "fem_startup.json"), "w") as fh:
            json.dump(res, fh, indent=1)
    return 0 if res["verdict"] == "met" else 1


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
