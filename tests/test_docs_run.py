"""Docs that run: every command of docs/deploy.md and docs/calibration.md and every example line of a
``flexsheet`` --help is executed here, so neither drifts from the code.

The commands are extracted mechanically (:func:`doc_commands`, :func:`help_commands`): fenced ``bash``/``sh``/
``console`` blocks, lines that start with ``flexsheet ``, inline code spans that start with ``flexsheet `` or
``python -m flexsheet``, and the ``example:`` lines of every parser of :func:`flexsheet.cli.build_parser` and
of every calibrate/experiment/bench NAME. Each is one test case (id: file:line, or the --help and the
example's number), handled by the first table that names it:

- :data:`SKIP` (command prefix → reason): a step only a lab machine can take; skipped with its reason;
- :data:`CHEAP` (command → (form, reason)): a cheaper command that proves the same (``--check`` instead of a
  launch, a short ``--duration``, fewer images), or ``parse``: the command is parsed by the real parsers (its
  NAME's own argparse included) and the repository files it names must exist, but it is not run (experiments
  and benchmarks of minutes);
- otherwise the command runs as written (or as its CHEAP form) in a sandbox (:func:`make_sandbox`: its own
  HOME, launch files on free ports, outputs in a temporary folder) within :data:`BUDGET_S`, and must exit 0,
  or as :data:`EXPECT` says where a lab step fails on purpose on a machine without the lab (for example a
  ``--check`` exits 78 naming only the lab's addresses);
- :data:`LIVE`: tool commands run against one live ``launch/sim.yaml`` graph (:func:`sim_graph`);
  :data:`INTERRUPT`: nodes and launches that run until Ctrl-C get it once they are up, and must stop cleanly.

A subcommand named bare in the prose (`flexsheet bag info`) is checked with its ``--help``. A command no table
names and that does not finish in the budget fails, as does a table entry whose command is gone from the docs
and the help: the tables are the complete list of what is not run as written.

The cases that start nodes or a graph are marked ``serial``: they run in phase 2 (tests/run.sh, conftest.py);
the rest, in-process parses and one-shot commands, in phase 1.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import io
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import pytest
from conftest import KILLED

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("docs/deploy.md", "docs/calibration.md")
SHELL_FENCES = ("bash", "sh", "shell", "console")
#: a line of an example epilog that is a command: ``flexsheet ...`` or ``VAR=value flexsheet ...``
HELP_CMD = re.compile(r"^(?:examples?:\s*)?((?:[A-Z_]+=\S+ )*flexsheet .*)$")
SPAN = re.compile(r"`((?:flexsheet|python3? -m flexsheet[.\w]*)(?:\s[^`]*)?)`")
#: the most one command run as written (or its cheap form) may take, s; a longer one needs a CHEAP entry
BUDGET_S = 60.0


# ------------------------------------------------------------------------------------------- extraction
@dataclass(frozen=True)
class Cmd:
    id: str        # where it was found first: docs/deploy.md:123, or "flexsheet topic --help:2" (2nd example)
    cmd: str       # the command, whitespace collapsed and its trailing comment removed


def normalise(cmd: str) -> str:
    """The command without its trailing ``# comment`` (outside quotes) and with whitespace collapsed."""
    out, quote = [], None
    for i, ch in enumerate(cmd):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or cmd[i - 1].isspace()):
            break
        out.append(ch)
    return " ".join("".join(out).split())


def doc_commands(path: Path, rel: str) -> list[Cmd]:
    """The commands of one docs page, each with its file:line: the lines of its shell fences (``console``: the
    ``$ `` lines), the lines that start with ``flexsheet ``, and the inline code spans that are commands."""
    lines = path.read_text().splitlines()
    found: list[Cmd] = []
    fence: str | None = None
    pending, start = "", 0
    for n, line in enumerate(lines, 1):
        m = re.match(r"^\s*```(\S*)", line)
        if m:
            fence = None if fence is not None else m.group(1)
            continue
        if fence is not None:
            if fence not in SHELL_FENCES:
                continue
            text = line.strip()
            if fence == "console":
                if not text.startswith("$ "):
                    continue
                text = text[2:]
            text, start = (pending + " " + text, start) if pending else (text, n)
            if text.endswith("\\"):
                pending = text[:-1]
                continue
            pending = ""
            if cmd := normalise(text):
                found.append(Cmd(f"{rel}:{start}", cmd))
        elif line.startswith("flexsheet "):
            found.append(Cmd(f"{rel}:{n}", normalise(line)))
    text = "\n".join(lines)
    for m in SPAN.finditer(text):
        found.append(Cmd(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}", normalise(m.group(1))))
    return found


def _walk(parser: argparse.ArgumentParser, path: tuple[str, ...]):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, (*path, name))


def examples(text: str) -> list[str]:
    """The command lines of a help text's ``example:``/``examples:`` section (to its end)."""
    m = re.search(r"^examples?:", text, re.M)
    if not m:
        return []
    return [normalise(c.group(1)) for line in text[m.start():].splitlines()
            if (c := HELP_CMD.match(line.strip()))]


DELEGATES = ("calibrate", "experiment", "bench")


def _delegate_table(kind: str) -> dict[str, str]:
    from flexsheet import registry

    return {"calibrate": registry.calibrations, "experiment": registry.experiments,
            "bench": registry.benches}[kind]()


def help_commands() -> list[Cmd]:
    """The example lines of ``flexsheet --help`` and of every subcommand's --help: the argparse tree of
    :func:`flexsheet.cli.build_parser`, then each calibrate/experiment/bench NAME's own parser (its
    ``--help``, run in this process)."""
    from flexsheet import cli, registry

    found: list[Cmd] = []
    for path, parser in _walk(cli.build_parser(), ()):
        where = " ".join(("flexsheet", *path, "--help"))
        found += [Cmd(f"{where}:{i}", c) for i, c in enumerate(examples(parser.format_help()), 1)]
    for kind in DELEGATES:
        for name, spec in _delegate_table(kind).items():
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
                registry.load(spec)(["--help"])
            found += [Cmd(f"flexsheet {kind} {name} --help:{i}", c) for i,
                      c in enumerate(examples(buf.getvalue()), 1)]
    return found


def all_commands() -> list[Cmd]:
    """Every command once (where it appears first), docs first."""
    seen: dict[str, Cmd] = {}
    for c in [c for rel in DOCS for c in doc_commands(ROOT / rel, rel)] + help_commands():
        seen.setdefault(c.cmd, c)
    return list(seen.values())


