"""``flexsheet launch --check`` (flexsheet.runtime.launch_check): a missing scene file is one error; on
hostile values it never raises and reports one line per problem."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import yaml
from hypothesis import given
from hypothesis import strategies as st

from flexsheet.runtime.launch import TOPLEVEL_ENV
from flexsheet.runtime.launch_check import check_launch
from unit.runtime.test_launch import COUNTS, FUZZ, VALID, _alarm, _report, hostile  # noqa: F401 - _report: the counts at the end

ROOT = Path(__file__).resolve().parents[3]


def test_a_missing_scene_file_is_reported_once(monkeypatch):
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"scene": "/nonexistent/organ.yaml"}))
    res = check_launch(ROOT / "launch/sim.yaml")
    hits = [e for e in res.errors if "organ.yaml" in e]
    assert len(hits) == 1 and "no such file" in hits[0], res.errors


CHECK_PATHS = [("nodes", "w", "params", "rate_hz"), ("nodes", "w", "params", "script"),
               ("nodes", "p", "params"),
               ("nodes", "p", "params", "shape"), ("nodes", "p", "params", "calib_file"), ("display_calib",),
               ("security",), ("security", "curve"), ("security", "public_keys_file"),
               ("security", "keys_dir"),
               ("hosts", "main", "address"), ("report",), ("nodes", "w", "params", "host")]


@FUZZ
@given(path=st.sampled_from(CHECK_PATHS), value=hostile)
def test_check_never_raises_and_reports_one_line_per_problem(tmp_path, path, value):
    """``flexsheet launch --check`` on hostile values: a :class:`CheckResult` whose every error is one line
    naming the file (never an exception, never a hang)."""
    import copy

    from flexsheet.runtime.launch_check import check_launch

    doc = copy.deepcopy(VALID)
    doc["nodes"]["w"]["params"] = {"rate_hz": 10.0}  # valid for the world node: only the mutation is wrong
    d = doc
    for k in path[:-1]:
        d = d.setdefault(k, {})
    d[path[-1]] = value
    p = tmp_path / "l.yaml"
    p.write_text(yaml.safe_dump(doc))
    COUNTS["check"]["tried"] += 1
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(20)
    try:
        res = check_launch(p, host="main", out=str(tmp_path / "out"))
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    COUNTS["check"]["rejected" if res.errors else "accepted"] += 1
    for line in res.errors + res.warnings:
        assert line.startswith(str(p)) and "\n" not in line and len(line) < 1500, line[:300]
