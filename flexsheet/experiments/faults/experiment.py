"""``flexsheet experiment faults --out DIR [--quick]``: every attack, counted.

Runs, in this process (nothing else needs to be running):

* recorder and bags (:mod:`.bags`): malformed frames between good ones (``lost`` must be 0); 8 flipped bytes
  in one chunk (reported damaged, nothing lost beyond that chunk); a bag cut as ``kill -9`` leaves it,
  recovered for the stock ``mcap`` reader;
* controller twins (:mod:`.controller`): 60 MXT MOVEs and 20 Modbus writes inside one cycle (executed motion
  beyond the per-cycle step check must be 0), a stranger's END, replayed CCounts, a STOP reset over Modbus;
* time (:mod:`.planner`): one fingertip stamped 1e12 s into the planner node;
* links (:mod:`.links`): a squatted port (garbage; plain ZMTP against CURVE), then the real publisher back
  (time to the first message, target 2 s); a subscriber that never reads stereo frames (the publisher's RSS
  growth, target ≤ 100 MB; skipped with ``--quick``); arm targets sent with a stolen host key and with another
  node's own key (authorization per node: 0 accepted, the planner's all arrive).

Writes ``DIR/faults.json`` (every count, the targets and the verdicts) and ``DIR/faults.png``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
import tempfile
from pathlib import Path

from flexsheet.experiments.faults import bags, controller, links, planner

log = logging.getLogger(__name__)

__all__ = ["run", "verdicts", "main"]

TARGETS = {"recorder_lost": 0, "beyond_cap_rad": 0.0, "squat_recovery_s": 2.0, "memory_growth_mb": 100.0}


def run(quick: bool = False) -> dict:
    """Every attack; returns ``{name: counts}`` (module doc)."""
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        for name, fn in (("recorder_malformed", bags.recorder_malformed), ("bag_flip", bags.bag_flip),
                         ("bag_cut_recover", bags.bag_cut_recover)):
            log.info(f"[faults] {name} ...")
            (t / name).mkdir()
            out[name] = fn(t / name)
    for name, fn in (("mxt_burst", controller.mxt_burst), ("modbus_burst", controller.modbus_burst),
                     ("mxt_stranger_end", controller.mxt_stranger_end), ("mxt_replay", controller.mxt_replay),
                     ("modbus_estop_network_reset", controller.modbus_estop_network_reset),
                     ("planner_future_stamp", planner.future_stamp)):
        log.info(f"[faults] {name} ...")
        out[name] = fn()
    for variant in ("garbage", "plain_zmtp_vs_curve"):
        log.info(f"[faults] squat {variant} ...")
        r = asyncio.run(links.squat_then_restart(variant))
        out[f"squat_{variant}"] = {k: r[k] for k in ("received", "recovery_s", "reconnects", "failures")}
    log.info("[faults] stolen keys: arm targets from the main host's key and from the triangulator's ...")
    with tempfile.TemporaryDirectory() as tmp:
        out["stolen_keys"] = links.stolen_keys(Path(tmp))
    if not quick:
        log.info("[faults] never-reading subscriber of stereo frames (8 s) ...")
        r = links.memory_run()
        out["never_reading_subscriber"] = {k: r[k]
                                           for k in ("published", "dropped", "growth_mb", "offered_mb")}
    return out


def verdicts(r: dict) -> dict:
    """met / MISSED per target of the issue."""
    def v(ok: bool) -> str:
        return "met" if ok else "MISSED"

    out = {"recorder_loses_nothing": v(r["recorder_malformed"]["lost"] == 0),
           "flipped_bag_reported_rest_read": v(r["bag_flip"]["reported_damaged"]
                                               and r["bag_flip"]["lost_beyond_the_damaged_chunk"] == 0),
           "recovered_bag_opens_in_stock_reader": v(r["bag_cut_recover"]["stock_reader_opens_recovered"]),
           "no_motion_beyond_cap": v(r["mxt_burst"]["beyond_cap_rad"] == 0.0
                                     and r["modbus_burst"]["beyond_cap_rad"]
                                     == 0.0),
           "strangers_end_ignored": v(r["mxt_stranger_end"]["owner_session_open"]),
           "replays_dropped": v(r["mxt_replay"]["dropped_counted"] == r["mxt_replay"]["sent_bad"]),
           "estop_not_reset_over_network":
               v(r["modbus_estop_network_reset"]["estop_latched_after_network_reset"]),
           "future_stamp_rejected_alone": v(r["planner_future_stamp"]["rejected"] == 1 and
                                            r["planner_future_stamp"]["served_after"]
                                            == r["planner_future_stamp"]["sent_after"])}
    for variant in ("garbage", "plain_zmtp_vs_curve"):
        s = r[f"squat_{variant}"]["recovery_s"]
        out[f"squat_{variant}_heals_in_2s"] = v(s is not None and s <= TARGETS["squat_recovery_s"])
    k = r["stolen_keys"]
    out["targets_only_from_the_planner"] = v(k["planner"]["received"] > 0 and k["host_key_at_planner_port"]
                                             ["received"] == 0 and k["other_node_key"]["received"] == 0)
    if "never_reading_subscriber" in r:
        out["memory_bounded"] = v(r["never_reading_subscriber"]["growth_mb"] <= TARGETS["memory_growth_mb"])
    return out


def _chart(res: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = res["verdicts"]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(v) + 1.2))
    names = list(v)
    ax.barh(names, [1] * len(names), color=["tab:green" if v[n] == "met" else "tab:red" for n in names])
    for i, n in enumerate(names):
        ax.text(0.5, i, v[n], ha="center", va="center", color="white", fontsize=8)
    ax.set_xticks([])
    ax.set_title("flexsheet experiment faults: each attack's verdict against its target", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment faults", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment faults --out docs/figures/faults")
    ap.add_argument("--out", required=True, help="output folder (faults.json, faults.png)")
    ap.add_argument("--quick", action="store_true", help="skip the 8 s memory run (the tests' mode)")
    args = ap.parse_args(argv)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    r = run(args.quick)
    res = {"results": r, "targets": TARGETS, "verdicts": verdicts(r), "quick": args.quick}
    (out_dir / "faults.json").write_text(json.dumps(res, indent=1))
    _chart(res, out_dir / "faults.png")
    missed = [k for k, x in res["verdicts"].items() if x != "met"]
    print(f"[faults] {len(res['verdicts']) - len(missed)} of {len(res['verdicts'])} targets met"
          + (f"; MISSED: {', '.join(missed)}" if missed else "") + f"; wrote {out_dir}/faults.json, "
                                                                   "faults.png")
    return 0 if not missed else 1


if __name__ == "__main__":
    sys.exit(main())