def subcommand_path(cmd: str) -> bool:
    """True for a bare subcommand named in prose (``flexsheet bag info``, ``flexsheet calibrate arms``)."""
    from flexsheet import cli

    words = cmd.split()
    if words[0] != "flexsheet" or len(words) < 2:
        return False
    tree = dict(_walk(cli.build_parser(), ()))
    if words[1] in DELEGATES:
        return len(words) == 3 and words[2] in _delegate_table(words[1])
    return tuple(words[1:]) in tree


# ----------------------------------------------------------------------------------------------- tables
P = "parse"     # CHEAP form: parse with the real parsers, check the files it names; do not run
LONG = "takes minutes (an experiment or benchmark of the figures); parsed with its own parser, not run"
LAB_HOST = ("this machine has none of the lab's addresses (10.77.0.x): the check runs and fails on exactly "
            "that (exit 78, nothing else wrong)")
LAB_TOOL = ("the lab's graph is not on this network: the tool loads the file and its keys, listens briefly "
            "(short --timeout/--window) and says nothing was heard (exit 1)")

#: command prefix -> why it cannot run here (real devices, the lab's network, root, another machine)
SKIP: dict[str, str] = {
    "ping -c 3 10.77.0.1": "needs the lab switch (10.77.0.x)",
    "ping -c 3 192.168.10.2": "needs an arm PC's private link to its controller",
    "sudo systemctl restart chrony": "root: restarts this host's time service (a lab PC's chrony.conf)",
    "chronyc tracking": "needs chrony synchronised to the lab's main PC (10.77.0.1)",
    "sudo ptp4l": "root and a PTP NIC on the lab switch",
    "sudo phc2sys": "root and a PTP NIC on the lab switch",
    "ssh arm1 ": "copies the arm PC's secrets to arm PC 1 over ssh",
    "ssh arm2 ": "copies the arm PC's secrets to arm PC 2 over ssh",
    "flexsheet bench camera --genicam --left 21234567": "needs two real GigE cameras with these serials, "
                                                        "hardware-triggered",
    "flexsheet calibrate display --live --launch launch/lab_sim.yaml": (
        "needs the lab on one machine running (minutes): tests/system/test_live_registration.py runs these "
        "commands (a drawn truth seed, without its true-sheet tables)"),
    "flexsheet calibrate display --live --launch launch/lab.yaml --host main --out": (
        "moves the lab's real arms (the graph up: cameras, arms, projector); its --dry-run runs as written"),
}

