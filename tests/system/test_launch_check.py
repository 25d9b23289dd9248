"""``flexsheet launch FILE --check``: every shipped launch file passes for every host once
the keys exist; each kind of problem is one line naming node, key and value; a broken param is refused before
anything starts; a node that exits with a configuration error is not respawned."""

from __future__ import annotations

import asyncio
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, free_port

from flexsheet.runtime import ports
from flexsheet.runtime.config import EXIT_CONFIG
from flexsheet.runtime.launch import TOPLEVEL_ENV, load_launch
from flexsheet.runtime.launch_check import check_launch
from flexsheet.runtime.launch_sets import split_sets
from flexsheet.runtime.ports import ephemeral_port_range
from flexsheet.runtime.supervisor import Supervisor
from flexsheet.runtime.testing import console_lines


@pytest.fixture(autouse=True)
def _domain_0(monkeypatch):
    """The checks name the ports the files give: domain 0 (a worker's own domain would move them)."""
    monkeypatch.delenv("FLEXSHEET_DOMAIN_ID", raising=False)

LAB_KEYGEN = ["keys", "generate", "--launch", "launch/lab.yaml"]


def flexsheet(*args: str, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexsheet", *args], capture_output=True, text=True,
                          cwd=ROOT,
                          env={**os.environ, **(env or {})}, timeout=timeout)


@pytest.fixture
def keys(tmp_path, monkeypatch) -> Path:
    """``$FLEXSHEET_KEYS`` = a fresh folder, filled by ``flexsheet keys generate --launch launch/lab.yaml``
    and ``--launch launch/lab_sim.yaml`` (both run CURVE; one public_keys.yaml holds both files'
    identities)."""
    folder = tmp_path / "keys"
    monkeypatch.setenv("FLEXSHEET_KEYS", str(folder))
    for keygen in (LAB_KEYGEN, ["keys", "generate", "--launch", "launch/lab_sim.yaml"]):
        r = flexsheet(*keygen)
        assert r.returncode == 0, r.stderr
    return folder


def _tiny_bag(path: Path) -> Path:
    """A real one-message MCAP bag (what ``launch/replay.yaml`` plays)."""
    from flexsheet.runtime.bag_write import BagWriter
    from flexsheet.runtime.codec import encode
    from messages import Fingertip, Header
    from messages.samples import sample_fields

    w = BagWriter(path)
    msg = Fingertip(header=Header(stamp=time.time(), frame_id="display", seq=0), **sample_fields(Fingertip))
    w.write(encode("/fingertip", msg), time.time_ns())
    w.close()
    return path


def _here(errors: list[str], path: Path) -> list[str]:
    """``errors`` less the one "not an address of this machine" line of each host of ``path`` whose address
    this machine lacks (the lab's 10.77.0.x); asserts that each such host got that line."""
    from flexsheet.runtime.machine_checks import not_local

    lf = load_launch(path)
    absent = {h: s.address for h, s in lf.hosts.items() if not_local(s.address)}
    out = []
    for e in errors:
        host = next((h for h, a in absent.items() if f"hosts.{h}.address = '{a}': not an address of this "
                                                     "machine"
                     in e), None)
        if host is None:
            out.append(e)
    return out


def _shipped() -> list[tuple[str, str]]:
    return [(f.name, h) for f in sorted((ROOT / "launch").glob("*.yaml")) for h in load_launch(f).hosts]


@pytest.mark.parametrize("name, host", _shipped())
def test_every_shipped_launch_file_passes_for_every_host(keys, tmp_path, name, host):
    overrides = {}
    if name == "replay.yaml":  # replays a bag the user names (docs/replay.md)
        overrides = {"player": {"file": str(_tiny_bag(tmp_path / "sim.mcap"))}}
    res = check_launch(ROOT / "launch" / name, host=host, out=str(tmp_path / "out"), overrides=overrides)
    assert _here(res.errors, ROOT / "launch" / name) == [], "\n".join(res.errors)
    assert res.nodes == sum(s.host == host for s in load_launch(ROOT / "launch" / name).nodes.values())


