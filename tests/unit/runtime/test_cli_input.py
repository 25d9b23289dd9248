"""Bad command-line input gets one clear line and a non-zero exit, never a traceback: ``--duration`` and
``--rtf`` must be positive, a missing scene file is one error, a launch file without ``type:`` names itself
once, a reader that goes away (``bag info … | head``) ends the command quietly; ``--set hosts.NAME.address``
moves a host and ``clock: {type: sim, rtf: X}`` paces the simulated clock."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexsheet import cli
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from flexsheet.runtime.launch import TOPLEVEL_ENV, LaunchError, load_launch
from flexsheet.runtime.launch_check import check_launch
from flexsheet.runtime.launch_sets import parse_toplevel_set
from messages import Fingertip, Header
from messages import topics as T

ROOT = Path(__file__).resolve().parents[3]


def _tip(stamp: float, seq: int) -> Fingertip:
    p = np.array([0.01, 0.0, 0.0])
    return Fingertip(header=Header(stamp=stamp, frame_id="display", seq=seq), position=p,
                     covariance=np.eye(3) * 1e-8, valid=True, predicted_position=p, exposure_stamp=stamp)


@pytest.mark.parametrize("flag,value", [("--duration", "-5"), ("--duration", "0"), ("--rtf", "0"),
                                        ("--rtf", "-1"), ("--rtf", "nan"), ("--duration", "inf")])
def test_a_duration_or_pace_that_is_not_positive_is_refused_in_one_line(capsys, flag, value):
    with pytest.raises(SystemExit) as exc:
        cli.main(["launch", "launch/sim.yaml", flag, value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"flexsheet launch: error: argument {flag}: {flag} must be a finite number > 0, got '{value}'"


def test_a_missing_scene_file_is_reported_once(monkeypatch):
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"scene": "/nonexistent/organ.yaml"}))
    res = check_launch(ROOT / "launch/sim.yaml")
    hits = [e for e in res.errors if "organ.yaml" in e]
    assert len(hits) == 1 and "no such file" in hits[0], res.errors


def test_a_launch_file_without_type_names_the_file_once(tmp_path, capsys):
    path = tmp_path / "notype.yaml"
    path.write_text("nodes:\n  a: {host: localhost}\n")
    assert cli.main(["launch", str(path)]) == 78
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].count(str(path)) == 1 and "key 'nodes.a.type'" in err[0], err


def test_launch_help_says_a_sim_file_runs_in_one_process(capsys):
    with pytest.raises(SystemExit):
        cli.main(["launch", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "each node as its own process, or the nodes of one container" in text
    assert "--rtf" in text and "hosts.main.address=127.0.0.1" in text


def test_bag_info_into_a_closed_pipe_ends_without_a_traceback(tmp_path):
    bag = tmp_path / "b.mcap"
    w = BagWriter(bag)
    for i in range(200):
        w.write(encode(T.FINGERTIP.name, _tip(1000.0 + i * 0.01, i)), int((1000.0 + i * 0.01) * 1e9))
    w.close()
    proc = subprocess.Popen([sys.executable, "-m", "flexsheet", "bag", "info", str(bag)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                  # the reader is gone before the command writes (as `| head -0`)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141 and "Traceback" not in err and "BrokenPipe" not in err, err


def test_bag_info_prints_a_simulated_start_as_simulated_seconds(tmp_path, capsys):
    bag = tmp_path / "b.mcap"
    w = BagWriter(bag)
    tip = _tip(1000.0, 0)
    w.write(encode(T.FINGERTIP.name, tip), 1_000_000_000_000)
    w.write(encode(T.FINGERTIP.name, tip), 1_002_500_000_000)
    w.close()
    assert cli.main(["bag", "info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "start 1000.000 s simulated, end 1002.500 s simulated" in out and "1970" not in out, out


def test_set_hosts_moves_a_host_and_an_unknown_host_is_one_error(monkeypatch):
    assert parse_toplevel_set("hosts.arm1.address=127.0.0.2", {"world"}) == ("hosts", {"arm1": {"address": "127.0.0.2"}})
    with pytest.raises(LaunchError, match="expected hosts.NAME.address=ADDRESS"):
        parse_toplevel_set("hosts.arm1=127.0.0.2", {"world"})
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"hosts": {"main": {"address": "127.0.0.1"},
                                                           "arm1": {"address": "127.0.0.2"}}}))
    lf = load_launch(ROOT / "launch/lab_sim.yaml")
    assert {n: h.address for n, h in lf.hosts.items()} == {"main": "127.0.0.1", "arm1": "127.0.0.2",
                                                           "arm2": "10.77.0.3"}
    assert lf.endpoint_of("arm_left") == "tcp://127.0.0.2:7508"
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"hosts": {"arm9": {"address": "127.0.0.9"}}}))
    with pytest.raises(LaunchError, match="no host 'arm9' in this file; hosts: main, arm1, arm2"):
        load_launch(ROOT / "launch/lab_sim.yaml")


def test_the_clock_mapping_sets_the_pace_and_pacing_needs_the_simulated_clock(tmp_path, monkeypatch):
    path = tmp_path / "c.yaml"
    path.write_text("clock: {type: sim, rtf: 2}\nnodes:\n  tk: {type: talker}\n")
    lf = load_launch(path)
    assert lf.clock == "sim" and lf.rtf == 2.0
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"rtf": 0.5}))
    assert load_launch(path).rtf == 0.5
    assert load_launch(ROOT / "launch/sim.yaml").rtf == 0.5
    monkeypatch.delenv(TOPLEVEL_ENV)
    path.write_text("clock: {type: wall, rtf: 2}\nnodes:\n  tk: {type: talker}\n")
    with pytest.raises(LaunchError, match="key 'clock.rtf': 2 paces simulated time; it needs clock: sim"):
        load_launch(path)
    path.write_text("clock: {type: sim, speed: 2}\nnodes:\n  tk: {type: talker}\n")
    with pytest.raises(LaunchError, match="unknown key 'speed'"):
        load_launch(path)