#: command -> (the cheaper form that runs instead, or P: parse only; why)
CHEAP: dict[str, tuple[str, str]] = {
    # the lab on one machine (docs/deploy.md): its checked
    # form; tests/system/test_live_registration.py runs it
    "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
    "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3 --set world.loop=true --out out/lab": (
        "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
        "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3 --set world.loop=true --out out/lab "
        "--check",
        "runs until Ctrl-C; tests/system/test_live_registration.py runs it"),
    "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
    "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3": (
        "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
        "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3 "
        "--check", "runs until Ctrl-C; the check of the same hosts"),
    "flexsheet launch launch/sim.yaml --rtf 1 --set world.loop=true": (
        "flexsheet launch launch/sim.yaml --rtf 1 --set world.loop=true --check",
        "runs until Ctrl-C; tests/system/test_simclock.py runs --rtf 1"),
    "flexsheet launch launch/sim.yaml --domain 3 --out out/d3": (
        "flexsheet launch launch/sim.yaml --domain 3 --out out/d3 --check",
        "the scripted run takes minutes; tests/system/test_domains.py runs two graphs in domains 3 and 4"),

    # launches: the check of the same file, host and settings (the live graph below runs launch/sim.yaml)
    "flexsheet launch launch/sim.yaml": ("flexsheet launch launch/sim.yaml --check",
                                         "the scripted run takes minutes; the live-graph cases run the file"),
    "flexsheet launch launch/sim.yaml --set twin.truth_seed=2 --set scene=launch/scenes/sphere.yaml": (
        "flexsheet launch launch/sim.yaml --set twin.truth_seed=2 --set scene=launch/scenes/sphere.yaml "
        "--check",
        "the scripted run takes minutes"),
    "flexsheet launch FILE --check --host H": ("flexsheet launch launch/lab.yaml --check --host arm2",
                                               "a template: the lab file and one of its hosts"),
    "flexsheet launch --check": ("flexsheet launch launch/sim.yaml --check", "the option, on the sim file"),
    "flexsheet launch launch/lab.yaml": ("flexsheet launch launch/lab.yaml --check", "the lab's three hosts"),
    "flexsheet calibrate display --live": (
        "parse: flexsheet calibrate display --live --launch launch/lab.yaml --host main --out "
        "out/registration",
        "a heading: the option, with the lab's file"),
    "flexsheet launch launch/lab.yaml --host arm1 --set arm_left.enabled=false": (
        "flexsheet launch launch/lab.yaml --host arm1 --set arm_left.enabled=false --check",
        "drives a real arm"),
    "flexsheet launch launch/lab.yaml --host arm2 --set arm_right.enabled=false": (
        "flexsheet launch launch/lab.yaml --host arm2 --set arm_right.enabled=false --check",
        "drives a real arm"),
    "flexsheet launch launch/lab.yaml --host main --out out/lab_dry": (
        "flexsheet launch launch/lab.yaml --host main --out out/lab_dry --check",
        "real cameras and projector"),
    "flexsheet launch launch/lab.yaml --host arm1": ("flexsheet launch launch/lab.yaml --host arm1 --check",
                                                     "drives a real arm"),
    "flexsheet launch launch/lab.yaml --host arm2": ("flexsheet launch launch/lab.yaml --host arm2 --check",
                                                     "drives a real arm"),
    "flexsheet launch launch/lab.yaml --host main --out out/lab": (
        "flexsheet launch launch/lab.yaml --host main --out out/lab --check", "real cameras and projector"),
    # the run-time tools on the lab's file
    "flexsheet topic echo /arm/left/joint_state --launch launch/lab.yaml --count 3": (
        "flexsheet topic echo /arm/left/joint_state --launch launch/lab.yaml --count 3 --timeout "
        "0.5", LAB_TOOL),
    "flexsheet node list --launch launch/lab.yaml": ("flexsheet node list --launch launch/lab.yaml --timeout "
                                                     "0.5",
                                                     LAB_TOOL),
    "flexsheet topic hz /fingertip --launch launch/lab.yaml": (
        "flexsheet topic hz /fingertip --launch launch/lab.yaml --window 0.5", LAB_TOOL),
    "flexsheet topic echo /arm/left/target --launch launch/lab.yaml --count 3": (
        "flexsheet topic echo /arm/left/target --launch launch/lab.yaml --count 3 --timeout 0.5", LAB_TOOL),
    "flexsheet param list planner --launch launch/lab.yaml": (
        "flexsheet param list planner --launch launch/lab.yaml --timeout 0.5", LAB_TOOL),
    # calibration: 4 of the 17 shipped XIMEA pairs stand for the lab's captures (all 17: ~20 s)
    "flexsheet calibrate stereo --left 'calib/left*.png' --right 'calib/right*.png' --board chessboard:9x6 "
    "--square 0.024 -o ~/.flexsheet/stereo.yaml": (
        "flexsheet calibrate stereo --left 'tests/data/stereo_xi/left0[1-4].jpg' --right "
        "'tests/data/stereo_xi/right0[1-4].jpg' --board chessboard:9x6 --square 0.024 -o "
        "~/.flexsheet/stereo.yaml",
        "the lab's captured pairs: 4 shipped XIMEA pairs instead"),
    "flexsheet calibrate stereo --left 'tests/data/stereo_xi/left*.jpg' --right "
    "'tests/data/stereo_xi/right*.jpg' --board chessboard:9x6 --square 0.024 -o calib.yaml": (
        "flexsheet calibrate stereo --left 'tests/data/stereo_xi/left0[1-4].jpg' --right "
        "'tests/data/stereo_xi/right0[1-4].jpg' --board chessboard:9x6 --square 0.024 -o calib.yaml",
        "4 of the 17 pairs (all 17: ~20 s)"),
    "flexsheet calibrate stereo --left 'tests/data/stereo_xi/left*.jpg' --right "
    "'tests/data/stereo_xi/right*.jpg' --board chessboard:9x6 --square 0.024 -o calib.yaml --validate 0": (
        "flexsheet calibrate stereo --left 'tests/data/stereo_xi/left0[1-4].jpg' --right "
        "'tests/data/stereo_xi/right0[1-4].jpg' --board chessboard:9x6 --square 0.024 -o calib.yaml "
        "--validate 0",
        "4 of the 17 pairs (all 17: ~20 s)"),
    "python -m flexsheet.twin.truth --bootstrap DIR": (
        "python -m flexsheet.twin.truth --help | grep -q -- '--bootstrap DIR'",
        "40 resampled stereo calibrations take minutes: the module and its option are there"),
    "flexsheet calibrate display --sim --truth-seed N --out DIR": (
        "parse: flexsheet calibrate display --sim --truth-seed 1 --out out/disp1",
        "a template; minutes per seed"),
    "flexsheet calibrate display --sim --truth-seed 0 --out out/calib": (P,
                                                                         "the full registration: ~1-2 min"),
    "flexsheet calibrate display --sim --truth-seed 0 --out out/cal0": (P, "the full registration: ~1-2 min"),
    "flexsheet calibrate display --sim --truth-seed 1 --quick --out /tmp/disp1":
        (P, "the twin's registration: ~1 min"),
    "flexsheet calibrate display --sweep --seeds 1,2,3 --out docs/figures/calibration": (P, LONG),
    "flexsheet calibrate display --draws 40 --out docs/figures/calibration/draws": (P, LONG),
    # the sandbox's docs/figures starts empty: the committed readings are written there first (seed 0: ~1 s)
    "flexsheet calibrate sheet --presses docs/figures/calibration/sheet/presses.csv --out /tmp/disp": (
        "flexsheet calibrate sheet --sim --truth-seed 0 --out docs/figures/calibration/sheet && "
        "flexsheet calibrate sheet --presses docs/figures/calibration/sheet/presses.csv --out /tmp/disp",
        "writes the readings it reads first"),
    "flexsheet calibrate camera-pose --sim --truth-seed 1 --quick --out /tmp/disp":
        (P, "renders and fits 12+ views"),
    "flexsheet calibrate projector --sim --truth-seed 1 --quick --out /tmp/disp": (P,
                                                                                   "renders 4 x 42 patterns"),
    "flexsheet calibrate arms --sim --truth-seed 1 --quick --out /tmp/disp":
        (P, "renders 2 x 12 configurations"),
    "flexsheet calibrate camera-pose --images lab/frames --out lab/": (
        P, "the lab's frames (docs/deploy.md's camera-pose step runs on blank frames in that layout)"),
    "flexsheet calibrate noise --images /work/shared/data/stereo_calib_xi --out "
    "docs/figures/calibration/ximea_noise.json": (P, "re-renders every real view: minutes"),
    # the run-time tools' recorders: one second instead of until Ctrl-C / ten
    "flexsheet bag record -o run.mcap /fingertip /sheet/target": (
        "flexsheet bag record -o run.mcap /fingertip /sheet/target --duration 1", "until Ctrl-C: 1 s"),
    "flexsheet bag record -o run.mcap --duration 10": ("flexsheet bag record -o run.mcap --duration 1",
                                                       "1 s"),
    # on a port of its own: the next case (bag play --loop) binds the default one
    "flexsheet bag play run.mcap --rate 0.5": ("flexsheet bag play run.mcap --rate 0.5 --endpoint tcp://127.0.0.1:7198",
                                                "its own port"),
    # experiments and benchmarks
    **{c: (P, LONG) for c in (
        "flexsheet experiment stroke --out out/stroke",
        "flexsheet experiment stroke --out docs/figures/stroke",
        "flexsheet experiment stroke --out /tmp/s --seeds 0 --set triangulator.tracking_index=0.3",
        # the slow tier's test_experiments_quick
        "flexsheet experiment stroke --quick --out /tmp/stroke_quick",
        "flexsheet experiment objects --quick --out /tmp/objects_quick",
        "flexsheet experiment objects --draws 8 --reference --out docs/figures/objects",
        "flexsheet experiment objects --first 3 --draws 1 --out /tmp/objects",
        "flexsheet experiment reach --draws 6 --out docs/figures/objects/reach",
        "flexsheet experiment reach --first 3 --draws 1 --samples 6 --out /tmp/reach",
        "flexsheet experiment stability --graph --out docs/figures/stroke/stability",
        "flexsheet experiment stroke_model --out docs/figures/planner",
        "flexsheet experiment stroke_model --out /tmp/s --seeds 1 --display-calib "
        "'out/cal{seed}/display.yaml'",
        "flexsheet experiment scenes --out docs/figures/scenes",
        "flexsheet experiment scenes --out /tmp/sc --quick --scene organ",
        "flexsheet experiment fem --out out/fem --quick",
        "flexsheet experiment fem --quick --out /tmp/fem",
        "flexsheet experiment fem --out /tmp/fem --node-table --azimuth 10",
        "flexsheet experiment fem --quick --mirror-study --out /tmp/fem",
        "flexsheet experiment fem --holdout-study --out /tmp/fem",
        "flexsheet experiment fem --quick --fold-study --out /tmp/fem",
        "flexsheet experiment fem --quick --material-study --out /tmp/fem",
        "flexsheet experiment fem --quick --scene launch/scenes/sphere.yaml --out /tmp/fem_sphere",
        "flexsheet experiment fem --scene launch/scenes/rounded_box.yaml --node-table --jobs 2 --out "
        "/tmp/rb_table",
        "flexsheet experiment correction --twin realistic --truth-seed 0 --quick --out /tmp/corr",
        "flexsheet experiment correction --twin both --seeds 0 1 2 --stability --speed --out "
        "docs/figures/renderer",
        "flexsheet experiment stability --quick --out /tmp/stab",
        "flexsheet experiment compliance --scene launch/scenes/organ.yaml --sheet "
        "docs/figures/calibration/sheet/sheet.json --out docs/figures/compliance",
        "flexsheet experiment latency_load --out docs/figures/realtime",
        "flexsheet experiment latency_load --out /tmp/ll --busy 0 2",
        "flexsheet experiment determinism --out docs/figures/simclock",
        "flexsheet experiment speed --out /tmp/speed --duration 10 --cut head30=head_camera.rate_hz=30",
        "flexsheet experiment speed --out docs/figures/speed --before /tmp/before",
        "flexsheet experiment head_rate --out docs/figures/head_rate --rates 60 30 20",
        "flexsheet experiment determinism --quick --out /tmp/det",           # run by the slow tier's
        "flexsheet experiment latency_load --out /tmp/ll --quick",  # tests/system/test_experiments_quick.py
        "flexsheet experiment faults --out docs/figures/faults",
        "flexsheet experiment triangulation --out docs/figures/vision",
        "flexsheet experiment triangulation --out /tmp/tri --quick",
        "flexsheet bench transport --json",
        "flexsheet bench vision --json",
        "flexsheet bench camera --genicam --seconds 10 --json",
        "flexsheet bench arm --json --cycles 2000 --out docs/figures/arm",
        "flexsheet bench arm --protocol mxt --json --cycles 10000 --out docs/figures/arm",
        "flexsheet bench fem --json",
        "flexsheet bench fem_startup --scene launch/scenes/organ.yaml --json",
        "flexsheet bench render --window --xvfb --seconds 5 --json",
        "flexsheet bench load --seconds 60 --out docs/figures/reliability",
        "flexsheet bench viz --out out/bench_viz --runs 3",
        "flexsheet bench viz --out out/bench_viz_10hz --param scene_rate=10 --param input_rate=10 "
        "--baseline out/bench_viz/viz_cpu.json",
        "flexsheet bench graph --seconds 10 --json > graph_bench.json",
        "flexsheet bench sim --duration 20 --out docs/figures/bench",
        "flexsheet bench sim --set scene=launch/scenes/organ.yaml --json",
        "flexsheet bench sim --duration 20 --profile --out docs/figures/bench",
        "flexsheet bench replay --out docs/figures/bench",
        "flexsheet bench replay --bag out/sim/sim.mcap --runs 3 --json",
    )},
}

