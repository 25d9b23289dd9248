# PYTHON_ARGCOMPLETE_OK
"""The ``flexsheet`` command: ROS 2-style subcommands (launch, run, topic, node, bag, calibrate, experiment,
bench).

Each subcommand's ``--help`` shows a working example. Argument parsing is argparse; subcommands that own
an algorithm (experiments, benches, calibration) parse their own arguments (see :mod:`flexsheet.registry`).
"""

from __future__ import annotations

import argparse
import os
import sys

from flexsheet import __version__, registry
from flexsheet.cli_commands import cmd_keys, cmd_launch, cmd_run
from flexsheet.runtime.console import LIBRARY, show_lines
from flexsheet.runtime.domain import DOMAIN_ENV, domain_id
from flexsheet.runtime.plugins import node_types


def _domain_arg(t) -> None:
    """``--domain D``: the graph's domain (flexsheet/runtime/domain.py), as ``FLEXSHEET_DOMAIN_ID``."""
    t.add_argument("--domain", metavar="D", help="run in domain D, 0..60 (default: $FLEXSHEET_DOMAIN_ID, "
                   "else 0): each domain has its own ports and its own graph, as ROS_DOMAIN_ID")


def _graph_args(t) -> None:
    """How a run-time tool finds the graph (:func:`flexsheet.runtime.discovery.resolve_graph`)."""
    _domain_arg(t)
    t.add_argument("--launch", metavar="FILE", help="the graph's launch file (needed for a graph on other "
                   "hosts or one running CURVE); default: $FLEXSHEET_LAUNCH, else the nodes running on this "
                   "machine")
    t.add_argument("--endpoint", action="append", metavar="tcp://HOST:PORT",
                   help="listen to this publisher only, repeatable (e.g. a bag player's tcp://127.0.0.1:7199)")


def _fmt(prog_examples: str) -> dict:
    return {"epilog": "example:\n" + prog_examples, "formatter_class": argparse.RawDescriptionHelpFormatter}


