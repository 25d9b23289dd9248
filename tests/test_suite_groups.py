"""tests/run.sh's grouping holds: pytest-xdist's ``--dist loadgroup`` sends every test of one ``xdist_group``
to one worker, so a module's session fixtures (the shared sim run, the twin's registrations) are built once.
With pytest 9 and pytest-xdist 3.8 the groups silently fell apart into single tests (pyproject.toml caps
pytest for it)."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_loadgroup_keeps_a_group_on_one_worker(tmp_path):
    """Six tests in group "a" and six in group "b" on two workers: each group's tests report one worker."""
    (tmp_path / "test_groups.py").write_text(textwrap.dedent('''
        import os, pytest

        @pytest.mark.parametrize("k", range(6))
        @pytest.mark.xdist_group("a")
        def test_a(k):
            open(f"a_{k}", "w").write(os.environ["PYTEST_XDIST_WORKER"])

        @pytest.mark.parametrize("k", range(6))
        @pytest.mark.xdist_group("b")
        def test_b(k):
            open(f"b_{k}", "w").write(os.environ["PYTEST_XDIST_WORKER"])
    '''))
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-p",
                        "no:cacheprovider",
                        "-p", "no:randomly", "test_groups.py"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    for g in ("a", "b"):
        workers = {(tmp_path / f"{g}_{k}").read_text() for k in range(6)}
        assert len(workers) == 1, f"group {g} ran on {sorted(workers)}"