#: lab checks that fail here on purpose: every error line
#: must be one of these (and at least one must be there)
LAB_ERRORS = re.compile(r"not an address of this machine|: probe: camera \w+: camera '\w+' not found"
                        r"|node head_camera: probe: head camera: cannot open UVC device '/dev/video0'")
#: command (as written) -> (exit status, a regex its output must match, why)
EXPECT: dict[str, tuple[int, str, str]] = {
    **{c: (78, "LAB", LAB_HOST) for c in (
        "flexsheet launch launch/lab.yaml --check --host main --probe",
        "flexsheet launch launch/lab.yaml --check --host arm1",
        "flexsheet launch launch/lab.yaml --check --host arm2",
        "flexsheet launch launch/lab.yaml",
        "flexsheet launch launch/lab.yaml --check --host main --set "
        "camera.calib_file=$HOME/.flexsheet/stereo.yaml",
        "flexsheet launch launch/lab.yaml --check --host main",
        "flexsheet launch FILE --check --host H",
        "flexsheet launch launch/lab.yaml --host arm1 --set arm_left.enabled=false",
        "flexsheet launch launch/lab.yaml --host arm2 --set arm_right.enabled=false",
        "flexsheet launch launch/lab.yaml --host main --out out/lab_dry",
        "flexsheet launch launch/lab.yaml --host arm1",
        "flexsheet launch launch/lab.yaml --host arm2",
        "flexsheet launch launch/lab.yaml --host main --out out/lab",
        "FLEXSHEET_KEYS=/tmp/k flexsheet keys generate --launch launch/lab.yaml && FLEXSHEET_KEYS=/tmp/k "
        "flexsheet launch launch/lab.yaml --check --host arm1",
    )},
    "flexsheet run arm_bridge --launch launch/lab.yaml --name arm_left --param enabled=false": (
        78, r"cannot bind publisher endpoint 'tcp://10\.77\.0\.2:", "the node needs arm PC 1's address"),
    "flexsheet run renderer --launch launch/lab.yaml --name renderer": (
        78, r"cannot bind publisher endpoint 'tcp://10\.77\.0\.1:", "the node needs the main PC's address"),
    **{c: (1, r"no message on|not heard|no live nodes heard|: 0 messages in", LAB_TOOL) for c in (
        "flexsheet topic echo /arm/left/joint_state --launch launch/lab.yaml --count 3",
        "flexsheet node list --launch launch/lab.yaml",
        "flexsheet topic hz /fingertip --launch launch/lab.yaml",
        "flexsheet topic echo /arm/left/target --launch launch/lab.yaml --count 3",
        "flexsheet param list planner --launch launch/lab.yaml",
    )},
    # the registration steps on blank frames in the documented
    # folder layout: read, then refused by the estimator
    "flexsheet calibrate camera-pose --images ~/reg --out ~/.flexsheet": (
        2, r"board not found in the home view", "blank frames in the documented layout "
                                                "(docs/calibration.md)"),
    "flexsheet calibrate projector --images ~/reg --out ~/.flexsheet": (
        2, r"patterns did not decode", "blank frames in the documented layout (docs/calibration.md)"),
    "flexsheet calibrate arms --images ~/reg --out ~/.flexsheet": (
        2, r"usable marker configurations", "blank frames in the documented layout (docs/calibration.md)"),
}