def _positive(flag: str):
    """An argparse type: a finite float > 0, else one line naming ``flag`` and the value."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} expects seconds or a factor > 0, got "
                                             f"{text!r}") from None
        if not (v > 0 and v != float("inf")):
            raise argparse.ArgumentTypeError(f"{flag} must be a finite number > 0, got {text!r}")
        return v
    return parse


def _tool(name: str):
    def call(args: argparse.Namespace) -> int:
        from flexsheet.runtime import tools
        return getattr(tools, name)(args)
    return call


def _service_tool(name: str):
    def call(args: argparse.Namespace) -> int:
        from flexsheet.runtime import service_tools
        return getattr(service_tools, name)(args)
    return call


def _bag(name: str):
    def call(args: argparse.Namespace) -> int:
        from flexsheet.runtime import bag
        return getattr(bag, name)(args)
    return call


def _delegate(table: dict[str, str], kind: str):
    def call(args: argparse.Namespace) -> int:
        if args.name not in table:
            print(f"flexsheet {kind}: unknown {kind} {args.name!r}; choose from: {', '.join(table)}"
                  + ("" if table else " (none registered: reinstall flexsheet, pip install -e ., to register "
                     "its entry points)"), file=sys.stderr)
            return 2
        main = registry.load(table[args.name])
        # the library's progress (INFO)
        show_lines(LIBRARY, clock=kind == "calibrate", stderr=kind == "bench")
        return int(main(args.rest) or 0)
    return call


def _add_launch_parser(sub) -> None:
    s = sub.add_parser("launch", help="start the nodes of a launch file (one host or all)",
                       description="Start the nodes of a launch file: each node as its own process, or the "
                                   "nodes of "
                                   "one container (every node of a 'clock: sim' file) in one process; with "
                                   "prefixed output, respawn and clean Ctrl-C shutdown. The file is checked "
                                   "first (params, hosts, ports, files, CURVE keys, and the graph: each "
                                   "source fits the clock, each required input has a publisher, shared "
                                   "values agree); with an error nothing starts (exit 78).",
                       **_fmt("  flexsheet launch launch/sim.yaml --duration 60 --out out/sim\n"
                              "  flexsheet launch launch/lab.yaml --check --host main   # check only, start "
                              "nothing\n  flexsheet launch launch/lab.yaml --host arm1     # on arm PC 1\n"
                              "  flexsheet launch launch/sim.yaml --set twin.truth_seed=2 --set "
                              "scene=launch/scenes/sphere.yaml\n  flexsheet launch launch/sim.yaml --rtf 1 "
                              "--set world.loop=true   # watch at real speed\n  flexsheet launch "
                              "launch/sim.yaml --domain 3 --out out/d3   # beside another graph\n  flexsheet "
                              "launch launch/lab_sim.yaml --set hosts.main.address=127.0.0.1 --set "
                              "hosts.arm1.address=127.0.0.2 --set hosts.arm2.address=127.0.0.3"))
    s.add_argument("file", help="launch YAML file")
    _domain_arg(s)
    s.add_argument("--host", help="start only the nodes of this host (default: all hosts, on this machine)")
    s.add_argument("--duration", type=_positive("--duration"),
                   help="stop after this many seconds — simulated seconds in a 'clock: sim' file (default: "
                        "until Ctrl-C or the scripted run ends)")
    s.add_argument("--rtf", type=_positive("--rtf"), metavar="X",
                   help="'clock: sim' files: cap simulated time at X times wall time (1 = real speed, to "
                        "watch; default: the file's clock.rtf, else as fast as this machine allows). Same "
                        "messages either way")
    s.add_argument("--out", help="output folder for bags, charts and the report (substituted for $(out))")
    s.add_argument("--set", action="append", metavar="NODE.KEY=VALUE", default=[],
                   help="override one node parameter (YAML value), repeatable: --set world.loop=true; or a "
                        "graph-wide setting: --set twin.truth_seed=3, --set scene=launch/scenes/sphere.yaml, "
                        "--set hosts.main.address=127.0.0.1")
    s.add_argument("--check", action="store_true",
                   help="only check the file for this host (--host) and this machine: one line per error, "
                        "exit 78 on any, 0 when it would start")
    s.add_argument("--json", action="store_true",
                   help="with --check: one JSON document on stdout (file, hosts, nodes, ok, errors, "
                        "warnings)")
    s.add_argument("--probe", action="store_true",
                   help="also ask whether the devices this host's nodes name are there (cameras), before "
                        "anything starts")
    s.set_defaults(func=cmd_launch)


def _add_run_parser(sub) -> None:
    s = sub.add_parser("run", help="run one node alone (or one container of nodes)",
                       description="Run one node in the foreground. With --launch it takes its endpoint, "
                                   "peers and params from the launch file; --param overrides. With "
                                   "--container NAME it runs every node of the launch file with 'container: "
                                   "NAME' (on --host) in this one process (docs/realtime.md).",
                       **_fmt("  flexsheet run talker --param rate=5 --endpoint tcp://127.0.0.1:7201\n"
                              "  flexsheet run listener --peer tcp://127.0.0.1:7201\n"
                              "  flexsheet run planner --launch launch/sim.yaml --param "
                              "use_prediction=false\n  flexsheet calibrate display --sim --truth-seed 0 "
                              "--out out/calib   # the twin's display.yaml (a launch makes its own)\n"
                              "  flexsheet run --container main_pc --launch launch/sim_composed.yaml --host "
                              "main --set camera.display_calib=out/calib/display.yaml"))
    s.add_argument("node_type", metavar="NODE", nargs="?", help="node type: "
                                                                f"{', '.join(sorted(node_types()))}")
    s.add_argument("--name", help="node name (default: the type; with --launch: the node's key)")
    s.add_argument("--launch", help="take endpoint, peers and params from this launch file")
    _domain_arg(s)
    s.add_argument("--param", "-p", action="append", metavar="KEY=VALUE",
                   help="parameter (YAML value), repeatable")
    s.add_argument("--endpoint", default="tcp://127.0.0.1:0", help="publisher endpoint to bind (without "
                                                                   "--launch)")
    s.add_argument("--peer", action="append", metavar="ENDPOINT", help="publisher endpoint to subscribe to")
    s.add_argument("--out", help="output folder ($(out) in params)")
    s.add_argument("--container", metavar="NAME", help="run the nodes of this container of the --launch file")
    s.add_argument("--host", help="with --container: the host whose share of the container to run")
    s.add_argument("--set", action="append", metavar="NODE.KEY=VALUE", default=[],
                   help="with --container: override one node parameter (YAML value), repeatable")
    s.add_argument("--sim-duration", type=float, metavar="S", help="with --container of a 'clock: sim' file: "
                   "stop after S simulated seconds (flexsheet launch --duration passes it)")
    s.set_defaults(func=cmd_run)


def _add_keys_parser(sub) -> None:
    s = sub.add_parser("keys", help="generate CURVE keypairs for the hosts and nodes of a launch file",
                       **_fmt("  flexsheet keys generate --launch launch/lab.yaml"))
    ks = s.add_subparsers(dest="keys_cmd", required=True, metavar="VERB")
    t = ks.add_parser("generate", help="write <name>.key, <name>.key_secret and public_keys.yaml",
                      description="Write a CURVE keypair per node and per host of a launch file, and "
                                  "public_keys.yaml (name -> public key), into the keys folder: -o, else "
                                  "$FLEXSHEET_KEYS, else ~/.flexsheet/keys. A launch file with security: "
                                  "{curve: true, public_keys_file: $(keys)/public_keys.yaml} (as "
                                  "launch/lab.yaml) then needs nothing pasted. Each node proves itself with "
                                  "its own key; security.publishers says which node may publish a guarded "
                                  "topic (the arm targets: the planner). Existing keypairs are kept.",
                      **_fmt("  flexsheet keys generate --launch launch/lab.yaml\n"
                             "  flexsheet keys generate --launch launch/lab.yaml arm_left --force   # rotate "
                             "one key\n  FLEXSHEET_KEYS=/tmp/k flexsheet keys generate --launch "
                             "launch/lab.yaml && FLEXSHEET_KEYS=/tmp/k flexsheet launch launch/lab.yaml "
                             "--check --host arm1"))
    t.add_argument("names", nargs="*", metavar="NAME", help="only these hosts or nodes of the launch file "
                                                            "(default: all)")
    t.add_argument("--launch", required=True, metavar="FILE", help="the launch file whose hosts and nodes "
                                                                   "get keys")
    t.add_argument("-o", "--output", default=None, help="keys folder (default $FLEXSHEET_KEYS or "
                                                        "~/.flexsheet/keys)")
    t.add_argument("--force", action="store_true", help="replace existing keypairs (every host then needs "
                                                         "the new public_keys.yaml, and the owner its new "
                                                         "secret)")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout: each key's status and "
                                                       "file, the secret files each host needs")
    t.set_defaults(func=cmd_keys)


def _add_topic_parser(sub) -> None:
    s = sub.add_parser("topic", help="inspect topics of the live graph (from heartbeats)",
                       **_fmt("  flexsheet topic list\n  flexsheet topic info /fingertip\n"
                              "  flexsheet topic echo /fingertip --count 3\n  flexsheet topic hz "
                              "/camera/stereo\n  flexsheet topic bw /camera/stereo --json"))
    ts = s.add_subparsers(dest="topic_cmd", required=True, metavar="VERB")
    for verb, helptext in (("list", "list topics with publishers, rates and types"),
                           ("info", "one topic: type, rate, publishers and subscribers with QoS and drops"),
                           ("echo", "print messages of a topic"), ("hz", "measure a topic's rate"),
                           ("bw", "measure a topic's bandwidth")):
        t = ts.add_parser(verb, help=helptext,
                          **_fmt(f"  flexsheet topic {verb}" + ("" if verb == "list" else " /fingertip")
                                 + (" --json" if verb in ("list", "info") else "")
                                 + (" --count 2 --json" if verb == "echo" else "")
                                 + (" --window 2" if verb in ("hz", "bw") else "")))
        if verb != "list":
            t.add_argument("topic")
        _graph_args(t)
        if verb not in ("hz", "bw"):
            t.add_argument("--timeout", type=float, default=2.5,
                           help="s to wait for the first message (none: it is not published; exit 1)"
                           if verb == "echo" else "s to listen for heartbeats")
        t.add_argument("--json", action="store_true", help="one JSON object per message, a line each" if
                       verb == "echo" else "one JSON document on stdout")
        if verb == "echo":
            t.add_argument("--count", type=int, default=0, help="stop after N messages")
            t.add_argument("--arrays", action="store_true", help="print whole arrays (default: shape only)")
        if verb in ("hz", "bw"):
            t.add_argument("--window", type=float, default=5.0, help="s to measure")
        t.set_defaults(func=_tool(f"topic_{verb}"))
    t = ts.add_parser("pub", help="publish a message (YAML) on a topic to the nodes that subscribe to it",
                      **_fmt("  flexsheet topic pub /fingertip \"{position: [0.0, 0.0, 0.01], covariance: "
                             "[[1.0e-8, 0, 0], "
                             "[0, 1.0e-8, 0], [0, 0, 1.0e-8]], valid: true, predicted_position: [0.0, 0.0, "
                             "0.01], exposure_stamp: 0.0}\" --times 5 --rate 10\n"
                             "  (every field without a default is required; the header is stamped with the "
                             "graph's clock; a topic guarded by security.publishers is refused)"))
    t.add_argument("topic")
    t.add_argument("message", nargs="?", default="", help="the message's fields as a YAML map (its type is "
                   "the topic's; the header is stamped with the graph's clock unless given)")
    t.add_argument("--times", type=int, default=1, help="messages to publish (default 1)")
    t.add_argument("--rate", type=float, default=10.0, help="Hz between them (default 10)")
    _tool_args(t, "s to find the subscribers and for each call")
    t.set_defaults(func=_service_tool("topic_pub"))


def _add_node_parser(sub) -> None:
    s = sub.add_parser("node", help="inspect nodes of the live graph (from heartbeats)",
                       **_fmt("  flexsheet node list\n  flexsheet node info planner"))
    ns = s.add_subparsers(dest="node_cmd", required=True, metavar="VERB")
    t = ns.add_parser("list", help="list live nodes with host, pid, state and rejections",
                      **_fmt("  flexsheet node list --launch launch/sim.yaml --json"))
    _tool_args(t, "s to listen for heartbeats")
    t.set_defaults(func=_tool("node_list"))
    t = ns.add_parser("info", help="one node: host, pid, state, its topics with rates, QoS and drops",
                      **_fmt("  flexsheet node info planner --launch launch/sim.yaml"))
    t.add_argument("name", help="node name (as in the launch file)")
    _tool_args(t, "s to listen for heartbeats")
    t.set_defaults(func=_tool("node_info"))


def _add_param_parser(sub) -> None:
    s = sub.add_parser("param", help="list, get and set the params of a running node",
                       **_fmt("  flexsheet param list planner\n  flexsheet param get planner "
                              "stiffness_scale\n  flexsheet param set planner stiffness_scale 0.5"))
    ps = s.add_subparsers(dest="param_cmd", required=True, metavar="VERB")
    for verb, helptext, example in (
            ("list", "every param: type, value, default, description, settable at run time",
             "list planner --json"),
            ("get", "one param's value", "get planner stiffness_scale"),
            ("set", "set a run-time param (others are read-only while the node runs)",
             "set planner stiffness_scale 0.5")):
        t = ps.add_parser(verb, help=helptext, **_fmt(f"  flexsheet param {example}"))
        t.add_argument("node", help="node name (as in the launch file)")
        if verb != "list":
            t.add_argument("name", help="param name")
        if verb == "set":
            t.add_argument("value", help="the new value (YAML: 0.5, true, [1, 2])")
        _tool_args(t)
        t.set_defaults(func=_service_tool(f"param_{verb}"))


def _add_service_parser(sub) -> None:
    s = sub.add_parser("service", help="list and call the services of a running node",
                       **_fmt("  flexsheet service list planner\n  flexsheet service call planner param/get "
                              "\"{name: stiffness_scale}\""))
    ss = s.add_subparsers(dest="service_cmd", required=True, metavar="VERB")
    t = ss.add_parser("list", help="the node's services, one line each",
                      **_fmt("  flexsheet service list fem"))
    t.add_argument("node", help="node name (as in the launch file)")
    _tool_args(t)
    t.set_defaults(func=_service_tool("service_list"))
    t = ss.add_parser("call", help="call one service with YAML arguments",
                      **_fmt("  flexsheet service call planner param/get \"{name: stiffness_scale}\""))
    t.add_argument("node", help="node name (as in the launch file)")
    t.add_argument("service", help="service name (service list shows them)")
    t.add_argument("args", nargs="?", default="", help="arguments as a YAML map")
    _tool_args(t)
    t.set_defaults(func=_service_tool("service_call"))


def _tool_args(t, timeout_help: str = "s to find the node and for the reply") -> None:
    """The run-time tools' common flags: ``--launch``, ``--timeout``, ``--json``."""
    _graph_args(t)
    t.add_argument("--timeout", type=float, default=2.5, help=timeout_help)
    t.add_argument("--json", action="store_true", help="one JSON document on stdout")