def test_lab_is_secure_by_default_and_check_without_keys_names_the_command(tmp_path):
    lf = load_launch(ROOT / "launch" / "lab.yaml")
    assert lf.security.curve and lf.security.public_keys_file and not lf.security.public_keys
    r = flexsheet("launch", "launch/lab.yaml", "--check", "--host", "arm1",
                  env={"FLEXSHEET_KEYS": str(tmp_path / "nokeys")})
    assert r.returncode == EXIT_CONFIG
    key_lines = [line for line in r.stderr.splitlines() if "FLEXSHEET_KEYS" in line]
    assert len(key_lines) == 1, r.stderr
    assert "flexsheet keys generate --launch launch/lab.yaml" in key_lines[0]
    assert str(tmp_path / "nokeys") in key_lines[0]
    # one node's secret missing (the arm PC got only
    # public_keys.yaml and its host key): names it and the command
    flexsheet(*LAB_KEYGEN, env={"FLEXSHEET_KEYS": str(tmp_path / "k")})
    (tmp_path / "k" / "arm_right.key_secret").unlink()
    res = _check_env(ROOT / "launch" / "lab.yaml", "arm2", tmp_path / "k")
    secret = [e for e in res.errors if "secret key for arm_right on host arm2" in e]
    assert len(secret) == 1 and "flexsheet keys generate --launch" in secret[0], res.errors
    assert not [e for e in _check_env(ROOT / "launch" / "lab.yaml", "arm1", tmp_path / "k").errors
                if "secret" in e or "FLEXSHEET_KEYS" in e or "security" in e]


def test_a_host_whose_address_this_machine_lacks_fails_the_check_and_names_it(keys, tmp_path):
    """The lab's main PC address (10.77.0.1) is not on this machine: --check --host main exits 78 naming it
    (it printed OK, then the launch failed 63 times to bind); the same file with main on 127.0.0.1 passes."""
    r = flexsheet("launch", "launch/lab.yaml", "--check", "--host", "main")
    assert r.returncode == EXIT_CONFIG, r.stdout + r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "hosts.main.address = '10.77.0.1': not an address of this "
                                                   "machine"
             in ln]
    assert len(lines) == 1, r.stderr
    doc = yaml.safe_load((ROOT / "launch" / "lab.yaml").read_text())
    doc["hosts"]["main"]["address"] = "127.0.0.1"
    doc["nodes"]["viz"]["params"]["host"] = "127.0.0.1"
    path = ROOT / "launch" / f".lab_here_{os.getpid()}.yaml"   # beside lab.yaml: its $(launch_dir) paths hold
    try:
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        flexsheet("keys", "generate", "--launch", str(path))
        res = check_launch(path, host="main", out=str(tmp_path / "out"))
    finally:
        path.unlink(missing_ok=True)
    assert not [e for e in res.errors if "address" in e], res.errors
    assert any("no display_calib: node(s) camera, planner, renderer" in w for w in res.warnings), res.warnings


def _check_env(path, host, keys_dir):
    old = os.environ.get("FLEXSHEET_KEYS")
    os.environ["FLEXSHEET_KEYS"] = str(keys_dir)
    try:
        return check_launch(path, host=host)
    finally:
        if old is None:
            del os.environ["FLEXSHEET_KEYS"]
        else:
            os.environ["FLEXSHEET_KEYS"] = old


BASE = {"name": "chk", "hosts": {"main": {"address": "127.0.0.1"}, "arm1": {"address": "127.0.0.1"}},
        "base_port": 21000,
        "nodes": {"talker": {"type": "talker", "host": "main", "params": {"rate": 5.0}},
                  "ctrl": {"type": "arm_controller_sim", "host": "arm1", "params": {"port": 21500}},
                  "rec": {"type": "recorder", "host": "main", "params": {"output": "$(out)/x.mcap"}}}}


def _mutate(doc: dict, dotted: str, value) -> dict:
    import copy

    doc = copy.deepcopy(doc)
    d = doc
    keys = dotted.split(".")
    for k in keys[:-1]:
        d = d.setdefault(k, {})
    d[keys[-1]] = value
    return doc


