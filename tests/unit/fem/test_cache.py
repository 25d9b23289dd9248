"""The FEM's array cache (flexsheet/fem/cache.py): round trip, hit, a corrupt entry, the shipped store."""

import numpy as np
import pytest

from flexsheet.fem.cache import ArrayCache, cache_key


def _said(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "flexsheet.fem.cache"]


def test_cache_round_trip_hit_and_corrupt_entry(tmp_path, caplog):
    caplog.set_level("INFO", logger="flexsheet.fem.cache")
    c = ArrayCache(str(tmp_path), shipped_dir=None)
    key = cache_key("x", 1.0, (2, 3))
    assert key == cache_key("x", 1.0, (2, 3)) and key != cache_key("x", 1.0000001, (2, 3))
    calls = []

    def compute():
        calls.append(1)
        return {"a": np.arange(3.0)}

    z1, hit1, _ = c.get_or_compute("thing", key, compute)
    z2, hit2, _ = c.get_or_compute("thing", key, compute)
    assert not hit1 and hit2 and len(calls) == 1 and np.array_equal(z1["a"], z2["a"])
    (tmp_path / f"thing_{key}.npz").write_bytes(b"not a zip")
    z3, hit3, _ = c.get_or_compute("thing", key, compute)
    assert not hit3 and len(calls) == 2 and any("unusable" in s for s in _said(caplog))
    assert ArrayCache(None).save("thing", key, {"a": np.zeros(1)}) is None
    with pytest.raises(ValueError, match="kind"):
        c.path("../evil", key)
    # an entry found only in the shipped store says so (the FEM node's diagnostics); the user's cache wins
    store = tmp_path / "store"
    both = ArrayCache(str(tmp_path / "user"), shipped_dir=str(store))
    both_key = cache_key("shipped")
    both.ship("thing", both_key, {"a": np.arange(2.0)})
    z4, hit4, _ = both.get_or_compute("thing", both_key, compute)
    assert (hit4 and both.shipped() and np.array_equal(z4["a"], [0.0, 1.0])
            and "shipped store" in _said(caplog)[-1])
    both.save("thing", both_key, {"a": np.arange(4.0)})
    z5, hit5, _ = both.get_or_compute("thing", both_key, compute)
    assert hit5 and not both.shipped() and len(z5["a"]) == 4 and _said(caplog)[-1].endswith(
        f"from cache (thing_{both_key})")