def _add_bag_parser(sub) -> None:
    s = sub.add_parser("bag", help="record, play, inspect, export and recover MCAP bags",
                       **_fmt("  flexsheet bag record -o run.mcap /fingertip /sheet/target\n"
                              "  flexsheet bag info run.mcap\n  flexsheet bag play run.mcap --rate 0.5\n"
                              "  flexsheet bag export run.mcap run_json.mcap\n"
                              "  flexsheet bag recover cut.mcap fixed.mcap"))
    bs = s.add_subparsers(dest="bag_cmd", required=True, metavar="VERB")
    t = bs.add_parser("record", help="record topics of the live graph (raw frames, lossless)",
                      **_fmt("  flexsheet bag record -o run.mcap --duration 10     # all topics, 10 s\n"
                             "exit status 1 if the bag could not be written completely"))
    t.add_argument("topics", nargs="*", help="topics (default: all)")
    t.add_argument("-o", "--output", default="", help="output .mcap (default: bag_<time>.mcap)")
    _graph_args(t)
    t.add_argument("--duration", type=float, help="stop after S seconds")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout at the end (log on "
                                                       "stderr)")
    t.set_defaults(func=_bag("cmd_record"))
    t = bs.add_parser("play", help="republish a bag with its original timing",
                      **_fmt("  flexsheet bag play out/sim/sim.mcap --loop     # publishes on tcp://127.0.0.1:7199\n"
                             "  flexsheet topic hz /fingertip                    # (another shell) finds the "
                             "player\n  flexsheet run viz --peer tcp://127.0.0.1:7199    # Foxglove at "
                             "ws://localhost:8765\nexit status 2 (one line on stderr) if the file is missing "
                             "or not MCAP"))
    t.add_argument("file")
    t.add_argument("--rate", type=float, default=1.0, help="playback speed factor")
    t.add_argument("--loop", action="store_true")
    t.add_argument("--topics", nargs="*", help="only these topics")
    t.add_argument("--endpoint", default="tcp://127.0.0.1:7199", help="endpoint to publish on")
    t.add_argument("--start-delay", type=float, default=0.5, help="s to let subscribers connect")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout at the end (log on "
                                                       "stderr)")
    t.set_defaults(func=_bag("cmd_play"))
    t = bs.add_parser("info", help="summary of any MCAP: topics, types, counts, duration, what is lost",
                      **_fmt("  flexsheet bag info run.mcap\n"
                             "exit status 1 if the bag is damaged (a 'damaged:' line) or cut short ('cut:'), "
                             "2 if it is not MCAP"))
    t.add_argument("file")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout (same exit status)")
    t.set_defaults(func=_bag("cmd_info"))
    t = bs.add_parser("export", help="transcode to JSON-encoded MCAP for Foxglove/Lichtblick, with the 3-D "
                                     "scene",
                      **_fmt("  flexsheet bag export run.mcap run_json.mcap     # open run_json.mcap in "
                             "Foxglove\nprogress on stderr every 2 s; exit status 1 if the source was "
                             "damaged or cut"))
    t.add_argument("file")
    t.add_argument("output")
    t.add_argument("--no-foxglove", action="store_true", help="JSON copies only, no /viz/* scene channels")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout (progress stays on "
                                                       "stderr)")
    t.set_defaults(func=_bag("cmd_export"))
    t = bs.add_parser("recover", help="rewrite a cut (kill -9) or damaged bag as a complete MCAP",
                      **_fmt("  flexsheet bag recover out/sim/sim.mcap out/sim/sim_recovered.mcap\n"
                             "prints the messages kept per topic and what was lost"))
    t.add_argument("file")
    t.add_argument("output")
    t.add_argument("--json", action="store_true", help="one JSON document on stdout (same exit status)")
    t.set_defaults(func=_bag("cmd_recover"))