#: shell run before the command, in the sandbox ($REPO: the repository; $TWIN_DISPLAY: the display.yaml the
#: live graph's twin registration wrote)
_BLANK_FRAMES = ("python - <<'EOF'\nimport json, os, cv2, numpy as np\nroot = os.path.expanduser('~/reg')\n"
                 "def blank(p):\n    os.makedirs(os.path.dirname(p), exist_ok=True)\n"
                 "    cv2.imwrite(p, np.zeros((512, 640), np.uint8))\n"
                 "for s in ('left', 'right'):\n    blank(f'{root}/camera_pose/view00_{s}.png')\n"
                 "    for i in range(42):\n        blank(f'{root}/projector/pose00/img{i:02d}_{s}.png')\n"
                 "    for a in ('left', 'right'):\n        blank(f'{root}/arms/{a}/config00_{s}.png')\n"
                 "json.dump({'arms': {a: {'joints': [[0.0] * 6]} for a in ('left', 'right')}, "
                 "'projector': {'width': 1024, 'height': 768}}, open(f'{root}/manifest.json', 'w'))\nEOF\n")
_CAMERA_ENTRY = 'mkdir -p ~/.flexsheet && cp "$TWIN_DISPLAY" ~/.flexsheet/display.yaml\n'
_LAB_KEYS = "flexsheet keys generate --launch launch/lab_sim.yaml >/dev/null\n"
PREP: dict[str, str] = {
    "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
    "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3 --set world.loop=true --out "
    "out/lab": _LAB_KEYS,
    "flexsheet launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
    "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3": _LAB_KEYS,
    "flexsheet launch launch/lab.yaml --check --host main --set "
    "camera.calib_file=$HOME/.flexsheet/stereo.yaml":
        "mkdir -p ~/.flexsheet && cp $REPO/flexsheet/vision/ximea_calib.yaml ~/.flexsheet/stereo.yaml\n",
    "flexsheet calibrate camera-pose --images ~/reg --out ~/.flexsheet": _BLANK_FRAMES,
    "flexsheet calibrate projector --images ~/reg --out ~/.flexsheet": _BLANK_FRAMES + _CAMERA_ENTRY,
    "flexsheet calibrate arms --images ~/reg --out ~/.flexsheet": _BLANK_FRAMES + _CAMERA_ENTRY,
    "flexsheet run --container main_pc --launch launch/sim_composed.yaml --host main "
    "--set camera.display_calib=out/calib/display.yaml": 'mkdir -p out/calib && cp "$TWIN_DISPLAY" '
                                                         'out/calib/\n',
    "flexsheet bag recover cut.mcap fixed.mcap": "head -c $(( $(stat -c %s run.mcap) * 2 / 3 )) run.mcap > "
                                                 "cut.mcap\n",
}

#: the server of the live graph: runs until its tools are done, then Ctrl-C (its bag and report are written)
GRAPH = "flexsheet launch launch/sim.yaml --duration 60 --out out/sim"
#: commands run (as written, or in their CHEAP form) against the live launch/sim.yaml graph, several at a
#: time; the recorders one after the other, the one of /fingertip last (the bag the other bag examples read)
LIVE = (
    "flexsheet topic list", "flexsheet topic list --json", "flexsheet topic info /fingertip",
    "flexsheet topic info /fingertip --json", "flexsheet topic echo /fingertip --count 3",
    "flexsheet topic echo /fingertip --count 2 --json", "flexsheet topic hz /camera/stereo",
    "flexsheet topic bw /camera/stereo --json", "flexsheet topic hz /fingertip --window 2",
    "flexsheet topic bw /fingertip --window 2",
    'flexsheet topic pub /fingertip "{position: [0.0, 0.0, 0.01], covariance: [[1.0e-8, 0, 0], [0, 1.0e-8, '
    '0], [0, 0, 1.0e-8]], valid: true, predicted_position: [0.0, 0.0, 0.01], exposure_stamp: 0.0}" --times 5 '
    '--rate 10',
    "flexsheet node list", "flexsheet node info planner", "flexsheet node list --launch launch/sim.yaml "
                                                          "--json",
    "flexsheet node info planner --launch launch/sim.yaml", "flexsheet param list planner",
    "flexsheet param list planner --json", "flexsheet param get planner stiffness_scale",
    "flexsheet param set planner stiffness_scale 0.5", "flexsheet service list planner",
    'flexsheet service call planner param/get "{name: stiffness_scale}"', "flexsheet service list fem",
    "flexsheet topic hz /fingertip",
)
LIVE_IN_ORDER = ("flexsheet bag record -o run.mcap --duration 10", "flexsheet bag record -o run.mcap "
                 "/fingertip /sheet/target")
#: commands that read what the live graph left (its bag, run.mcap, the twin's display.yaml): run after it
AFTER_GRAPH = (
    "flexsheet bag info run.mcap", "flexsheet bag play run.mcap --rate 0.5", "flexsheet bag export run.mcap "
    "run_json.mcap", "flexsheet bag recover cut.mcap fixed.mcap",
    "flexsheet bag recover out/sim/sim.mcap out/sim/sim_recovered.mcap",
    "flexsheet calibrate projector --images ~/reg --out ~/.flexsheet",
    "flexsheet calibrate arms --images ~/reg --out ~/.flexsheet",
    "flexsheet bag play out/sim/sim.mcap --loop", "flexsheet run viz --peer tcp://127.0.0.1:7199",
)
#: nodes that run until Ctrl-C -> a line of their output that says they are up (then Ctrl-C; they must exit 0)
INTERRUPT: dict[str, str] = {
    "flexsheet run planner --launch launch/sim.yaml --param use_prediction=false": r"planner up:",
    "flexsheet run --container main_pc --launch launch/sim_composed.yaml --host main "
    "--set camera.display_calib=out/calib/display.yaml": r"camera up:(.|\n)*planner up:|planner "
                                                         r"up:(.|\n)*camera up:",
    "flexsheet bag play out/sim/sim.mcap --loop": r"playing out/sim/sim\.mcap on tcp://",
    "flexsheet run viz --peer tcp://127.0.0.1:7199": r"viz up:",
}
#: the talker and the listener of ``flexsheet run --help``:
#: started together, the listener must hear the talker
TALKER = "flexsheet run talker --param rate=5 --endpoint tcp://127.0.0.1:7201"
LISTENER = "flexsheet run listener --peer tcp://127.0.0.1:7201"
SERIAL = {*LIVE, *LIVE_IN_ORDER, *AFTER_GRAPH, *INTERRUPT, GRAPH, TALKER, LISTENER}


