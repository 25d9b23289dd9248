"""The shipped tables' manifests (flexsheet/manifest.py): every shipped file is listed with its SHA-256, size
and the command that wrote it, and shipping a table replaces the old one of its kind."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from flexsheet import manifest

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = [ROOT / "flexsheet" / "fem" / "data", ROOT / "flexsheet" / "model" / "sheet_tables",
           ROOT / "flexsheet" / "twin" / "sheet_tables"]


def test_every_shipped_table_is_in_its_manifest_and_matches_it():
    for folder in SHIPPED:
        entries = json.loads((folder / manifest.MANIFEST).read_text())
        assert set(entries) == {p.name for p in folder.glob("*.npz")} != set()
        assert manifest.verify(folder) == []
        for name, e in entries.items():
            assert e["command"].split()[0] in ("flexsheet", "python"), e
            assert e["kind"] == name.split("_")[0] and name.endswith(f"_{e['key']}.npz")


def test_record_replaces_the_old_table_of_its_kind_and_verify_names_a_changed_file(tmp_path):
    old = tmp_path / "snapshots_aaaa.npz"
    old.write_bytes(b"old")
    other = tmp_path / "pathsnap_cccc.npz"
    other.write_bytes(b"other")
    manifest.record(old, "flexsheet experiment fem --node-table --ship")
    manifest.record(other, "flexsheet experiment fem --scene x --ship")
    new = tmp_path / "snapshots_bbbb.npz"
    new.write_bytes(b"new table")
    e = manifest.record(new, "flexsheet experiment fem --node-table --ship", replaces="snapshots_")
    assert not old.exists() and other.exists()
    assert e == {"kind": "snapshots", "key": "bbbb", "sha256": hashlib.sha256(b"new table").hexdigest(),
                 "size": 9,
                 "command": "flexsheet experiment fem --node-table --ship"}
    assert sorted(json.loads((tmp_path / manifest.MANIFEST).read_text())) == ["pathsnap_cccc.npz",
                                                                              "snapshots_bbbb.npz"]
    assert manifest.verify(tmp_path) == []
    new.write_bytes(b"new tablf")                       # same size, one byte flipped
    assert manifest.verify(tmp_path) == [f"{new}: SHA-256 differs from MANIFEST.json"]
    (tmp_path / "spheresnap_dddd.npz").write_bytes(b"x")
    assert f"{tmp_path / 'spheresnap_dddd.npz'}: not in MANIFEST.json" in manifest.verify(tmp_path)
