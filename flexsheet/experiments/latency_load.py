"""``flexsheet experiment latency_load``: the loop's latency against CPU load.

The same wall-clock run (``flexsheet launch launch/sim_composed.yaml``, one stroke) is repeated with 0, 1 and
2 cores taken away by busy-loop processes (``nice 0``, one per core), and the report's hops are charted:
camera frame → arm command and fingertip → rendered frame (median and p99, ms), plus the controllers' watchdog
trips. Output: ``OUT/latency_load.json`` and ``OUT/latency_load.png`` (matplotlib Agg). Each point is one run
(noisy on a shared machine; the JSON keeps every run's numbers).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import subprocess
import sys
import time
from pathlib import Path

HOPS = ("exposure_to_arm_command", "exposure_to_projected")
SCRIPT = "world.script=[{mode: stroke, moving_time: 10}]"
#: ``--quick``: one run on the machine as it is, a 4 s stroke
QUICK_SCRIPT = "world.script=[{mode: stroke, moving_time: 4}]"


def _busy(stop) -> None:
    while not stop.is_set():
        for _ in range(100000):
            pass


def run_once(launch: str, busy: int, out: Path, timeout: float = 400.0, script: str = SCRIPT) -> dict:
    """One sim run with ``busy`` busy-loop processes; returns its latency hops and watchdog trips.
    Raises ``RuntimeError`` when the launch fails (its last lines in the message)."""
    stop = mp.Event()
    procs = [mp.Process(target=_busy, args=(stop,), daemon=True) for _ in range(busy)]
    for p in procs:
        p.start()
    try:
        t0 = time.monotonic()
        res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", launch, "--out", str(out), "--set",
                              script],
                             capture_output=True, text=True, timeout=timeout)
        wall = time.monotonic() - t0
    finally:
        stop.set()
        for p in procs:
            p.join(2.0)
            if p.is_alive():
                p.kill()
    if res.returncode != 0:
        raise RuntimeError(f"launch with {busy} busy cores failed ({res.returncode}): "
                           + " | ".join(res.stdout.strip().splitlines()[-5:]))
    summary = json.loads((out / "summary.json").read_text())
    return {"busy_cores": busy, "wall_s": wall,
            "latency_ms": {h: summary["latency_ms"]["chain"][h] for h in HOPS},
            "watchdog": summary.get("faults", {}).get("watchdog"),
            "dtheta_10_deg": summary.get("10", {}).get("dtheta_mean_deg")}


def chart(rows: list[dict], path: Path) -> None:
    """Median and p99 of each hop against busy cores (Agg PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    x = [r["busy_cores"] for r in rows]
    for hop, colour in zip(HOPS, ("tab:blue", "tab:orange"), strict=True):
        ax.plot(x, [r["latency_ms"][hop]["median"] for r in rows], "o-", color=colour, label=f"{hop} median")
        ax.plot(x, [r["latency_ms"][hop]["p99"] for r in rows], "s--", color=colour, alpha=0.6,
                label=f"{hop} p99")
    ax.set_yscale("log")
    ax.set_xlabel("cores taken by busy-loop processes (of 2)")
    ax.set_ylabel("latency, ms")
    ax.set_xticks(x)
    ax.set_title("flexsheet sim: latency against CPU load (one run per point)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="flexsheet experiment latency_load", description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  flexsheet experiment latency_load --out docs/figures/realtime\n"
               "  flexsheet experiment latency_load --out /tmp/ll --busy 0 2\n"
               "  flexsheet experiment latency_load --out /tmp/ll --quick")
    p.add_argument("--out", default="docs/figures/realtime", help="output folder (JSON + PNG)")
    p.add_argument("--launch", default="launch/sim_composed.yaml",
                   help="launch file to run (clock: wall: the load is what it measures)")
    p.add_argument("--busy", type=int, nargs="+", default=[0, 1, 2],
                   help="busy cores per run (default 0 1 2)")
    p.add_argument("--quick", action="store_true", help="one run, no busy core, a 4 s stroke")
    a = p.parse_args(argv)
    script = QUICK_SCRIPT if a.quick else SCRIPT
    if a.quick:
        a.busy = [0]
    if any(b < 0 or b > 8 for b in a.busy):
        p.error(f"--busy: each value must be 0..8, got {a.busy}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for b in a.busy:
        print(f"[latency_load] run with {b} busy core(s) ...", flush=True)
        rows.append(run_once(a.launch, b, out / f"run_busy{b}", script=script))
        r = rows[-1]["latency_ms"]
        print(f"[latency_load]   exposure -> arm {r[HOPS[0]]['median']:.2f} / {r[HOPS[0]]['p99']:.1f} ms, "
              f"exposure -> projected {r[HOPS[1]]['median']:.1f} / {r[HOPS[1]]['p99']:.1f} ms, "
              f"watchdog {rows[-1]['watchdog']}", flush=True)
    (out
     / "latency_load.json").write_text(json.dumps({"runs": rows, "launch": a.launch, "script": script},
                                                  indent=1))
    chart(rows, out / "latency_load.png")
    print(f"[latency_load] wrote {out}/latency_load.json and latency_load.png", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