@pytest.mark.parametrize("dotted, value, expect", [
    ("nodes.talker.params.rate", -3, r"node talker: params\.rate = -3: Input should be greater than 0"),
    ("nodes.talker.params.colour", "red", r"node talker: params\.colour = 'red': not a parameter of node "
                                          r"type talker \(its params: rate, count, start_delay, worker_s, "
                                          r"exit_lines\)"),
    ("nodes.talker.params", {"co\nlour": 1}, r"node talker: params\.co\\nlour = 1: not a parameter of node "
                                             r"type talker"),
    ("nodes.ctrl.params.port", 21003, r"node ctrl: params\.port = 21003: port 21003 on host arm1 is already "
                                      r"used by node rec's publisher"),
    ("hosts.arm1.address", "not_a host!", r"hosts\.arm1\.address = 'not_a host!': not an IP address or a "
                                          r"host name"),
    ("hosts.arm1.address", "0.0.0.0", r"hosts\.arm1\.address = '0\.0\.0\.0': the unspecified address"),
    ("hosts.arm1.address", "nosuchhost-flexsheet.invalid", r"does not resolve on this machine"),
    ("nodes.ctrl.params.host", "bad host!", r"node ctrl: params\.host = 'bad host!': not an IP address"),
    ("nodes.talker", {"type": "player", "host": "main"}, r"node talker: params\.file: required, not given"),
    ("report", "flexsheet.nosuch:main", r"report = 'flexsheet\.nosuch:main': no such 'module:function'"),
    ("display_calib", "$(launch_dir)/display.yaml", r"display_calib = '.*/display\.yaml': no such file"),
    ("nodes.rec.params.output", "$(launch_dir)/chk.yaml/x.mcap", r"node rec: params\.output = "
                                                               r"'.*/chk\.yaml/x\.mcap': cannot write here: "
                                                               r".*chk\.yaml is not a folder"),
])
def test_each_problem_is_one_line_naming_node_key_and_value(tmp_path, dotted, value, expect):
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(_mutate(BASE, dotted, value), sort_keys=False))
    res = check_launch(path, out=str(tmp_path / "out"))
    assert len(res.errors) == 1, res.errors
    assert res.errors[0].startswith(f"{path}: ") and "\n" not in res.errors[0]
    assert re.search(expect, res.errors[0]), res.errors[0]


def test_base_file_passes_and_files_are_checked_only_on_their_host(tmp_path):
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(BASE, sort_keys=False))
    assert check_launch(path, out=str(tmp_path / "out")).errors == []
    doc = _mutate(BASE, "nodes.cam", {"type": "camera", "host": "main",
                                      "params": {"model": "file", "calib_file": "$(launch_dir)/calib.yaml"}})
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    on_main = check_launch(path, host="main")
    assert len(on_main.errors) == 1 and "node cam: params.calib_file" in on_main.errors[0] \
        and str(tmp_path / "calib.yaml") in on_main.errors[0] and "no such file" in on_main.errors[0]
    assert check_launch(path, host="arm1").errors == []           # the camera does not run on arm1
    (tmp_path / "calib.yaml").write_text("not: a calibration\n")  # present but unusable: the reader says why
    bad = check_launch(path, host="main").errors
    assert len(bad) == 1 and "unusable" in bad[0] and "calib_file" in bad[0], bad
    (tmp_path / "calib.yaml").write_text((ROOT / "flexsheet" / "vision" / "ximea_calib.yaml").read_text())
    assert check_launch(path, host="main").errors == []
    # an override is checked like the file's own value
    res = check_launch(path, host="main", overrides={"talker": {"rate": 0}, "ghost": {"x": 1}})
    assert sorted(e.split(": ")[1] for e in res.errors) == ["--set = 'ghost'", "node talker"], res.errors


def test_display_calib_present_but_unreadable_is_one_clear_line(tmp_path):
    """A top-level display_calib names the registration file; --check reads it with the registration
    module's loader (or says the loader is not available)."""
    (tmp_path / "display.yaml").write_text("%YAML:1.0\n---\nnothing: here\n")
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(_mutate(BASE, "display_calib", "$(launch_dir)/display.yaml"),
                                   sort_keys=False))
    res = check_launch(path, out=str(tmp_path / "out"))
    assert len(res.errors) == 1, res.errors
    assert res.errors[0].startswith(f"{path}: display_calib = '{tmp_path / 'display.yaml'}': ")
    assert ("unusable" in res.errors[0]
            or "flexsheet.calibration.display_calib is not available" in res.errors[0])


