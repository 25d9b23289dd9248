"""Launch files (flexsheet.runtime.launch, load_launch): ``--set hosts.NAME.address`` moves a host,
``clock: {type: sim, rtf: X}`` paces the simulated clock, a launch extension's sections are validated naming
the key and value.

Hostile launch files: :func:`flexsheet.runtime.launch.load_launch` must give a
:class:`LaunchError` naming the file (and the key where one is at fault) or a valid graph — never another
exception type, never a hang. Inputs: random bytes, non-UTF-8, random YAML documents, valid files with
mutated keys (wrong types, NaN/inf, huge/negative numbers), alias bombs, over-deep nesting, duplicate keys.
Counts are printed at the end (``pytest -s``).
"""

from __future__ import annotations

import collections
import json
import math
import signal
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from flexsheet.runtime.launch import TOPLEVEL_ENV, LaunchError, load_launch
from flexsheet.runtime.launch_sets import parse_toplevel_set

ROOT = Path(__file__).resolve().parents[3]
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                        HealthCheck.function_scoped_fixture],
                database=None)
COUNTS: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
VALID = {"name": "fz", "hosts": {"main": {"address": "127.0.0.1"}}, "base_port": 7100,
         "heartbeat_period": 1.0,
         "nodes": {"w": {"type": "world", "host": "main", "params": {"rate": 10.0},
                         "respawn": {"policy": "on-failure", "delay": 0.5, "max_restarts": 3}},
                   "p": {"type": "planner", "host": "main", "port": 7200, "remaps": {"/fingertip": "/ft"}}}}


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print("\n[fuzz] launch files: inputs tried / rejected (LaunchError) / accepted")
    for target, c in sorted(COUNTS.items()):
        print(f"[fuzz]   {target:<28} tried {c['tried']:5d}  rejected {c['rejected']:5d}  accepted "
              f"{c['accepted']:5d}")


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "l.yaml"
    p.write_text("name: t\n" + text + "nodes:\n  w: {type: world}\n  tk: {type: talker}\n")
    return p


def _alarm(signum, frame):
    raise TimeoutError("load_launch still running after 20 s (hang)")


def check(path: Path, data: bytes, target: str):
    """Write ``data`` to ``path``, load it; assert LaunchError (one line naming the file) or a valid graph."""
    path.write_bytes(data)
    COUNTS[target]["tried"] += 1
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(20)
    try:
        lf = load_launch(path)
    except LaunchError as exc:
        COUNTS[target]["rejected"] += 1
        text = str(exc)
        assert text.startswith(str(path)) and "\n" not in text and len(text) < 1200, text[:300]
        return None
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    COUNTS[target]["accepted"] += 1
    eps = lf.endpoints()
    assert len(set(eps.values())) == len(eps)
    for name, ep in eps.items():
        assert int(ep.rsplit(":", 1)[1]) <= 65535 or lf.nodes[name].endpoint
    assert math.isfinite(lf.heartbeat_period) and lf.heartbeat_period > 0
    return lf


def test_repo_launch_files_load():
    files = sorted((ROOT / "launch").glob("*.yaml"))
    assert files
    for f in files:
        assert load_launch(f).nodes


@FUZZ
@given(data=st.binary(max_size=400))
def test_random_bytes(tmp_path, data):
    check(tmp_path / "l.yaml", data, "random bytes")


yaml_leaf = st.one_of(st.none(), st.booleans(), st.integers(-(2 ** 70), 2 ** 70), st.floats(allow_nan=True),
                      st.text(max_size=20))
yaml_doc = st.recursive(yaml_leaf, lambda c: st.lists(c, max_size=4) | st.dictionaries(
    st.one_of(st.sampled_from(["nodes", "hosts", "type", "port", "params", "base_port", "respawn", "name"]),
              st.text(max_size=8)), c, max_size=4), max_leaves=25)


@FUZZ
@given(doc=yaml_doc)
def test_random_yaml_documents(tmp_path, doc):
    check(tmp_path / "l.yaml", yaml.safe_dump(doc).encode(), "random YAML")


PATHS = [("name",), ("hosts",), ("hosts", "main"), ("hosts", "main", "address"), ("base_port",),
         ("heartbeat_period",), ("shutdown_timeout",), ("report",), ("nodes",), ("nodes", "w"),
         ("nodes", "w", "type"), ("nodes", "w", "host"), ("nodes", "w", "port"), ("nodes", "w", "endpoint"),
         ("nodes", "w", "params"), ("nodes", "w", "remaps"), ("nodes", "w", "respawn", "delay"),
         ("nodes", "w", "respawn", "policy"), ("nodes", "w", "respawn", "max_restarts"),
         ("nodes", "w", "required"),
         ("nodes", "p", "port"), ("security", "curve"), ("security", "public_keys"), ("bogus",)]
hostile = st.one_of(yaml_leaf,
                    st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, 2 ** 63, 65536, 1e300, "",
                                     "tcp://", "x" * 500, [], {}]),
                    st.lists(yaml_leaf, max_size=3),
                    st.dictionaries(st.text(max_size=5), yaml_leaf, max_size=3))


