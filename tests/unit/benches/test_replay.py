"""flexsheet bench replay's comparison of two replays (flexsheet.benches.replay.bag_digest) and its argument
errors."""

import numpy as np
import pytest

from flexsheet.benches.replay import bag_digest, main
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import Fingertip, Header
from messages import topics as T


def _bag(path, xs):
    bw = BagWriter(path)
    for i, x in enumerate(xs):
        msg = Fingertip(header=Header(stamp=1.0 + 0.01 * i, frame_id="display", seq=i),
                        position=np.array([x, 0.0, 0.0]), valid=True, covariance=np.eye(3) * 1e-8,
                        predicted_position=np.array([x, 0.0, 0.0]), exposure_stamp=1.0 + 0.01 * i)
        bw.write(encode(T.FINGERTIP.name, msg), int((1.0 + 0.01 * i) * 1e9))
    bw.close()
    return path


def test_two_bags_of_the_same_messages_agree_and_one_changed_bit_of_one_message_does_not(tmp_path):
    xs = [0.01 * k for k in range(50)]
    a = bag_digest(_bag(tmp_path / "a.mcap", xs))
    b = bag_digest(_bag(tmp_path / "b.mcap", xs))
    assert a == b and a[T.FINGERTIP.name][0] == 50
    ys = list(xs)
    ys[37] = np.nextafter(ys[37], 1.0)           # one message, one ulp of one field
    c = bag_digest(_bag(tmp_path / "c.mcap", ys))
    assert c[T.FINGERTIP.name][0] == 50 and c != a


@pytest.mark.parametrize("argv, match", [(["--runs", "1"], "--runs must be at least 2"),
                                         (["--duration", "0"], "--duration must be > 0"),
                                         (["--bag", "no/such.mcap"], "--bag: no file")])
def test_arguments_that_cannot_measure_are_refused_before_anything_runs(argv, match, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2 and match in capsys.readouterr().err