def test_display_calib_missing_or_stale_entries_are_named_per_host(tmp_path):
    """The entries the checked host's nodes need must be in display.yaml (a missing one names the calibrate
    command); the camera entry must be newer than the stereo calibration it was fitted with."""
    dc = pytest.importorskip("flexsheet.calibration.display_calib")
    write_display_calib = pytest.importorskip("flexsheet.calibration.display_calib_file").write_display_calib
    import dataclasses

    stereo = tmp_path / "stereo.yaml"
    stereo.write_text((ROOT / "flexsheet" / "vision" / "ximea_calib.yaml").read_text())
    doc = _mutate(BASE, "display_calib", "$(launch_dir)/display.yaml")
    doc["nodes"].update({"cam": {"type": "camera", "host": "main",
                                 "params": {"model": "file", "calib_file": "$(launch_dir)/stereo.yaml"}},
                         "rend": {"type": "renderer", "host": "main"},
                         "arm_right": {"type": "arm_bridge", "host": "arm1", "params": {"arm": "right"}}})
    doc["external"] = ["/arm/right/target"]      # no planner in this file: its targets come from outside
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    nominal = dc.nominal_display_calib()
    write_display_calib(str(tmp_path / "display.yaml"), nominal)
    res = check_launch(path, out=str(tmp_path / "out"))
    assert res.errors == [], res.errors      # nominal entries: warnings, one per entry a node uses
    assert sorted(w.split("'")[1] for w in res.warnings if "nominal" in w) == ["arms.right", "camera", "eye",
                                                                               "projector"], res.warnings
    measured = dc.Provenance("test fit", measured_at="2000-01-01T00:00:00Z", source="lab", n_poses=8)
    calib = dataclasses.replace(nominal, projector=None, arms={"left": nominal.arms["left"]},
                                camera=dataclasses.replace(nominal.camera, provenance=measured))
    write_display_calib(str(tmp_path / "display.yaml"), calib)
    main = check_launch(path, host="main", out=str(tmp_path / "out")).errors
    assert len(main) == 2, main
    assert "stale 'camera' entry: measured 2000-01-01T00:00:00Z, before node cam's calib_file" in main[0]
    assert "no 'projector' entry, which node rend needs (run: flexsheet calibrate projector" in main[1]
    arm1 = check_launch(path, host="arm1").errors
    assert len(arm1) == 1 and ("no 'arms.right' entry, which node arm_right needs (run: flexsheet calibrate "
                               "arms") \
        in arm1[0], arm1