def table_keys() -> list[tuple[str, str]]:
    return ([("SKIP", k) for k in SKIP] + [("CHEAP", k) for k in CHEAP] + [("EXPECT", k) for k in EXPECT]
            + [("PREP", k) for k in PREP] + [("LIVE", k) for k in (*LIVE, *LIVE_IN_ORDER, GRAPH)]
            + [("AFTER_GRAPH", k) for k in AFTER_GRAPH]
            + [("INTERRUPT", k) for k in (*INTERRUPT, TALKER, LISTENER)])


def skip_reason(cmd: str) -> str | None:
    return next((why for prefix, why in SKIP.items() if cmd.startswith(prefix)), None)


# ------------------------------------------------------------------------------------------- the sandbox
REAL_HOME = Path(os.path.expanduser("~"))


def make_sandbox(sb: Path) -> Path:
    """A working folder the commands run in as if it were the repository: its code and test data linked, its
    own launch/ (the launch files with their ports moved to free ones, so that a graph here cannot collide
    with another on this machine), docs/figures/, out/ and tmp/ for what the commands write (``/tmp/`` paths
    are moved there), and its own HOME (``~/.flexsheet``: keys, display.yaml) whose ``.cache`` is the real one
    (the FEM models and the twin's registrations, cached per machine). The lab file's CURVE keys are generated
    there first, so that a check of the lab file fails on the lab's addresses alone."""
    import yaml

    from flexsheet.runtime.keys import generate
    from flexsheet.runtime.launch import identities, load_launch
    from flexsheet.runtime.ports import free_port

    for name in ("flexsheet", "nodes", "messages", "tests", "docker", "pyproject.toml"):
        (sb / name).symlink_to(ROOT / name)
    (sb / "launch").mkdir()
    for src in sorted((ROOT / "launch").iterdir()):
        dst = sb / "launch" / src.name
        if src.suffix == ".yaml" and "127.0.0.1" in src.read_text():
            lf = yaml.safe_load(src.read_text())
            lf["base_port"] = free_port(span=len(lf["nodes"]) + 10)
            moved: dict[int, int] = {}        # a controller twin and its bridge share their port
            for spec in lf["nodes"].values():
                if "port" in spec.get("params", {}):
                    spec["params"]["port"] = moved.setdefault(spec["params"]["port"], free_port())
            dst.write_text(yaml.safe_dump(lf, sort_keys=False))
        else:
            dst.symlink_to(src)
    for d in ("docs/figures", "out", "tmp", "home", "bin"):
        (sb / d).mkdir(parents=True)
    (sb / "home" / ".cache").symlink_to(REAL_HOME / ".cache")
    wrapper = sb / "bin" / "flexsheet"
    wrapper.write_text(f'#!/bin/sh\nexec {sys.executable} -m flexsheet "$@"\n')
    wrapper.chmod(0o755)
    # a script, not a link: CPython finds the venv's pyvenv.cfg from the path it was started by, and a link
    # outside the venv's folder would start the base Python, without the project's packages
    for name in ("python", "python3"):
        (sb / "bin" / name).write_text(f'#!/bin/sh\nexec {sys.executable} "$@"\n')
        (sb / "bin" / name).chmod(0o755)
    lab = load_launch(str(ROOT / "launch" / "lab.yaml"))
    generate(identities(lab), sb / "home" / ".flexsheet" / "keys")
    return sb


def sandbox_env(sb: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("FLEXSHEET_KEYS", "FLEXSHEET_LAUNCH")}
    env.update(HOME=str(sb / "home"), PATH=f"{sb / 'bin'}{os.pathsep}{env.get('PATH', '')}", REPO=str(ROOT),
               PYTHONDONTWRITEBYTECODE="1", FLEXSHEET_GRAPH_DIR=str(sb / "graph"), **extra)
    return env


_PORTS: dict[str, int] = {}


def localize(cmd: str, sb: Path) -> str:
    """The command as it runs in the sandbox: ``/tmp/`` paths under the sandbox's tmp/, and a fixed local TCP
    port moved to a free one (the same one for every command that names it)."""
    from flexsheet.runtime.ports import free_port

    cmd = re.sub(r"(?<![\w.])/tmp/", f"{sb}/tmp/", cmd)
    return re.sub(r"tcp://127\.0\.0\.1:(\d+)",
                  lambda m: f"tcp://127.0.0.1:{_PORTS.setdefault(m.group(1), free_port())}", cmd)


@dataclass
class Result:
    cmd: str
    code: int | str          # exit status, or "timeout"
    out: str
    err: str
    seconds: float

    def __str__(self) -> str:
        return (f"$ {self.cmd}\nexit {self.code} after {self.seconds:.1f} s\n--- stdout\n{self.out[-3000:]}"
                f"\n--- stderr\n{self.err[-3000:]}")


class Proc:
    """``bash -c cmd`` in the sandbox, in its own process group, its output collected as it comes."""

    def __init__(self, cmd: str, sb: Path, **env: str) -> None:
        self.cmd, self.t0 = cmd, time.monotonic()
        self.proc = subprocess.Popen(["bash", "-c", cmd], cwd=sb, env=sandbox_env(sb, **env), text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        self.chunks: dict[str, list[str]] = {"out": [], "err": []}
        self.readers = [threading.Thread(target=lambda f=f, k=k: self.chunks[k].extend(iter(f.readline, "")),
                                         daemon=True) for f,
                        k in ((self.proc.stdout, "out"), (self.proc.stderr, "err"))]
        for r in self.readers:
            r.start()

    def text(self) -> str:
        return "".join(self.chunks["out"] + self.chunks["err"])

    def interrupt(self) -> None:
        """Ctrl-C: SIGINT to its process group."""
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGINT)

    def wait(self, timeout: float = BUDGET_S, up: str | None = None) -> Result:
        """Its result once it ends; killed after ``timeout`` s (code "timeout"). ``up``: a regex of its output
        that says it is up: then Ctrl-C, as a user stops a node."""
        code: int | str = "timeout"
        deadline = time.monotonic() + timeout
        interrupted = False
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                code = self.proc.returncode
                break
            if up and not interrupted and re.search(up, self.text()):
                time.sleep(0.5)
                self.interrupt()
                interrupted = True
            time.sleep(0.05)
        else:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        for r in self.readers:
            r.join(timeout=5)
        return Result(self.cmd, code, "".join(self.chunks["out"]), "".join(self.chunks["err"]),
                      time.monotonic() - self.t0)


def run_shell(cmd: str, sb: Path, timeout: float = BUDGET_S, up: str | None = None, **env: str) -> Result:
    """Run ``cmd`` in the sandbox to its end (:class:`Proc`)."""
    return Proc(cmd, sb, **env).wait(timeout, up)


