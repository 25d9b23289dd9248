"""Where flexsheet keeps its cache and its install-time data (flexsheet/dirs.py)."""

from __future__ import annotations

import os

import platformdirs

from flexsheet import dirs
from flexsheet.fem import cache


def test_the_cache_is_the_users_unless_flexsheet_cache_moves_it(monkeypatch, tmp_path):
    monkeypatch.delenv("FLEXSHEET_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert dirs.cache_root() == str(tmp_path / "xdg" / "flexsheet")
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path / "c"))
    assert dirs.cache_root() == str(tmp_path / "c")


def test_data_folders_are_searched_most_specific_first_without_repeats(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("XDG_DATA_DIRS", f"{tmp_path / 'site'}:/usr/share")
    monkeypatch.delenv("FLEXSHEET_DATA", raising=False)
    assert dirs.data_dirs() == [str(tmp_path / "home" / "flexsheet"), str(tmp_path / "site" / "flexsheet")]
    monkeypatch.setenv("FLEXSHEET_DATA", str(tmp_path / "home" / "flexsheet"))     # the same folder once
    assert dirs.data_dirs() == [str(tmp_path / "home" / "flexsheet"), str(tmp_path / "site" / "flexsheet")]
    monkeypatch.setenv("FLEXSHEET_DATA", str(tmp_path / "mine"))
    assert dirs.data_dirs()[0] == str(tmp_path / "mine")


def test_the_installer_writes_the_machines_folder_when_it_may_else_the_users(monkeypatch, tmp_path):
    monkeypatch.delenv("FLEXSHEET_DATA", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("XDG_DATA_DIRS", str(tmp_path / "site"))
    assert dirs.install_data_dir() == str(tmp_path / "site" / "flexsheet")      # creatable: tmp_path is ours
    monkeypatch.setattr(dirs, "_writable", lambda p: False)
    assert dirs.install_data_dir() == str(tmp_path / "home" / "flexsheet")
    monkeypatch.setenv("FLEXSHEET_DATA", str(tmp_path / "d"))
    assert dirs.install_data_dir() == str(tmp_path / "d")


def test_a_folder_below_a_missing_one_is_writable_if_its_nearest_existing_parent_is(tmp_path):
    assert dirs._writable(str(tmp_path / "a" / "b" / "c"))
    assert not dirs._writable("/proc/1/no/such")


def test_the_fem_cache_searches_the_install_folders_after_the_shipped_store_never_the_package():
    assert cache.INSTALL_DIRS == tuple(os.path.join(d, "fem") for d in dirs.data_dirs())
    pkg = os.path.dirname(cache.__file__)
    assert not any(d.startswith(pkg) for d in (cache.INSTALL_DIR, *cache.INSTALL_DIRS))
    assert cache.DEFAULT_CACHE_DIR == os.path.join(platformdirs.user_cache_dir("flexsheet"), "fem")


def test_launch_files_are_the_checkouts_else_the_current_folders(monkeypatch, tmp_path):
    assert dirs.launch_dir() == dirs._CHECKOUT / "launch"
    assert (dirs.launch_dir() / "scenes" / "cylinder.yaml").is_file()
    # an installed package: its folder's parent (site-packages) holds no launch/
    monkeypatch.setattr(dirs, "_CHECKOUT", tmp_path / "site-packages")
    monkeypatch.chdir(tmp_path)
    assert dirs.launch_dir() == tmp_path / "launch"
