"""Hostile input for the stereo calibration loader and the Modbus register decoder.

* :func:`flexsheet.vision.calib_yaml.load_yaml`: random bytes, valid OpenCV YAML with mutated numbers
  (NaN/inf, huge, negative, zero), wrong shapes, missing keys. Contract (its docstring): ``ValueError``
  naming the file and key, or a calibration with finite values of the documented shapes.
* :mod:`messages.registers`: register images of any length and content (negative, > 65535,
  floats, bools, None, strings, numpy scalars) and wrong container types. Contract: ``ValueError`` naming
  the register, or a decoded state equal to what was encoded.

The bugs fuzzing found there (cv2.FileStorage heap corruption on negative rows/cols, SystemError/
OverflowError/NaN from the calibration loader, TypeError/OverflowError from the register codec) are
fixed; their reproducers stay as regression tests. Counts are printed at the end (``pytest -s``).
"""

from __future__ import annotations

import collections
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexsheet.vision.calib_yaml import load_yaml, write_yaml
from messages import registers as reg

FUZZ = settings(max_examples=60, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
COUNTS: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print("\n[fuzz] calibration loader / register decoder: inputs tried / rejected (ValueError) / accepted / "
          "other exception (bug)")
    for target, c in sorted(COUNTS.items()):
        print(f"[fuzz]   {target:<34} tried {c['tried']:5d}  rejected {c['rejected']:5d}  "
              f"accepted {c['accepted']:5d}  other {c['other']:3d}")


K = np.array([[800.0, 0, 320], [0, 800.0, 256], [0, 0, 1]])
GOOD = dict(image_size=(640, 512), K1=K, D1=np.zeros(5), K2=K.copy(), D2=np.zeros(5), R=np.eye(3),
            T=np.array([-0.1, 0.0, 0.0]))


def _good_text(tmp_path) -> str:
    p = tmp_path / "good.yaml"
    write_yaml(str(p), GOOD)
    return p.read_text()


def _load(path, target: str, strict: bool):
    """Load; count; return ('ok', calib) | ('rejected', msg) | ('other', exc). ``strict`` re-raises others."""
    COUNTS[target]["tried"] += 1
    try:
        calib = load_yaml(str(path))
    except ValueError as exc:
        COUNTS[target]["rejected"] += 1
        return "rejected", str(exc)
    except Exception as exc:  # noqa: BLE001 - counted: another type is a contract violation
        COUNTS[target]["other"] += 1
        if strict:
            raise
        return "other", exc
    COUNTS[target]["accepted"] += 1
    return "ok", calib


def _check_accepted(calib: dict) -> None:
    for key in ("K1", "K2", "R"):
        assert calib[key].shape == (3, 3), key
    assert calib["T"].shape == (3,) and calib["D1"].shape == (5,) and calib["D2"].shape == (5,)
    w, h = calib["image_size"]
    assert w > 0 and h > 0


def test_good_calibration_round_trips(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text(_good_text(tmp_path))
    kind, calib = _load(p, "calibration: valid", strict=True)
    assert kind == "ok"
    _check_accepted(calib)
    np.testing.assert_allclose(calib["K1"], K)


NUM = re.compile(r"(?<![A-Za-z_])-?\d+\.?\d*(?:e[-+]?\d+)?")
hostile_num = st.sampled_from([".nan", ".inf", "-.inf", "1e308", "-1e308", "0", "-1", "0.", "1e-320", "abc",
                               "[]",
                               "99999999999999999999999", "nan", "inf"])


@FUZZ
@given(data=st.data())
def test_calibration_mutated_numbers(tmp_path, data):
    """One number of a valid file replaced by a hostile token: ValueError, or finite documented shapes."""
    text = _good_text(tmp_path)
    spans = [m.span() for m in NUM.finditer(text)]
    a, b = data.draw(st.sampled_from(spans))
    tok = data.draw(hostile_num)
    line = text[:a].rsplit("\n", 1)[-1]
    if line.strip() in ("rows:", "cols:") and tok.startswith("-"):
        # negative rows/cols corrupt the heap inside cv2.FileStorage: see test_calibration_heap_corruption
        tok = "0"

    p = tmp_path / "c.yaml"
    p.write_text(text[:a] + tok + text[b:])
    kind, out = _load(p, "calibration: mutated numbers", strict=False)
    if kind == "ok":
        _check_accepted(out)


@FUZZ
@given(data=st.binary(max_size=300))
def test_calibration_random_bytes(tmp_path, data):
    p = tmp_path / "c.yaml"
    p.write_bytes(b"%YAML:1.0\n---\n" + data if data[:1] == b"\x00" else data)
    kind, out = _load(p, "calibration: random bytes", strict=False)
    if kind == "ok":
        _check_accepted(out)


def test_calibration_wrong_shapes_and_missing_keys(tmp_path):
    text = _good_text(tmp_path)
    cases = {
        "K1 2x2": text.replace("K1: !!opencv-matrix\n   rows: 3\n   cols: 3",
                               "K1: !!opencv-matrix\n   rows: 2\n   cols: 2")
                      .replace("data: [ 800., 0., 320., 0., 800., 256., 0., 0., 1. ]",
                               "data: [ 800., 0., 0., 800. ]", 1),
        "no R": re.sub(r"R: !!opencv-matrix\n(   .*\n){4}", "", text, count=1),
        "no width": text.replace("image_width: 640\n", ""),
        "negative height": text.replace("image_height: 512", "image_height: -512"),
        "missing file": None,
    }
    for name, t in cases.items():
        p = tmp_path / f"{name.replace(' ', '_')}.yaml"
        if t is not None:
            p.write_text(t)
        kind, out = _load(p, "calibration: shapes/keys", strict=True)
        assert kind == "rejected", f"{name}: {kind}"
        assert str(p) in out or "not found" in out


# flexsheet/vision/stereo_calibration.py load_yaml: reproducers of contract violations found by fuzzing
CALIB_BUGS = {
    "garbage bytes -> SystemError from cv2.FileStorage": b"\x00\xff garbage",
    "empty file -> SystemError from cv2.FileStorage": b"",
    "image_width .inf -> OverflowError": ("image_width: 640", "image_width: .inf"),
    "image_width 1e300 -> cv2.error in stereoRectify": ("image_width: 640", "image_width: 1e300"),
    "NaN in K1 accepted": ("800.", ".nan"),
}


def test_calibration_former_bugs_are_rejected(tmp_path):
    text = _good_text(tmp_path)
    bad = []
    for name, case in CALIB_BUGS.items():
        p = tmp_path / "b.yaml"
        if isinstance(case, bytes):
            p.write_bytes(case)
        else:
            p.write_text(text.replace(case[0], case[1], 1))
        kind, out = _load(p, "calibration: known-bug reproducers", strict=False)
        if (kind == "other"
            or (kind == "ok" and not all(np.isfinite(out[k]).all() for k in ("K1", "K2", "R", "T")))):
            bad.append(f"{name}: {kind} {out!r:.80}")
    assert not bad, "; ".join(bad)


# ---------------------------------------------------------------------------------------------- registers
reg_value = st.one_of(st.integers(0, 0xFFFF), st.integers(-(2 ** 40), 2 ** 40), st.booleans(), st.none(),
                      st.floats(allow_nan=True), st.text(max_size=3),
                      st.integers(0, 0xFFFF).map(np.uint16), st.integers(-5, 70000).map(np.int64),
                      st.floats(allow_nan=True).map(np.float64))


def _decode(fn, *args, target: str):
    COUNTS[target]["tried"] += 1
    try:
        out = fn(*args)
    except ValueError as exc:
        COUNTS[target]["rejected"] += 1
        assert str(exc) and "\n" not in str(exc)
        return None
    COUNTS[target]["accepted"] += 1
    return out


def _is_reg(v) -> bool:
    return not isinstance(v, (bool, np.bool_)) and isinstance(v, (int, np.integer)) and 0 <= int(v) <= 0xFFFF


@settings(max_examples=150, deadline=None, database=None)
@given(regs=st.one_of(st.lists(reg_value, min_size=reg.IR_COUNT, max_size=reg.IR_COUNT),
                      st.lists(reg_value, max_size=60)))
def test_decode_input_hostile_images(regs):
    st_ = _decode(reg.decode_input, regs, target="registers: decode_input")
    valid = len(regs) == reg.IR_COUNT and all(_is_reg(v) for v in regs)
    assert (st_ is not None) == valid, f"valid={valid} accepted={st_ is not None}"
    if st_ is not None:
        assert (np.isfinite(st_.position).all()
                and np.abs(st_.position).max() <= reg.INT32_MAX * reg.SCALE + 1e-9)
        assert st_.status == regs[reg.IR_STATUS] and 0 <= st_.cycle < 2 ** 32


@settings(max_examples=150, deadline=None, database=None)
@given(q=st.lists(st.one_of(st.floats(min_value=-1e300, max_value=1e300),
                            st.sampled_from([math.nan, math.inf, -math.inf, 2147.483647, 2147.4836475,
                                             -2147.483648,
                                             -2147.4836485, 1e-7, 5e-7])), min_size=6, max_size=6))
def test_joint_encode_decode_round_trip_or_valueerror(q):
    regs = _decode(reg.encode_joints, q, target="registers: encode_joints")
    if regs is None:
        assert not all(math.isfinite(x) and abs(round(x / reg.SCALE)) <= reg.INT32_MAX for x in q)
        return
    back = _decode(reg.decode_joints, regs, target="registers: decode_joints")
    assert back is not None and np.allclose(back, q, atol=reg.SCALE / 2 + 1e-12, rtol=0)


@settings(max_examples=100, deadline=None, database=None)
@given(hi=reg_value, lo=reg_value)
def test_register_pairs(hi, lo):
    for fn, name in ((reg.decode_i32, "decode_i32"), (reg.decode_u32, "decode_u32")):
        out = _decode(fn, hi, lo, target=f"registers: {name}")
        assert (out is not None) == (_is_reg(hi) and _is_reg(lo))
    out = _decode(reg.decode_status, hi, target="registers: decode_status")
    assert (out is not None) == _is_reg(hi)
    out = _decode(reg.check_command, hi, target="registers: check_command")
    assert (out is not None) == (_is_reg(hi) and not int(hi) & ~reg.CMD_MASK)


def test_register_wrong_containers_rejected():
    bad = []
    COUNTS["registers: wrong containers"]["tried"] += 1
    try:
        # |q|/SCALE overflows to inf: round() raises OverflowError
        reg.encode_joints([0, 0, 0, 0, 0, 1.8e302])
    except ValueError:
        COUNTS["registers: wrong containers"]["rejected"] += 1
    except Exception as exc:  # noqa: BLE001
        COUNTS["registers: wrong containers"]["other"] += 1
        bad.append(f"encode_joints([.., 1.8e302]): {type(exc).__name__}: {exc}")
    for regs in (None, 5, {i: 0 for i in range(reg.IR_COUNT)}, (i for i in range(reg.IR_COUNT))):
        for fn in (reg.decode_input, reg.decode_joints):
            COUNTS["registers: wrong containers"]["tried"] += 1
            try:
                fn(regs)
            except ValueError:
                COUNTS["registers: wrong containers"]["rejected"] += 1
            except Exception as exc:  # noqa: BLE001
                COUNTS["registers: wrong containers"]["other"] += 1
                bad.append(f"{fn.__name__}({type(regs).__name__}): {type(exc).__name__}: {exc}")
    assert not bad, "; ".join(bad)


HEAP_REPRO = """
import numpy as np
from flexsheet.vision.calib_yaml import load_yaml, write_yaml
K = np.array([[800.0, 0, 320], [0, 800.0, 256], [0, 0, 1]])
write_yaml("{d}/good.yaml", dict(image_size=(640, 512), K1=K, D1=np.zeros(5), K2=K, D2=np.zeros(5), R=np.eye(3),
                                 T=np.array([-0.1, 0, 0])))
text = open("{d}/good.yaml").read()
d1 = text.index("D1:")
for old, new in (("rows: 5", "rows: -1"), ("cols: 1", "cols: -1")) * 200:
    open("{d}/bad.yaml", "w").write(text[:d1] + text[d1:].replace(old, new, 1))
    try:
        load_yaml("{d}/bad.yaml")
    except ValueError:
        pass
"""  # noqa: E501 - a table, template or command line kept whole


def test_calibration_negative_rows_cols_never_reach_opencv(tmp_path):
    """A calibration file with ``rows: -1`` / ``cols: -1`` (loaded repeatedly) must raise ValueError, not
    abort the process. Run in a child process: the abort would kill pytest."""
    import subprocess
    import sys

    COUNTS["calibration: negative rows/cols"]["tried"] += 400
    r = subprocess.run([sys.executable, "-c", HEAP_REPRO.format(d=tmp_path)], capture_output=True, text=True,
                       timeout=120, cwd=str(Path(__file__).resolve().parents[2]))
    if r.returncode != 0:
        COUNTS["calibration: negative rows/cols"]["other"] += 1
    assert r.returncode == 0, f"rc {r.returncode}: {r.stderr.strip()[-200:]}"