def check_result(r: Result, original: str, why: str = "") -> None:
    """The command's exit status and output are what :data:`EXPECT` says (exit 0 when it says nothing)."""
    if r.code == "timeout":
        pytest.fail(f"over the budget ({BUDGET_S:.0f} s): give it a cheap form in CHEAP (or a SKIP "
                    f"reason)\n{r}")
    code, pattern, _ = EXPECT.get(original, (0, "", ""))
    assert r.code == code, f"expected exit {code}{' (' + why + ')' if why else ''}\n{r}"
    if pattern == "LAB":
        errors = [line for line in r.err.splitlines() if line.startswith("launch/lab.yaml: ")
                  and not line.startswith("launch/lab.yaml: warning:")]
        assert (errors
                and all(LAB_ERRORS.search(line)
                        for line in errors)), f"errors beyond the lab's addresses\n{r}"
    elif pattern:
        assert re.search(pattern, r.out + r.err), f"expected {pattern!r} in its output\n{r}"
    assert "Traceback (most recent call last)" not in r.err, f"a traceback\n{r}"


# ------------------------------------------------------------------------------------------- parse only
class _Parsed(Exception):
    pass


def parse_only(cmd: str) -> None:
    """Parse ``cmd`` (``flexsheet ...``) with the real parsers, as far as the calibrate/experiment/bench
    NAME's own (its ``parse_args`` returns, then it stops), and check that every repository file it names
    (``launch/``, ``tests/``, ``flexsheet/``, ``docker/``) exists. Fails with the parser's message."""
    from flexsheet import cli, registry

    words = [w for w in shlex.split(cmd) if not re.match(r"^[A-Z_]+=", w)]
    if ">" in words:
        words = words[:words.index(">")]
    assert words[0] == "flexsheet", cmd
    argv = words[1:]
    for w in argv:
        for part in w.split("="):
            if re.match(r"^(launch|tests|flexsheet|docker)/", part):
                assert glob.glob(str(ROOT / part)), f"{cmd}: {part} does not exist"
    err = io.StringIO()
    original = argparse.ArgumentParser.parse_args

    def parse_and_stop(self, args=None, namespace=None):
        raise _Parsed(original(self, args, namespace))

    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            args = cli.build_parser().parse_args(argv)
            if args.command not in DELEGATES:
                return
            main = registry.load(_delegate_table(args.command)[args.name])
            with mock.patch.object(argparse.ArgumentParser, "parse_args", parse_and_stop):
                main(args.rest)
        except _Parsed:
            return
        except SystemExit as exc:
            if exc.code in (0, None) and "--help" in argv:
                return
            pytest.fail(f"{cmd}: does not parse (exit {exc.code}):\n{err.getvalue()}")
    pytest.fail(f"{cmd}: ran without parsing its arguments with argparse")


# ------------------------------------------------------------------------------------------- fixtures
COMMANDS = all_commands()


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory) -> Path:
    return make_sandbox(tmp_path_factory.mktemp("docs_run"))


def _form(cmd: str) -> str:
    form = CHEAP.get(cmd, (cmd, ""))[0]
    return cmd if form == P else form


@pytest.fixture(scope="module")
def sim_graph(sandbox, sim_fem_cache) -> dict[str, Result | str]:
    """:data:`GRAPH` (launch/sim.yaml on free ports) up; then every :data:`LIVE` command against it, six at a
    time (the :data:`LIVE_IN_ORDER` ones in turn on one worker); then Ctrl-C. Returns each command's
    :class:`Result`, the launch's under :data:`GRAPH`, and the display.yaml of its twin registration under
    ``"display.yaml"``. A container killed by a signal fails the tests (:func:`_tail` shows its line
    first)."""
    results, failure = _sim_graph_once(sandbox)
    if failure is not None:
        raise failure
    return results


def _tail(launch: Proc) -> str:
    """The launch's output for a failure: any line of a process killed by a signal, then its last 4000
    characters (the report)."""
    text = launch.text()
    return "".join(m.group(0) + "\n" for m in KILLED.finditer(text)) + text[-4000:]


def _sim_graph_once(sandbox: Path) -> tuple[dict[str, Result | str], AssertionError | None]:
    """One run of :func:`sim_graph`: its results (the launch's always, under :data:`GRAPH`) and the failure
    that ended it early, if any."""
    launch = Proc(localize(GRAPH, sandbox), sandbox)
    results: dict[str, Result | str] = {}
    up = failure = None
    try:
        deadline = time.monotonic() + 240          # a cold machine registers the twin and precomputes the FEM
        while "every node active" not in launch.text():
            assert launch.proc.poll() is None and time.monotonic() < deadline, \
                "the sim did not come up:\n" + _tail(launch)
            time.sleep(0.1)
        time.sleep(1.0)                             # the first frames and heartbeats
        # on a cold cache a node may still be building a table in the graph's one process (no heartbeat
        # meanwhile): the tools run once every node of the graph is heard
        while run_shell("flexsheet node list --timeout 5", sandbox).out.count("state=") < 12:
            assert launch.proc.poll() is None and time.monotonic() < deadline, \
                "the sim's nodes were not heard:\n" + _tail(launch)
        up = time.monotonic() - launch.t0

        def in_order() -> list[Result]:
            return [run_shell(localize(_form(c), sandbox), sandbox) for c in LIVE_IN_ORDER]

        with ThreadPoolExecutor(max_workers=6) as pool:
            ordered = pool.submit(in_order)
            results.update(zip(LIVE,
                               pool.map(lambda c: run_shell(localize(_form(c), sandbox), sandbox), LIVE),
                               strict=True))
            results.update(zip(LIVE_IN_ORDER, ordered.result(), strict=True))
        # the run's report judges Table I (exit 1 without a row): the first segment, the 10 s
        # stroke, must be over before Ctrl-C, however slowly the graph ran beside its tools
        while "segment 2/3" not in launch.text():
            assert launch.proc.poll() is None and time.monotonic() < deadline + 120, \
                "the sim did not finish its first segment:\n" + _tail(launch)
            time.sleep(0.2)
    except AssertionError as exc:
        failure = exc
    finally:
        t1 = time.monotonic()
        launch.interrupt()  # Ctrl-C: the launch stops its nodes, then writes its report
        r = launch.wait(120)
    results[GRAPH] = r
    m = re.search(r"twin registration: (\S+display\.yaml)", r.out + r.err)
    results["display.yaml"] = m.group(1) if m else ""
    if failure is None:
        print(f"sim graph: up in {up:.1f} s, its tools {t1 - launch.t0 - up:.1f} s, stopped in "
              f"{time.monotonic() - t1:.1f} s")
    return results, failure


