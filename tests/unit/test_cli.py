"""The command line (flexsheet.cli): bad input gets one clear line and a non-zero exit, never a traceback:
``--duration`` and ``--rtf`` must be positive, a launch file without ``type:`` names itself once, a reader
that goes away (``bag info … | head``) ends the command quietly; every subcommand's --help shows an
example."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexsheet import cli
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import Fingertip, Header
from messages import topics as T

ROOT = Path(__file__).resolve().parents[2]


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
    assert (err[-1]
            == f"flexsheet launch: error: argument {flag}: {flag} must be a finite number > 0, got '{value}'")


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


@pytest.mark.parametrize("cmd", [[], ["launch"], ["run"], ["topic"], ["node"], ["bag"], ["calibrate"],
                                 ["experiment"], ["bench"]])
def test_every_subcommand_help_shows_an_example(cmd):
    out = subprocess.run([sys.executable, "-m", "flexsheet", *cmd, "--help"], capture_output=True, text=True,
                         timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "example:" in out.stdout and "flexsheet " in out.stdout.split("example:")[1]