def test_curve_problems_name_the_key_file(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_KEYS", str(tmp_path / "k"))
    doc = _mutate(BASE, "security", {"curve": True, "public_keys_file": "$(keys)/public_keys.yaml"})
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert flexsheet("keys", "generate", "--launch", str(path)).returncode == 0
    assert check_launch(path, out=str(tmp_path / "out")).errors == []
    os.chmod(tmp_path / "k" / "arm1.key_secret", 0o644)
    errs = check_launch(path, host="arm1").errors
    assert len(errs) == 1 and "readable by others (mode 644)" in errs[0] and "chmod 600" in errs[0], errs
    os.chmod(tmp_path / "k" / "arm1.key_secret", 0o600)
    other = tmp_path / "other"                                       # keys from another run: mismatch
    assert flexsheet("keys", "generate", "--launch", str(path), "-o", str(other)).returncode == 0
    os.replace(other / "public_keys.yaml", tmp_path / "k" / "public_keys.yaml")
    errs = check_launch(path, host="main").errors
    from flexsheet.runtime.launch import identities
    assert len(errs) == len(identities(load_launch(path), "main")) >= 2, errs   # main and each of its nodes
    assert all("does not match" in e for e in errs) and "security.public_keys.main" in errs[0], errs


def test_curve_off_on_a_networked_graph_is_a_warning_not_an_error(tmp_path):
    doc = _mutate(_mutate(BASE, "hosts.arm1.address", "10.77.0.2"), "nodes.ctrl.params.host", "127.0.0.1")
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    res = check_launch(path, host="main", out=str(tmp_path / "out"))
    assert res.errors == [] and len(res.warnings) == 1 and "security.curve is off" in res.warnings[0]


def test_node_ports_in_the_ephemeral_range_are_a_warning_naming_the_range(tmp_path):
    lo, hi = ephemeral_port_range()
    assert 1024 <= lo < hi <= 65535
    path = tmp_path / "chk.yaml"
    below = _mutate(_mutate(BASE, "base_port", min(21000, lo - 600)), "nodes.ctrl.params.port",
                    min(21500, lo - 100))
    path.write_text(yaml.safe_dump(below, sort_keys=False))
    assert not any("ephemeral" in w for w in check_launch(path, out=str(tmp_path / "out")).warnings)
    # talker lo + 1, rec lo + 3
    inside = _mutate(_mutate(BASE, "base_port", lo), "nodes.ctrl.params.port", lo + 10)
    path.write_text(yaml.safe_dump(inside, sort_keys=False))
    res = check_launch(path, out=str(tmp_path / "out"))
    assert res.errors == []
    eph = [w for w in res.warnings if "ephemeral" in w]
    assert len(eph) == 1 and f"range {lo}-{hi}" in eph[0] and f"talker ({lo + 1})" in eph[0] \
        and f"below {lo}" in eph[0] and eph[0].count("(") >= 4, eph      # 3 named, "..." for the rest
    assert "4 listening port(s)" in eph[0], eph  # 3 publishers + the twin's Modbus port
    bad = tmp_path / "range"
    bad.write_text("not numbers\n")
    assert ephemeral_port_range(bad) == (32768, 60999)       # unreadable: Linux's default
    bad.write_text("20000\t40000\n")
    assert ephemeral_port_range(bad) == (20000, 40000)



def test_free_ports_lie_below_the_ephemeral_range_and_bad_ranges_are_named(monkeypatch):
    lo, _ = ephemeral_port_range()
    for span in (1, 20):
        p = ports.free_port(span=span)
        assert ports.LOW_PORT <= p and p + span <= min(lo, 32768)
    with pytest.raises(ValueError, match="span must be an int >= 1, got 0"):
        ports.free_port(span=0)
    # no room below: above the range
    monkeypatch.setattr(ports, "ephemeral_port_range", lambda: (20005, 60999))
    p = ports.free_port(span=10)
    assert 61000 <= p and p + 10 <= 65536
    monkeypatch.setattr(ports, "ephemeral_port_range", lambda: (1024, 65535))
    with pytest.raises(RuntimeError, match=r"range 1024-65535 \(net.ipv4.ip_local_port_range\) leaves no "
                                           r"room"):
        ports.free_port(span=10)


def test_broken_param_is_refused_before_anything_starts_with_one_clear_line(demo_launch):
    path = demo_launch(rate=-3.0)
    t0 = time.monotonic()
    r = flexsheet("launch", str(path), "--duration", "30")
    assert r.returncode == EXIT_CONFIG
    assert time.monotonic() - t0 < 25                      # refused, not run for its duration
    assert "started pid" not in r.stdout + r.stderr          # no node process was started
    errors = [line for line in r.stderr.splitlines() if "warning" not in line and "error(s)" not in line]
    assert errors == [f"{path}: node talker: params.rate = -3.0: Input should be greater than 0"], r.stderr


def _run_supervisor(lf, **kw) -> tuple[int, list[str]]:
    with console_lines() as lines:
        code = asyncio.run(Supervisor(lf, **kw).run())
    return code, lines


def test_node_with_a_configuration_error_is_not_respawned(tmp_path):
    """The player's bag is missing when it starts (past the check): its setup fails, ``flexsheet run`` exits
    78 and the supervisor reports it once and does not respawn, though its policy would allow 10 restarts."""
    port = free_port()
    path = tmp_path / "cfg.yaml"
    path.write_text(f"""
hosts: {{main: {{address: 127.0.0.1}}}}
nodes:
  player: {{type: player, host: main, port: {port}, params: {{file: {tmp_path / 'gone.mcap'}}},
            respawn: {{policy: always, delay: 0.1, max_restarts: 10}}}}
""")
    code, lines = _run_supervisor(load_launch(path), duration=5.0)
    assert code == EXIT_CONFIG
    assert sum("started pid" in line for line in lines) == 1, "\n".join(lines)
    assert any(re.search(r"configuration error: setup: file: bag '.*gone\.mcap' not found", line)
               for line in lines)
    assert any("configuration error (see the line above): not respawned" in line for line in lines)
    assert not any("respawning" in line for line in lines)


def test_other_failures_are_still_respawned(tmp_path):
    """Counter-check: the same node failing for another reason (exit 1) is respawned by its policy."""
    fake = tmp_path / "fail.sh"
    fake.write_text("#!/bin/sh\necho 'transport down'\nexit 1\n")
    fake.chmod(0o755)
    path = tmp_path / "f.yaml"
    path.write_text("hosts: {main: {address: 127.0.0.1}}\nnodes:\n  t: {type: talker, host: main, "
                    f"port: {free_port()}, respawn: {{policy: on-failure, delay: 0.1, max_restarts: 3}}}}\n")
    code, lines = _run_supervisor(load_launch(path), duration=3.0, python=str(fake))
    assert sum("started pid" in line for line in lines) == 4, "\n".join(lines)
    assert any("not respawned: 3 restarts used" in line for line in lines)


def _doc_commands() -> list[str]:
    text = (ROOT / "docs" / "deploy.md").read_text()
    lines = [ln.split("  #")[0].strip() for block in re.findall(r"```bash\n(.*?)```", text, re.S)
             for ln in block.splitlines()]
    return [ln for ln in lines if ln.startswith(("flexsheet launch ", "flexsheet run "))]


def test_deploy_doc_commands_pass_the_check(keys, tmp_path, monkeypatch):
    """Every ``flexsheet launch``/``flexsheet run --launch`` command of docs/deploy.md parses with the real
    CLI and passes the check, once ``flexsheet keys generate --launch launch/lab.yaml`` has run (the doc's
    step 3). The lab's own stereo calibration (step 5) stands in as a copy of the shipped one."""
    import shlex

    from flexsheet.cli import build_parser
    from flexsheet.cli_commands import parse_params

    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / ".flexsheet").mkdir()
    (tmp_path / ".flexsheet"
     / "stereo.yaml").write_text((ROOT / "flexsheet/vision/ximea_calib.yaml").read_text())
    cmds = _doc_commands()
    assert sum(c.startswith("flexsheet launch launch/lab.yaml") for c in cmds) >= 9, cmds
    assert "flexsheet keys generate --launch launch/lab.yaml" in (ROOT / "docs" / "deploy.md").read_text()
    for cmd in cmds:
        args = build_parser().parse_args([os.path.expandvars(a) for a in shlex.split(cmd)[1:]])
        if args.command == "launch":
            toplevel, overrides = split_sets(args.set, set(load_launch(ROOT / args.file).nodes))
            monkeypatch.setenv(TOPLEVEL_ENV, json.dumps(toplevel))   # as flexsheet launch hands them on
            res = check_launch(ROOT / args.file, host=args.host, out=str(tmp_path / "out"),
                               overrides=overrides)
            monkeypatch.delenv(TOPLEVEL_ENV)
        else:
            lf = load_launch(ROOT / args.launch)
            res = check_launch(lf.path, host=lf.nodes[args.name].host,
                               overrides={args.name: parse_params(args.param or [])})
        assert _here(res.errors, res.path) == [], f"{cmd}:\n" + "\n".join(res.errors)