@FUZZ
@given(path=st.sampled_from(PATHS), value=hostile)
@example(path=("hosts",), value={"\n": None})      # found by hypothesis: a key with a newline
def test_mutated_valid_file(tmp_path, path, value):
    import copy

    doc = copy.deepcopy(VALID)
    d = doc
    for k in path[:-1]:
        d = d.setdefault(k, {})
    d[path[-1]] = value
    lf = check(tmp_path / "l.yaml", yaml.safe_dump(doc).encode(), "mutated keys")
    if lf is not None:  # typed keys accept only their own type, finite
        leaf = path[-1]
        if leaf in ("base_port", "port", "max_restarts"):
            assert type(value) is int or (leaf == "port" and value is None)
        if leaf in ("heartbeat_period", "shutdown_timeout", "delay"):
            assert type(value) in (int, float) and math.isfinite(value)
        if leaf == "bogus":
            pytest.fail("unknown key accepted")


def test_hostile_structures(tmp_path):
    """Alias bomb (9^9 leaves if expanded), 5000-deep nesting, duplicate keys, non-UTF-8, huge file, a
    directory, ports running past 65535: each a LaunchError, none a hang or a crash."""
    bomb = "a: &a [x,x,x,x,x,x,x,x,x]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [" + ",".join([f"*{chr(97 + i)}"] * 9) + "]\n" for i in range(8))
    cases = {
        "alias bomb in nodes": bomb + "nodes: *i\n",
        "alias bomb in hosts": bomb + "hosts: *i\nnodes: {}\n",
        "deep nesting": "nodes: " + "[" * 5000 + "]" * 5000,
        "duplicate key": "nodes: {w: {type: world}}\nnodes: {}\n",
        "duplicate node": "nodes:\n  w: {type: world}\n  w: {type: planner}\n",
        "non-UTF-8": b"nodes: {w: {type: \xff\xfe}}\n",
        "huge file": b"#" * (2 << 20),
        "ports past 65535": "base_port: 65000\nnodes:\n" + "".join(f"  n{i}: {{type: "
                                                                   "world}\n" for i in range(540)),
        "python tag": "nodes: !!python/object/apply:os.system [echo hi]\n",
        "recursive": "nodes: &a {x: *a}\n",
        "inf period": "heartbeat_period: .inf\nnodes: {}\n",
        "bool port": "nodes: {w: {type: world, port: true}}\n",
        "string port": "nodes: {w: {type: world, port: '7300'}}\n",
        "bad endpoint": "nodes: {w: {type: world, endpoint: 'not an endpoint'}}\n",
    }
    for name, text in cases.items():
        data = text if isinstance(text, bytes) else text.encode()
        assert check(tmp_path / "l.yaml", data, "hostile structures") is None, f"{name}: accepted"
    COUNTS["hostile structures"]["tried"] += 1
    with pytest.raises(LaunchError, match="cannot read"):
        load_launch(tmp_path)  # a directory
    COUNTS["hostile structures"]["rejected"] += 1


def test_set_hosts_moves_a_host_and_an_unknown_host_is_one_error(monkeypatch):
    assert (parse_toplevel_set("hosts.arm1.address=127.0.0.2", {"world"})
            == ("hosts", {"arm1": {"address": "127.0.0.2"}}))
    with pytest.raises(LaunchError, match="expected hosts.NAME.address=ADDRESS"):
        parse_toplevel_set("hosts.arm1=127.0.0.2", {"world"})
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"hosts": {"main": {"address": "127.0.0.1"},
                                                           "arm1": {"address": "127.0.0.2"}}}))
    lf = load_launch(ROOT / "launch/lab_sim.yaml")
    assert {n: h.address for n, h in lf.hosts.items()} == {"main": "127.0.0.1", "arm1": "127.0.0.2",
                                                           "arm2": "10.77.0.3"}
    assert lf.endpoint_of("arm_left") == "tcp://127.0.0.2:7508"
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"hosts": {"arm9": {"address": "127.0.0.9"}}}))
    with pytest.raises(LaunchError, match="no host 'arm9' in this file; hosts: main, arm1, arm2"):
        load_launch(ROOT / "launch/lab_sim.yaml")


def test_the_clock_mapping_sets_the_pace_and_pacing_needs_the_simulated_clock(tmp_path, monkeypatch):
    path = tmp_path / "c.yaml"
    path.write_text("clock: {type: sim, rtf: 2}\nnodes:\n  tk: {type: talker}\n")
    lf = load_launch(path)
    assert lf.clock == "sim" and lf.rtf == 2.0
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"rtf": 0.5}))
    assert load_launch(path).rtf == 0.5
    assert load_launch(ROOT / "launch/sim.yaml").rtf == 0.5
    monkeypatch.delenv(TOPLEVEL_ENV)
    path.write_text("clock: {type: wall, rtf: 2}\nnodes:\n  tk: {type: talker}\n")
    with pytest.raises(LaunchError, match="key 'clock.rtf': 2 paces simulated time; it needs clock: sim"):
        load_launch(path)
    path.write_text("clock: {type: sim, speed: 2}\nnodes:\n  tk: {type: talker}\n")
    with pytest.raises(LaunchError, match="unknown key 'speed'"):
        load_launch(path)


def test_sections_are_validated_with_the_key_and_value_named(tmp_path):
    with pytest.raises(LaunchError) as exc:
        load_launch(_write(tmp_path, "twin: {truth_seed: -1, realism: bogus}\nscene: 3\nbogus_section: 1\n"))
    lines = exc.value.lines
    assert any("key 'twin.truth_seed'" in x and "(value -1)" in x for x in lines), lines
    assert any("key 'twin.realism'" in x and "'bogus'" in x for x in lines), lines
    assert any("key 'scene'" in x and "(value 3)" in x for x in lines), lines
    assert any("key 'bogus_section'" in x and "Extra inputs are not permitted" in x for x in lines), lines
