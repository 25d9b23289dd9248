"""Faults in the full simulated graph: ``kill -9`` of every node but the world, one after another, while the
paper's stroke runs (``launch/sim_composed.yaml``, the wall-clock graph of processes, through ``flexsheet
launch``).

What must hold:

* the launcher sees each death and respawns the node (policy ``on-failure``, the launch-file default);
* the arm bridges keep their arms still meanwhile: no target → ``hold:no_target`` after ``target_timeout``;
  a dead bridge → the controller's watchdog holds the arm (``fault:watchdog``), the new bridge resets it;
  and no commanded joint step is larger than one period at the bridge's speed limit;
* the run ends normally with ``summary.json`` (Table I + latency from the bag);
* the recording loses only the dead node's own messages: per topic, the recorder saw no publisher
  sequence gap (wire drop) in any publisher incarnation, and a topic's publisher restarted (sequence
  reset) only when the node publishing it was killed; the messages it did not publish while dead are
  counted from the gap in its stream;
* the bag cut by ``kill -9`` of the recorder reads up to its last complete chunk.

The recorder is killed first: a respawned recorder never overwrites its bag, it continues in
``sim.1.mcap``, so ``sim.mcap`` stays the bag cut by the kill (also copied aside right after the kill, to
check it as it was) and ``sim.1.mcap`` holds the rest of the run (see docs/reliability.md).

``python tests/system/test_faults.py`` runs the scenario once and prints the numbers for docs/reliability.md.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from conftest import MIN_TIPS_HZ, private_ports  # noqa: E402

from flexsheet.runtime.bag_read import BagSummary, bag_info, read_bag  # noqa: E402
from flexsheet.runtime.codec import decode_any  # noqa: E402
from flexsheet.runtime.launch import load_launch  # noqa: E402

#: the slow tier (tests/run.sh --slow): over a minute of end-to-end work
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]   # the faulted run and its waits: minutes

#: kill order, in groups killed together (nodes of different chains): the recorder first (see module doc),
#: the slow-to-start FEM solver with the renderer and camera, the triangulator, the planner, then one arm's
#: bridge with the other's controller twin, and the other
#: way round. The world is required (its exit ends the run).
KILL_GROUPS = [["recorder"], ["fem", "renderer", "camera"], ["triangulator"], ["planner"],
               ["arm_left", "ctrl_right"], ["ctrl_left", "arm_right"]]
KILL_ORDER = [n for g in KILL_GROUPS for n in g]
#: nodes whose restart is awaited before the next kill (all: each death must be seen in a flowing graph)
WAIT_UP = set(KILL_ORDER)
#: which recorded topics each node publishes (the others' streams must not restart when it dies)
PUBLISHES = {
    "camera": ["/camera/calibration"],
    "triangulator": ["/fingertip"],
    "planner": ["/sheet/target", "/arm/left/target", "/arm/right/target"],
    "arm_left": ["/arm/left/joint_state"],
    "arm_right": ["/arm/right/joint_state"],
    "fem": ["/object/deformation", "/object/force_depth"],
    "renderer": ["/render/stereo"],
    "world": ["/world/finger", "/world/sheet", "/world/contact", "/world/head"],
    "head_camera": ["/eye/pose"],
}
#: a 120 s stroke the kills start in, then the paper's two stroking speeds (Table I rows 30 s and
#: 10 s): ~170 s of script, so that it outlasts the kill schedule, whose length depends on the
#: machine: the kills once took 27 s, > 46 s on a slower day, and > 94 s on a quiet 2-core
#: machine with the two-arm motion (each respawn waits for its node to be "up"); every shorter
#: script ended before the last kill on some machine. The 10 s stroke after them shows the graph
#: recovered. The FEM's precompute is cached before the launch (conftest.sim_fem_cache): a cold
#: FEM start inside the graph took > 60 s on a fresh machine and the FEM was not up for its kill.
SCRIPT = ("world.script=[{mode: stroke, moving_time: 120, seed: 2}, {mode: stroke, moving_time: 30}, "
          "{mode: stroke, moving_time: 10, seed: 1}]")
SETTLE = 1.5              # s after a respawn (or, for WAIT_UP nodes, after "up") before the next kill
#: longer for the recorder: "up" is before its subscriptions have connected to every publisher (ZeroMQ joins
#: late), and the next group's streams must be in its new bag before they are cut — on a cold machine one run
#: of three had the FEM killed before the respawned recorder received /object/deformation (no restart seen)
SETTLE_AFTER = {"recorder": 5.0}
#: the launcher's wait before each respawn, per node (s), from the launch file the scenario runs
RESPAWN_DELAY = {name: spec.respawn.delay for name,
                 spec in load_launch(ROOT / "launch" / "sim_composed.yaml").nodes.items()}
STEP_TOLERANCE = 1.5      # the controller twin's own refusal threshold: qd_max · period · 1.5


class Launch:
    """``flexsheet launch FILE`` as a child process; output lines collected with arrival times."""

    def __init__(self, launch_file: Path, out: Path, *extra: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "flexsheet", "launch", str(launch_file), "--out", str(out), *extra],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.lines: list[tuple[float, str]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append((time.time(), line.rstrip()))

    def find(self, pattern: str, start: int = 0) -> tuple[int, float, re.Match] | None:
        rx = re.compile(pattern)
        for i in range(start, len(self.lines)):
            t, line = self.lines[i]
            m = rx.search(line)
            if m:
                return i, t, m
        return None

    def wait(self, pattern: str, timeout: float, start: int = 0) -> tuple[int, float, re.Match]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            hit = self.find(pattern, start)
            if hit:
                return hit
            if self.proc.poll() is not None and not self._reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"{pattern!r} not seen in {timeout} s:\n" + self.tail())

    def tail(self, n: int = 80) -> str:
        return "\n".join(line for _, line in self.lines[-n:])

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


def _pid(launch: Launch, name: str) -> tuple[int, int]:
    last = None
    for i, (_, line) in enumerate(launch.lines):
        m = re.search(rf"^\[{name}\s*\] started pid (\d+)", line)
        if m:
            last = (i, int(m.group(1)))
    assert last is not None, f"no pid for {name}\n" + launch.tail()
    return last


#: s a node may take to be up (its setup: the FEM's force-depth table, ~10 s of CPU, while the other twelve
#: processes start on the two cores): a wait, not a target; 60 s was passed on a slow machine
UP_S = 180.0


def run_scenario(out: Path, cut_copy: Path) -> dict:
    """Run the graph, kill every node of KILL_GROUPS once, wait for the end. Returns the kill log and output.

    The nodes of a group die together once all are up; the next group follows ``SETTLE`` s after the
    launcher restarted them (and, for the arm chain, after they are up again)."""
    # kill -9 is about one node = one process: no composable containers here
    lf = private_ports(ROOT / "launch" / "sim_composed.yaml", out.parent / f"{out.name}_sim.yaml",
                       split_containers=True)
    launch = Launch(lf, out, "--set", SCRIPT)
    kills = []
    try:
        launch.wait(r"\[world\s*\] .*segment 1/3", 120)
        for group in KILL_GROUPS:
            victims = {}
            for name in group:   # each must be up before it is killed
                i, pid = _pid(launch, name)
                launch.wait(rf"^\[{name}\s*\] .* up: endpoint", UP_S, start=i)
                victims[name] = pid
            start = len(launch.lines)
            for name, pid in victims.items():
                t_kill = time.time()
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    raise AssertionError(f"{name} (pid {pid}) died before its kill:\n"
                                         + launch.tail()) from None
                if name == "recorder":
                    shutil.copyfile(out / "sim.mcap", cut_copy)
                kills.append({"node": name, "old_pid": pid, "t_kill": t_kill})
            for k in kills[-len(victims):]:
                name = k["node"]
                i_resp, k["t_respawn"], _ = launch.wait(rf"^\[{name}\s*\] respawning", 30, start=start)
                k["i_started"], k["t_started"], m = launch.wait(rf"^\[{name}\s*\] started pid (\d+)", 30,
                                                                start=i_resp)
                k["new_pid"] = int(m.group(1))
                if name in WAIT_UP:
                    launch.wait(rf"^\[{name}\s*\] .* up: endpoint", UP_S, start=k["i_started"])
            time.sleep(max(SETTLE, *(SETTLE_AFTER.get(n, 0.0) for n in group)))
        code = launch.proc.wait(timeout=300)      # a guard against a hang, not a speed test: on 2 cores the
        # kills' respawns (a process start each) and the two bridges' IK every cycle slow the last stroke
    finally:
        launch.stop()
    for k in kills:   # when each respawned node was up again
        hit = launch.find(rf"^\[{k['node']}\s*\] .* up: endpoint", k.pop("i_started"))
        k["t_up"] = hit[1] if hit else None
    return {"kills": kills, "code": code, "lines": [line for _, line in launch.lines]}


def analyse_bag(bag: Path, summary: BagSummary | None = None) -> dict:
    """Per topic: publisher incarnations (a sequence reset starts a new one), sequence gaps within each
    (wire drops), the time gaps between incarnations, and the arms' joint states (commanded, position,
    bridge status, stamp) in order."""
    streams: dict[str, list[tuple[float, int]]] = defaultdict(list)
    hb: dict[str, list[float]] = defaultdict(list)
    arms: dict[str, list] = defaultdict(list)
    for m in read_bag(bag, summary=summary):
        msg = decode_any(m.frames)
        if m.topic == "/diagnostics":
            hb[msg.node].append(msg.header.stamp)
            continue
        streams[m.topic].append((m.log_time, msg.header.seq))
        if m.topic.endswith("/joint_state"):
            arms[msg.arm].append((msg.header.stamp, msg.header.seq, msg.commanded.copy(), msg.position.copy(),
                                  msg.bridge_status))
    topics = {}
    for topic, s in streams.items():
        incarnations, gaps, lost_seq, lost_start = [[s[0]]], [], 0, 0
        for prev, cur in zip(s, s[1:], strict=False):
            if cur[1] <= prev[1]:           # sequence reset: the publisher restarted
                gaps.append((prev[0], cur[0]))
                incarnations.append([cur])
                lost_start += cur[1]        # published before the recorder's subscription reached it
            else:
                lost_seq += cur[1] - prev[1] - 1
                incarnations[-1].append(cur)
        dt = np.diff([t for t, _ in s])
        period = float(np.median(dt)) if dt.size else 0.0
        topics[topic] = {"n": len(s), "restarts": gaps, "wire_lost": lost_seq, "period": period,
                         "restart_lost": lost_start,
                         "downtime_lost": int(sum(max(0, round((b - a) / period) - 1) for a, b in gaps))
                         if period > 0 else 0}
    return {"topics": topics, "arms": arms, "heartbeats": hb}


@pytest.fixture(scope="module")
def faults(tmp_path_factory, sim_fem_cache):
    out = tmp_path_factory.mktemp("faults")
    cut = out.parent / f"{out.name}_cut.mcap"
    run = run_scenario(out, cut)
    return out, cut, run


def test_every_killed_node_is_respawned_and_the_run_finishes(faults):
    out, _, run = faults
    why = [ln for ln in run["lines"] if re.search(r"exited with code|failed "
                                                  r"during|Traceback|Error|escalating", ln)]
    # a launch in which nodes failed exits 1, naming them: the kills, and nothing else
    failed = [ln for ln in run["lines"] if "failed during the run" in ln]
    assert run["code"] == 1 and len(failed) == 1, "\n".join(why[-40:] + ["..."] + run["lines"][-60:])
    assert (sorted(part.split(" (")[0] for part in failed[0].split(": ", 1)[1].split("), "))
            == sorted(KILL_ORDER)), \
        failed
    assert [k["node"] for k in run["kills"]] == KILL_ORDER
    for k in run["kills"]:
        assert k["new_pid"] != k["old_pid"]
        assert k["t_kill"] < k["t_respawn"] < k["t_up"]
        # the launcher saw the signal death (exit code -9) before respawning
        assert any(re.search(rf"^\[{k['node']}\s*\] exited with code -9", line) for line in run["lines"]), k
    summary = json.loads((out / "summary.json").read_text())
    # Table I of both strokes was computed from the bag of the faulted run (its accuracy is not the point
    # here: a restarted controller twin re-creates its arm at the initial joints)
    assert summary["30"]["n"] > MIN_TIPS_HZ * 30 and summary["10"]["n"] > MIN_TIPS_HZ * 10


def test_the_recording_loses_only_the_dead_nodes_own_messages(faults):
    out, _, run = faults
    info = bag_info(out / "sim.1.mcap")     # the respawned recorder's bag: the run after its restart
    assert not info.truncated
    assert bag_info(out / "sim.mcap").truncated   # the first part, cut by the kill, was kept as it was
    res = analyse_bag(out / "sim.1.mcap")
    killed = {k["node"]: k for k in run["kills"]}
    for topic, t in res["topics"].items():
        # no message lost on the wire in any publisher incarnation (the recorder's own count agrees)
        assert t["wire_lost"] == 0, (topic, t)
        assert info.dropped.get(topic, 0) == 0, (topic, info.dropped)
        # latched: resent to every (re)joining subscriber
        if topic in ("/camera/calibration", "/object/force_depth"):
            continue
        owner = next(n for n, ts in PUBLISHES.items() if topic in ts)
        if owner in killed:
            k = killed[owner]
            assert len(t["restarts"]) == 1, (topic, t["restarts"])
            a, b = t["restarts"][0]
            # the stream stopped at the kill (a is the recorder's receive time of the last message sent before
            # it: 0.077 s after the kill was seen at load 9 on the 2 cores, so 0.15 s) and stayed down at
            # least the launcher's respawn delay: a and b are both the recorder's clock. (Bounding b by
            # the launcher's "started pid" line failed in CI: the test read that line 0.27 s after the new
            # incarnation's first message had been recorded; the test reads the launcher's output late.)
            assert a <= k["t_kill"] + 0.15, (topic, a, k)
            assert b - a >= RESPAWN_DELAY[owner], (topic, a, b, RESPAWN_DELAY[owner])
            assert b <= k["t_up"] + 5.0, (topic, b, k)
        else:
            assert t["restarts"] == [], (topic, t["restarts"])


def _step_limit() -> np.ndarray:
    from flexsheet.arm.kinematics import QD_MAX
    from nodes.arm_bridge.params import ArmBridgeParams

    p = ArmBridgeParams()
    return QD_MAX * p.speed_scale * p.period


def test_the_arms_hold_and_never_jump(faults):
    out, _, run = faults
    res = analyse_bag(out / "sim.1.mcap")
    killed = {k["node"]: k for k in run["kills"]}
    limit = _step_limit()
    for arm in ("left", "right"):
        states = res["arms"][arm]
        stamps = np.array([s[0] for s in states])
        status = [s[4] for s in states]
        # the planner's death: no target for target_timeout → the bridge holds (the arm stops)
        k = killed["planner"]
        during = {st for t, st in zip(stamps, status, strict=True) if k["t_kill"] + 0.3 < t < k["t_up"]}
        assert "hold:no_target" in during, (arm, during)
        # the controller twin's death: the bridge reconnects to the new twin, which starts disabled
        k = killed[f"ctrl_{arm}"]
        after = [st for t, st in zip(stamps, status, strict=True) if k["t_kill"] < t < k["t_up"] + 5.0]
        # (a state or two read just before the kill may still say "ok")
        assert "hold:disabled" in after[:20], (arm, after[:20])
        assert "ok" in after[after.index("hold:disabled"):], (arm, sorted(set(after)))
        # the run recovers: the arm follows targets again at the end
        assert status[-1] in ("ok", "hold:no_target"), (arm, status[-50:])
        n_reset = 0
        for prev, cur in zip(states, states[1:], strict=False):
            step = np.abs(cur[2] - prev[2])
            if cur[1] == prev[1] + 1 and cur[0] - prev[0] < 0.5:
                # consecutive cycles: no commanded step beyond the controller's own step check; except into a
                # cycle where the controller faulted (e.g. its watchdog, after a late cycle under load): the
                # bridge then reseeds its command to the measured joints (flexsheet/arm/stream.py,
                # Verdict.reseed), which lag the last command by
                # the servo's tracking error, not a motion (seen
                # once: 0.039 rad on J6 at a fault:watchdog cycle, 3.0x the step limit); the step out of the
                # fault is checked
                if not cur[4].startswith("fault:"):
                    assert np.all(step <= STEP_TOLERANCE * limit + 1e-9), (arm, cur[0], step / limit)
            elif cur[1] <= prev[1]:
                # the bridge restarted: while it was dead the controller's watchdog held the arm, so the
                # arm is no farther from the last command than the new bridge's cycles so far allow
                n_reset += 1
                moved = np.abs(cur[3] - prev[2])
                assert np.all(moved <= (cur[1] + 2) * STEP_TOLERANCE * limit + 5e-3), (arm, moved, cur[1])
            # every command starts where the arm is after any gap (no jump toward a stale goal)
            if cur[1] != prev[1] + 1 or cur[0] - prev[0] >= 0.5:
                assert np.all(np.abs(cur[2] - cur[3]) <= (cur[1] + 2) * STEP_TOLERANCE * limit
                              + 5e-3), (arm, cur[0])
        assert n_reset == 1, (arm, n_reset)


def test_a_bag_cut_by_kill_9_reads_to_its_last_complete_chunk(faults):
    _, cut, run = faults
    s = BagSummary()
    n = sum(1 for _ in read_bag(cut, summary=s))
    assert s.truncated and n > 100, (s.truncated, n)
    info = bag_info(cut)
    # every message of the cut bag decodes, and its last one is from before the kill
    assert sum(info.counts.values()) == n and info.end <= run["kills"][0]["t_kill"]
    for m in read_bag(cut):
        decode_any(m.frames)


if __name__ == "__main__":
    import tempfile

    d = Path(tempfile.mkdtemp(prefix="faults_"))
    out, cut = d / "out", d / "cut.mcap"
    out.mkdir()
    from conftest import warm_sim_fem

    warm_sim_fem()
    t0 = time.time()
    run = run_scenario(out, cut)
    print(f"wall {time.time() - t0:.1f} s, launch exit {run['code']}")
    for k in run["kills"]:
        up = f"{k['t_up'] - k['t_kill']:.2f} s" if k["t_up"] else "never"
        print(f"  {k['node']:<12} respawn after {k['t_respawn'] - k['t_kill']:.2f} s, up after {up}")
    res = analyse_bag(out / "sim.1.mcap")
    for topic, t in sorted(res["topics"].items()):
        print(f"  {topic:<24} n={t['n']:6d} restarts={len(t['restarts'])} wire_lost={t['wire_lost']} "
              f"downtime_lost={t['downtime_lost']} restart_lost={t['restart_lost']} "
              f"period={t['period'] * 1e3:.1f} ms")
    s = BagSummary()
    n = sum(1 for _ in read_bag(cut, summary=s))
    print(f"cut bag: {n} messages, truncated={s.truncated}, size {cut.stat().st_size} B")
    lim = _step_limit()
    for arm, states in res["arms"].items():
        steps = [np.max(np.abs(c[2] - p[2]) / lim) for p, c in zip(states, states[1:], strict=False)
                 if c[1] == p[1] + 1]
        print(f"  {arm}: max step/limit {max(steps):.3f}, statuses {sorted({s[4] for s in states})}")
    (d / "run.json").write_text(json.dumps({k: v for k, v in run.items() if k != "lines"}, indent=1))
    (d / "launch.log").write_text("\n".join(run["lines"]))
    print(d)
