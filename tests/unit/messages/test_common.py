"""The array fields' validation (messages.common.ndarray): the finiteness check of float arrays (a sum that
overflows is settled element by element; a NaN or inf anywhere, small or large array, is rejected naming the
field), and shape and dtype errors naming expected and got."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import BaseModel, ConfigDict, ValidationError

from flexsheet.runtime.codec import DecodeError, decode, encode
from messages import Fingertip, Header
from messages import topics as T
from messages.common import ndarray


def tip(**kw) -> Fingertip:
    base = dict(header=Header(stamp=12.5, frame_id="display", seq=7), position=np.array([0.01, -0.02, 0.03]),
                covariance=np.eye(3) * 1e-8, valid=True, predicted_position=np.array([0.011, -0.02, 0.03]),
                exposure_stamp=12.49)
    base.update(kw)
    return Fingertip(**base)


class Cloud(BaseModel):
    """A model with a free-length float array (the large-array path) and a float32 one."""

    model_config = ConfigDict(frozen=True, strict=True, arbitrary_types_allowed=True)

    points: ndarray("float64", (None, 3))
    weights: ndarray("float32", None)


def test_finite_values_whose_sum_overflows_are_accepted():
    big = np.array([1.7e308, 1.7e308, -1.0])
    msg = tip(position=big, predicted_position=big)
    out = decode(encode(T.FINGERTIP.name, msg), T.FINGERTIP)
    np.testing.assert_array_equal(out.position, big)
    c = Cloud(points=np.full((1000, 3), 1e308), weights=np.full(500, 3e38, dtype=np.float32))
    assert c.points.shape == (1000, 3) and c.weights.dtype == np.float32


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("n", [1, 64, 65, 5000])
def test_a_non_finite_element_anywhere_is_rejected_naming_the_field(bad, n):
    pts = np.zeros((n, 3))
    pts[n // 2, 2] = bad
    with pytest.raises(ValidationError, match="points"):
        Cloud(points=pts, weights=np.zeros(3, dtype=np.float32))
    w = np.ones(n, dtype=np.float32)
    w[-1] = bad
    with pytest.raises(ValidationError, match="weights"):
        Cloud(points=np.zeros((1, 3)), weights=w)


def test_inf_and_minus_inf_together_are_rejected():
    """Their sum is NaN: still not finite."""
    with pytest.raises(ValueError, match="position"):
        tip(position=np.array([np.inf, -np.inf, 0.0]))
    frames = encode(T.FINGERTIP.name, tip())
    frames[3] = np.array([[1.0, 0, 0], [0, np.inf, 0], [0, 0, -np.inf]]).tobytes()
    with pytest.raises(DecodeError, match="field covariance: .*must be finite"):
        decode(frames, T.FINGERTIP)


def test_shape_and_dtype_errors_name_expected_and_got():
    with pytest.raises(ValidationError, match=r"expected shape \(3, 3\), got \(3, 2\)"):
        tip(covariance=np.zeros((3, 2)))
    with pytest.raises(ValidationError, match=r"expected shape \(N, 3\), got \(4,\)"):
        Cloud(points=np.zeros(4), weights=np.zeros(1, dtype=np.float32))
    with pytest.raises(ValidationError, match="expected dtype float64, got float32"):
        tip(position=np.zeros(3, dtype=np.float32))
    with pytest.raises(ValidationError, match="expected a numpy.ndarray, got list"):
        tip(position=[0.0, 0.0, 0.0])