def read_only(cmd: str) -> bool:
    """A check or a look at the lab's graph: writes nothing the others read, so :func:`batch` runs it beside
    another (not a keys command, nothing with a PREP step)."""
    form = _form(cmd)
    return ((" --check" in form or "--launch launch/lab.yaml" in form) and "keys" not in form
            and cmd not in PREP and cmd not in SERIAL and not skip_reason(cmd)
            and CHEAP.get(cmd, ("",))[0] != P
            and not form.startswith("parse: "))


@pytest.fixture(scope="module")
def batch(sandbox) -> dict[str, Result]:
    """The :func:`read_only` commands, two at a time (a check is ~1 s of Python start-up and imports)."""
    cmds = [c.cmd for c in COMMANDS if read_only(c.cmd)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(cmds, pool.map(lambda c: run_shell(localize(_form(c), sandbox), sandbox), cmds),
                        strict=True))


@pytest.fixture(scope="module")
def talker_listener(sandbox) -> dict[str, Result]:
    """The talker and the listener of ``flexsheet run --help``, together; Ctrl-C to both once it has heard."""
    talker = Proc(localize(TALKER, sandbox), sandbox)
    try:
        heard = run_shell(localize(LISTENER, sandbox), sandbox, up=r"heard seq=\d+(.|\n)*heard seq=")
    finally:
        talker.interrupt()
    return {TALKER: talker.wait(30), LISTENER: heard}


# ------------------------------------------------------------------------------------------- the tests
def _cases():
    for c in COMMANDS:
        marks = [pytest.mark.serial] if c.cmd in SERIAL else []
        yield pytest.param(c, id=c.id, marks=marks)


@pytest.mark.parametrize("c", list(_cases()))
def test_command_runs(c: Cmd, request):
    cmd = c.cmd
    if why := skip_reason(cmd):
        pytest.skip(f"{cmd}: {why}")
    form, why = CHEAP.get(cmd, (cmd, ""))
    if form == P or form.startswith("parse: "):
        parse_only(cmd if form == P else form.removeprefix("parse: "))
        return
    if subcommand_path(cmd) and cmd not in SERIAL:
        parse_only(cmd + " --help")
        return
    sb = request.getfixturevalue("sandbox")
    if cmd in (*LIVE, *LIVE_IN_ORDER, GRAPH):
        r = request.getfixturevalue("sim_graph")[cmd]
        if cmd == GRAPH:
            assert list((sb / "out" / "sim").glob("sim.mcap")), f"no bag out/sim/sim.mcap\n{r}"
    elif cmd in (TALKER, LISTENER):
        r = request.getfixturevalue("talker_listener")[cmd]
        if cmd == LISTENER:
            assert "heard seq=" in r.out, f"the listener heard nothing from the talker\n{r}"
    elif read_only(cmd):
        r = request.getfixturevalue("batch")[cmd]
    else:
        env = {}
        if cmd in AFTER_GRAPH or cmd in INTERRUPT:
            env["TWIN_DISPLAY"] = request.getfixturevalue("sim_graph")["display.yaml"]
        r = run_shell(PREP.get(cmd, "") + localize(form, sb), sb, up=INTERRUPT.get(cmd), **env)
    check_result(r, cmd, why)


def test_the_tables_name_only_current_commands():
    """A table entry whose command is gone from the docs and the help (renamed, fixed, removed) is stale."""
    current = {c.cmd for c in COMMANDS}
    stale = [f"{table}: {key!r}" for table, key in table_keys()
             if (key not in current if table != "SKIP" else not any(c.startswith(key) for c in current))]
    assert stale == [], "table entries for commands no longer in the docs or the help:\n" + "\n".join(stale)


def test_a_command_is_run_one_way():
    """No command both skipped and run, or run both live and alone."""
    ways = {}
    for c in COMMANDS:
        w = [name for name, hit in (("SKIP", skip_reason(c.cmd)), ("CHEAP", c.cmd in CHEAP),
                                    ("LIVE", c.cmd in (*LIVE, *LIVE_IN_ORDER)),
                                    ("INTERRUPT", c.cmd in INTERRUPT))
             if hit]
        if len(w) > 1 and w != ["CHEAP", "LIVE"]:
            ways[c.cmd] = w
    assert ways == {}


def test_the_extraction_finds_fences_lines_spans_and_examples(tmp_path):
    """The extractor is not vacuous: a planted page gives its fenced, console, bare-line and inline commands
    with their lines, and the help walk finds examples of nested parsers and of the NAMEs' own parsers."""
    page = tmp_path / "p.md"
    page.write_text("intro `flexsheet bag info` and `flexsheet/cli.py`\n```bash\n# a comment\n"
                    "flexsheet keys generate --launch x.yaml   # note\nflexsheet a \\\n  --b\n```\n"
                    "```\nnot a command\n```\n```console\n$ ls -l\noutput\n```\nflexsheet topic list\n")
    got = [(c.id, c.cmd) for c in doc_commands(page, "p.md")]
    assert got == [("p.md:4", "flexsheet keys generate --launch x.yaml"), ("p.md:5", "flexsheet a --b"),
                   ("p.md:12", "ls -l"), ("p.md:15", "flexsheet topic list"),
                   ("p.md:1", "flexsheet bag info")]
    assert examples("usage\n\nexample: flexsheet x --y 1\n         flexsheet z   # c\nexit status 1\n") == \
        ["flexsheet x --y 1", "flexsheet z"]
    ids = {c.id.rsplit(":", 1)[0] for c in COMMANDS}
    assert {"docs/deploy.md", "docs/calibration.md"} <= ids
    assert {"flexsheet --help", "flexsheet topic echo --help", "flexsheet calibrate stereo --help",
            "flexsheet experiment fem --help", "flexsheet bench planner --help"} <= ids
    assert sum(c.id.startswith("docs/deploy.md") for c in COMMANDS) >= 30
    assert subcommand_path("flexsheet bag info") and subcommand_path("flexsheet calibrate arms")
    assert not subcommand_path("flexsheet bag info run.mcap") and not subcommand_path(
        "flexsheet launch x.yaml")


def test_parse_only_rejects_a_bad_option_and_a_missing_file():
    parse_only("flexsheet experiment fem --quick --out /tmp/x")
    with pytest.raises(pytest.fail.Exception, match="does not parse"):
        parse_only("flexsheet experiment fem --no-such-option")
    with pytest.raises(AssertionError, match="does not exist"):
        parse_only("flexsheet launch launch/no_such.yaml --check")