def test_probe_names_the_cameras_this_machine_does_not_see(tmp_path):
    """``--check --probe``: the camera node's GenICam serials (Aravis discovery) and UVC devices are asked for
    on the checked host; without ``--probe`` the same file passes; another host's camera is not probed
    here."""
    doc = _mutate(BASE, "nodes.cam", {"type": "camera", "host": "main",
                                      "params": {"source": "genicam", "left_id": "SN-LEFT-0",
                                                 "right_id": "SN-RIGHT-0"}})
    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert check_launch(path, host="main").errors == []
    errs = check_launch(path, host="main", probe=True).errors
    assert len(errs) == 2, errs
    assert "node cam: probe: camera left_id: camera 'SN-LEFT-0' not found; cameras found:" in errs[0]
    assert "camera right_id: camera 'SN-RIGHT-0' not found" in errs[1]
    assert check_launch(path, host="arm1", probe=True).errors == []
    uvc = _mutate(BASE, "nodes.cam", {"type": "camera", "host": "main",
                                      "params": {"source": "device", "device_left": 57}})
    path.write_text(yaml.safe_dump(uvc, sort_keys=False))
    errs = check_launch(path, host="main", probe=True).errors
    assert errs == [f"{path}: node cam: probe: camera device_left = 57: no such video device can be opened "
                    "here"]
    r = flexsheet("launch", str(path), "--check", "--host", "main", "--probe")
    assert r.returncode == EXIT_CONFIG and "probe: camera device_left = 57" in r.stderr, r.stderr


def test_check_json_is_one_document_with_the_same_lines_and_status(tmp_path):
    import json

    path = tmp_path / "chk.yaml"
    path.write_text(yaml.safe_dump(BASE, sort_keys=False))
    r = flexsheet("launch", str(path), "--check", "--json")
    j = json.loads(r.stdout)
    assert (r.returncode == 0 and j["ok"] and j["errors"] == [] and j["nodes"] == 3
            and j["hosts"] == ["main", "arm1"])
    path.write_text(yaml.safe_dump(_mutate(BASE, "nodes.talker.params.rate", -3), sort_keys=False))
    r = flexsheet("launch", str(path), "--check", "--json")
    j = json.loads(r.stdout)
    assert r.returncode == EXIT_CONFIG and not j["ok"] and len(j["errors"]) == 1
    assert "params.rate = -3" in j["errors"][0] and j["errors"][0] in r.stderr
