"""`flexsheet experiment fem --quick` end to end, cold cache, once per package (fixture ``quick``: a
subprocess of several minutes), read by this folder's modules (test_runs, test_outputs, test_candidates,
studies/: one xdist group, ``SAME_WORKER`` in tests/conftest.py)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = str(Path(__file__).resolve().parents[4])


def _run(out, cache):
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf",
                        "--out", str(out),
                        "--cache-dir", str(cache), "--jobs", "2"], cwd=ROOT, capture_output=True, text=True,
                       timeout=1500)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    with open(os.path.join(out, "summary.json")) as fh:
        return json.load(fh), r.stdout


@pytest.fixture(scope="package")
def quick(tmp_path_factory):
    base = tmp_path_factory.mktemp("fem")
    summ, log = _run(base / "out", base / "cache")
    return base, summ, log