def _add_delegate_parsers(sub) -> None:
    for kind, table, helptext, example in (
            ("calibrate", registry.calibrations(), "calibrate devices and register the display (stereo, "
             "camera pose, projector, arms, eye; display = all of them)",
             "  flexsheet calibrate stereo --left 'tests/data/stereo_xi/left*.jpg' --right "
             "'tests/data/stereo_xi/right*.jpg' --board chessboard:9x6 --square 0.024 -o calib.yaml\n"
             "  flexsheet calibrate display --sim --truth-seed 0 --out out/calib   # all of it, in the twin"),
            ("experiment", registry.experiments(), "run an experiment: charts + JSON",
             "  flexsheet experiment stroke --out out/stroke\n  flexsheet experiment fem --out out/fem "
             "--quick"),
            ("bench", registry.benches(), "run a benchmark and print figures",
             "  flexsheet bench transport --json\n  flexsheet bench planner")):
        s = sub.add_parser(kind, help=helptext, description=f"{helptext}. NAME is one of: "
                                                            f"{', '.join(table)}. "
                           "Arguments after NAME go to it (NAME --help shows them).", **_fmt(example))
        s.add_argument("name", metavar="NAME", help=" | ".join(table))
        s.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for NAME")
        s.set_defaults(func=_delegate(table, kind))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="flexsheet",
        description="flexsheet: encountered-type visual haptic display using a flexible sheet. "
                    "A ROS-style node graph on ZeroMQ: launch files, nodes, topics, MCAP bags, experiments.",
        **_fmt("  flexsheet launch launch/sim.yaml            # the whole display, simulated on localhost\n"
               "  flexsheet topic list                        # topics of the running graph\n"
               "  flexsheet experiment stroke --out out/stroke"))
    p.add_argument("--version", action="version", version=f"flexsheet {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_launch_parser, _add_run_parser, _add_keys_parser, _add_topic_parser,
                _add_node_parser, _add_param_parser, _add_service_parser, _add_bag_parser,
                _add_delegate_parsers):
        add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``flexsheet`` console script. Returns the process exit code."""
    parser = build_parser()
    if argv is None:            # shell completion (argcomplete): answers and exits when the shell asks
        import argcomplete

        argcomplete.autocomplete(parser)
    args = parser.parse_args(argv)
    try:                  # the graph's domain, checked once; the processes this command starts inherit it
        domain = domain_id(getattr(args, "domain", None))
    except ValueError as exc:
        parser.error(str(exc))
    if getattr(args, "domain", None) is not None:
        os.environ[DOMAIN_ENV] = str(domain)
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()   # here, so that a reader gone away is caught below, not at interpreter exit
        return code
    except KeyboardInterrupt:
        return 130
    # the reader went away (``| head``): no traceback, the shell's 141 (128 + SIGPIPE)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())   # Python's own flush at exit must not fail again
        return 141


if __name__ == "__main__":
    sys.exit(main())
