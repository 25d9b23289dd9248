"""flexsheet bench sim's arithmetic (flexsheet.benches.sim): CPU-seconds per simulated second from a launch's
clock file, the runtime's share as the process's rest, and clear errors on files that are not a sim
launch's."""

import pytest

from flexsheet.benches.sim import BUDGET, RTF_TARGET, cost_per_sim_s

SIM_CLOCK = {"sim_s": 20.0, "wall_s": 16.0, "realtime_factor": 1.25, "process_cpu_run_s": 10.0,
             "host_handler_cpu_s": {"camera": 9.0, "planner": 9.0, "world": 9.0},   # with start-up: not read
             "host_handler_cpu_run_s": {"camera": 2.0, "planner": 3.0, "world": 1.0}}


def test_per_node_cost_and_the_runtime_as_the_rest_of_the_process_over_the_run_only():
    c = cost_per_sim_s(SIM_CLOCK)
    assert c["nodes"] == pytest.approx({"camera": 0.1, "planner": 0.15, "world": 0.05})
    assert c["total"] == pytest.approx(0.5)
    assert c["runtime"] == pytest.approx(0.2)            # 10 − 6 CPU-s over 20 simulated s
    assert c["realtime_factor"] == 1.25
    # threads' CPU beyond the process's (clock granularity) never gives a negative runtime
    assert cost_per_sim_s({**SIM_CLOCK, "process_cpu_run_s": 5.0})["runtime"] == 0.0


def test_the_budgets_share_one_core_at_the_target_speed():
    assert sum(BUDGET.values()) == pytest.approx(1.0 / RTF_TARGET, abs=0.01)


@pytest.mark.parametrize("clock, match", [
    ({k: v for k, v in SIM_CLOCK.items() if k != "host_handler_cpu_run_s"}, "host_handler_cpu_run_s"),
    ({k: v for k, v in SIM_CLOCK.items() if k != "process_cpu_run_s"}, "process_cpu_run_s"),
    ({**SIM_CLOCK, "sim_s": 0.0}, "sim_s must be > 0, got 0.0"),
])
def test_files_that_are_not_a_sim_launchs_are_named(clock, match):
    with pytest.raises(ValueError, match=match):
        cost_per_sim_s(clock)


def _busy(n):
    s = 0
    for i in range(n):          # in its own frame: its own time is the loop's (a generator's is not)
        s += i * i
    return s


def test_the_profile_ranks_a_known_hot_function_per_simulated_second(tmp_path):
    """A stats file of a run that called a known function 30 times: it is named with its file and line, its
    calls counted, its own time divided by the simulated span; a span that is not > 0 is refused."""
    import cProfile

    from flexsheet.benches.sim_profile import hottest
    prof = cProfile.Profile()
    prof.runcall(lambda: [_busy(20000) for _ in range(30)])
    prof.dump_stats(tmp_path / "p.pstats")
    h1, h10 = hottest(tmp_path / "p.pstats", 1.0), hottest(tmp_path / "p.pstats", 10.0)
    row = next(r for r in h1["functions"] if r["function"] == "_busy")
    assert row["where"].startswith("tests/unit/benches/test_sim.py:") and row["calls"] == 30
    row10 = next(r for r in h10["functions"] if r["function"] == "_busy")
    assert row10["cumulative"] == pytest.approx(row["cumulative"] / 10.0, rel=0.02, abs=2e-4)
    assert any(f["file"] == "tests/unit/benches/test_sim.py" for f in h1["files"])
    assert h1["total_own"] >= row["own"] > 0.0
    with pytest.raises(ValueError, match="sim_s must be > 0"):
        hottest(tmp_path / "p.pstats", 0.0)
