"""The install-time FEM warm-up (``python3 -m nodes.fem.warm``) on an empty cache: it runs the FEM node as a
graph runs it and fills the cache; any model that fails makes it exit 1 with a ``FAILED`` line."""

from __future__ import annotations

from pathlib import Path

import pytest

from flexsheet.fem import cache
from nodes.fem import warm


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    """An empty install folder and HOME: only the tables shipped in the repository are found."""
    monkeypatch.setattr(cache, "INSTALL_DIR", str(tmp_path / "installed"))
    monkeypatch.setattr(cache, "INSTALL_DIRS", (str(tmp_path / "installed"),))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    return tmp_path / "out"


def test_the_warm_up_readies_a_scene_on_an_empty_cache_and_fills_it(empty_cache, capsys):
    assert warm.main(["--out", str(empty_cache), "--scene", "sphere.yaml"]) == 0
    out = capsys.readouterr().out
    assert "[fem warm] sphere.yaml: ready in" in out, out
    assert "FAILED" not in out
    written = sorted(p.name for p in empty_cache.glob("*.npz"))
    assert written, "the warm-up wrote nothing into the empty cache"
    # a second run only loads what the first wrote
    assert warm.main(["--out", str(empty_cache), "--scene", "sphere.yaml"]) == 0
    assert sorted(p.name for p in empty_cache.glob("*.npz")) == written


def test_a_model_that_fails_makes_the_warm_up_exit_1_naming_it(empty_cache, capsys, monkeypatch):
    good = warm.param_sets()
    bad = {**good[0], "scene": str(empty_cache / "no_such_scene.yaml")}
    monkeypatch.setattr(warm, "param_sets", lambda: [bad, good[0]])
    assert warm.main(["--out", str(empty_cache)]) == 1
    cap = capsys.readouterr()
    assert "[fem warm] no_such_scene.yaml: FAILED (" in cap.out, cap.out
    assert f"[fem warm] {Path(good[0]['scene']).name}: ready in" in cap.out     # the rest still warmed
    assert "1 model(s) FAILED" in cap.err


def test_an_unknown_scene_is_a_usage_error_naming_the_known_ones(capsys):
    with pytest.raises(SystemExit) as exc:
        warm.main(["--scene", "nope.yaml"])
    assert exc.value.code == 2
    assert "--scene: unknown nope.yaml; known: cylinder.yaml, organ.yaml" in capsys.readouterr().err
