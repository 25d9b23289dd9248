"""The cylinder's cached reference pushes (flexsheet/fem/reference/paths.py): off-axis pushes on the half
model under one key, and the stable path's rows and dtypes."""

from dataclasses import replace

import numpy as np
import pytest

# the slow tier, with the FEM experiment's quick run
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]


def _fake_path_dict(n_dof: int, depths) -> dict:
    d = len(depths)
    return {"u_dof": np.zeros((d, n_dof, 3), np.float32), "force": np.arange(d, dtype=float),
            "newton": np.ones(d, int), "converged": np.ones(d, bool), "min_detF": np.ones(d),
            "inverted": np.zeros(d, int), "max_strain": np.zeros(d), "penetration": np.zeros(d)}


class _KeyRecorder:
    """A stand-in cache for :func:`reference_path` that records (key, what) of every lookup and has
    nothing."""

    def __init__(self):
        self.seen = []

    def load(self, kind, key):
        return None

    def path(self, kind, key):
        return None

    def get_or_compute(self, kind, key, compute, what):
        self.seen.append((key, what))
        return {}, True, 0.0


def test_reference_path_solves_off_axis_pushes_on_the_half_model_under_one_key():
    """Away from azimuth 0 a quarter-model spec (``half_z``) is solved on its half model, as the snapshot
    table meshes it: the quarter and the half spec give one cache entry (one solve), and −0° is 0°."""
    from dataclasses import replace

    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.paths import push_depths, reference_path
    from flexsheet.fem.snapshots import DEFAULT_REF_SPEC

    c = _KeyRecorder()
    probes = np.zeros((2, 3))
    d = push_depths(0.0025)
    for spec, a in ((DEFAULT_REF_SPEC, 10.0), (replace(DEFAULT_REF_SPEC, half_z=False), 10.0),
                    (DEFAULT_REF_SPEC, 0.0), (DEFAULT_REF_SPEC, -0.0)):
        reference_path(spec, a, d, Material(), c, probes)
    (k10q, w10), (k10h, _), (k0, w0), (k0m, _) = c.seen
    assert k10q == k10h and "hz=0" in w10 and k0 == k0m and "hz=1" in w0 and k0 != k10q


def test_stable_path_takes_the_unloaded_rows_only_and_keeps_the_dtypes(tmp_path, monkeypatch):
    """stable_path: rows where stable_states took the unloaded state come from its record, the others are the
    loading path's as cached, every array keeps its dtype; the energies and branch flags are stored; a second
    call reads the "stable" cache entry without touching the loading path."""
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference import paths as X
    from flexsheet.fem.reference.mesh import RefSpec

    depths = np.array([0.01, 0.02, 0.03])
    n_dof, k = 4, 2
    base = {**_fake_path_dict(n_dof, depths), "u": np.zeros((3, k, 3)), "inverted_qp": np.zeros(3, int),
            "inverted_nodal_visible": np.zeros(3, int), "seconds": np.array(1.0),
            "cpu_seconds": np.array(1.0)}
    calls = []

    def fake_reference_path(*a, **kw):
        calls.append(a[1])
        return base

    class FakeModel:
        mesh = type("M", (), {"radius": 0.035, "center": np.zeros(3)})()

    def fake_stable_states(model, caps, states, step, iters):
        moved = [replace(s, u=s.u + 1.0, force=10.0 + j) for j, s in enumerate(states)]
        return ([states[0], moved[1], states[2]], np.array([0, 1, 0]),
                np.array([[3.0, 3.0], [2.0, 1.5], [1.0, 1.0]]))

    def fake_record(model, states, probes, angle_deg):
        n = len(states)
        return {"u": np.full((n, k, 3), 7.0), "u_dof": np.stack([s.u for s in states]).astype(np.float64),
                "force": np.array([s.force for s in states]), "inverted": np.full(n, 5),
                "inverted_qp": np.full(n, 6), "inverted_nodal_visible": np.full(n, 2),
                "min_detF": np.full(n, 0.5),
                "max_strain": np.full(n, 0.25), "penetration": np.full(n, 1e-5), "newton": np.full(n, 9),
                "converged": np.array([True] * n)}

    monkeypatch.setattr(X, "reference_path", fake_reference_path)
    monkeypatch.setattr(X, "reference_model", lambda *a, **kw: FakeModel())
    monkeypatch.setattr(X, "stable_states", fake_stable_states)
    monkeypatch.setattr(X, "_path_record", fake_record)
    cache = ArrayCache(str(tmp_path), shipped_dir=None)
    spec, probes = RefSpec(0.016, 0.012), np.zeros((k, 3))
    z = X.stable_path(spec, 10.0, depths, Material(), cache, probes)
    assert z["branch"].tolist() == [0, 1, 0] and z["energy_unloading"].tolist() == [3.0, 1.5, 1.0]
    assert z["force"].tolist() == [0.0, 11.0, 2.0]  # the loading path's 0 and 2, the record's 11
    assert z["u"][1].max() == 7.0 and z["u"][[0, 2]].max() == 0.0
    assert z["u_dof"].dtype == np.float32 and np.all(z["u_dof"][1] == 1.0) and np.all(z["u_dof"][0] == 0.0)
    assert z["newton"].tolist() == [1, 9, 1] and z["inverted_qp"].tolist() == [0, 6, 0]
    assert z["converged"].dtype == bool
    assert calls == [10.0]
    # the cached entry, no loading path read
    z2 = X.stable_path(spec, 10.0, depths, Material(), cache, probes)
    assert calls == [10.0] and z2["force"].tolist() == [0.0, 11.0, 2.0]
