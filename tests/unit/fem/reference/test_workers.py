"""The reference solves' workers (flexsheet/fem/reference/workers.py): the scheduler's address is checked
before any work."""

import pytest

# the slow tier, with the FEM experiment's quick run
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]


def test_scheduler_address_is_checked_before_any_work(tmp_path):
    """--scheduler takes a dask scheduler's tcp://HOST:PORT; anything else is refused naming the value, and
    the local cluster stays the default."""
    from flexsheet.fem.reference import workers

    with pytest.raises(ValueError, match="tcp://HOST:PORT, got 'localhost:8786'"):
        workers.set_scheduler("localhost:8786")
    with pytest.raises(ValueError, match="got 'tcp://h:99999'"):
        workers.set_scheduler("tcp://h:99999")
    assert workers.SCHEDULER is None and not workers.parallel(1) and workers.parallel(2)
    try:
        workers.set_scheduler("tcp://10.77.0.1:8786")
        assert workers.parallel(1)
    finally:
        workers.set_scheduler(None)
    from flexsheet.experiments.fem.cli import main

    with pytest.raises(SystemExit, match="--scheduler must be tcp://HOST:PORT"):
        main(["--quick", "--scheduler", "nowhere", "--out", str(tmp_path)])
