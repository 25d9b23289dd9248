"""Every distribution the code imports is declared in pyproject.toml (``deptry``, configured in its
``[tool.deptry]``): an import reached only through another package's dependencies (``lz4`` through ``mcap``)
or preinstalled on one machine (``orjson``) breaks a clean install. The positive control plants the one
undeclared import this project once shipped and sees it named."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("deptry", reason="the test extra's deptry (pip install -e '.[test]')")


def _deptry(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "deptry", ".", "--no-ansi"], cwd=root, capture_output=True,
                          text=True, timeout=120)


def test_every_imported_distribution_is_declared():
    r = _deptry(ROOT)
    assert r.returncode == 0, f"deptry found dependency issues:\n{r.stdout}\n{r.stderr}"
    assert re.search(r"Scanning (\d+) files", r.stdout + r.stderr), r.stdout + r.stderr
    n = int(re.search(r"Scanning (\d+) files", r.stdout + r.stderr).group(1))
    assert n > 300, f"deptry scanned only {n} files: the tree or its excludes changed"


def test_an_undeclared_import_is_named(tmp_path):
    """The same scan on a copy whose pyproject.toml lacks orjson, with the module that imports it."""
    text = (ROOT / "pyproject.toml").read_text()
    lines = [ln for ln in text.splitlines() if not ln.strip().startswith('"orjson')]
    assert len(lines) == len(text.splitlines()) - 1, "pyproject.toml no longer declares orjson on one line"
    (tmp_path / "pyproject.toml").write_text("\n".join(lines) + "\n")
    (tmp_path / "flexsheet" / "runtime").mkdir(parents=True)
    shutil.copy(ROOT / "flexsheet" / "runtime" / "bag_json.py",
                tmp_path / "flexsheet" / "runtime" / "bag_json.py")
    r = _deptry(tmp_path)
    out = r.stdout + r.stderr
    assert r.returncode == 1, out
    # DEP001 where nothing else brings orjson, DEP003 where another package happens to (foxglove-sdk's tree)
    assert re.search(r"bag_json\.py:\d+:\d+: DEP00[13] 'orjson' imported but", out), out
