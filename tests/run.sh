#!/usr/bin/env bash
# The test suite, as the README and CI run it, in two phases on the 2-core machine:
#   1. the pure-computation modules (tests/unit/ and tests/test_layout.py: marker `cpu`, set by folder in tests/conftest.py) on two pytest-xdist workers,
#      a module per worker (tests/conftest.py: groups; the longest groups first, LONGEST_FIRST, so not
#      xdist's reorder by test count), one BLAS/OpenMP thread each;
#   2. everything else (nodes, launches, sockets, windows, deadlines) one by one, with the machine to itself:
#      those tests judge a live loop against the clock.
# Two tiers: by default the tests of every-day work; `tests/run.sh --slow` runs the other tier, the end-to-end tests
# that take over a minute each (marker `slow`: the lab on one machine registered live, the three-namespace lab,
# the faults run, the FEM experiment's study); CI runs both (.ci/run). docs/testing.md lists the tiers and times.
# Other arguments go to both phases (e.g. tests/run.sh -x, tests/run.sh -p no:cacheprovider, tests/run.sh -k bridge);
# not -m, which replaces the phase's own marker selection. With -x a failure in phase 1 skips phase 2; an
# interrupt (Ctrl-C), an internal or a usage error in phase 1 ends the run. $SUITE_JSON=FILE writes the phases'
# wall times and exit codes there (docs/figures/testing/). Plain `python3 -m pytest -q` runs every test of
# both tiers in one process, one by one (slower).
set -u
cd "$(dirname "$0")/.."
tier="not slow"
args=()
for arg in "$@"; do
  case "$arg" in
    --slow) tier="slow";;
    -m|-m*) echo "tests/run.sh: -m selects each phase's tests here; run python3 -m pytest $* instead" >&2; exit 4;;
    *) args+=("$arg");;
  esac
done
LOADAVG0=$(cut -d' ' -f1-3 /proc/loadavg)
t0=$(date +%s)
echo "[tests] tier: $tier; phase 1/2: pure computation (-m 'cpu and $tier') on 2 workers"
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 python3 -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder -m "cpu and $tier" "${args[@]}"
a=$?
t1=$(date +%s)
case $a in 2|3|4) echo "[tests] phase 1 ended with exit $a (interrupted or an error): phase 2 not run" >&2; exit $a;; esac
if [ $a -eq 1 ]; then
  for arg in "${args[@]}"; do
    case "$arg" in -x|--exitfirst) echo "[tests] phase 1 failed and -x: phase 2 not run" >&2; exit 1;; esac
  done
fi
echo "[tests] phase 2/2: nodes, launches and timing (-m 'not cpu and $tier'), one by one"
python3 -m pytest -q -m "not cpu and $tier" "${args[@]}"
b=$?
t2=$(date +%s)
# 5 = no tests collected in that phase (e.g. a selection inside the other phase's modules)
if [ $a -eq 5 ] && [ $b -ne 5 ]; then a=0; fi
if [ $b -eq 5 ] && [ $a -ne 5 ]; then b=0; fi
p1=$((t1 - t0)); p2=$((t2 - t1)); tot=$((t2 - t0))
echo "[tests] tier '$tier': phase 1 exit $a in $p1 s, phase 2 exit $b in $p2 s, $tot s in all"
if [ -n "${SUITE_JSON:-}" ]; then
  mkdir -p "$(dirname "$SUITE_JSON")"
  printf '{"tier": "%s", "phase1_s": %d, "phase2_s": %d, "total_s": %d, "phase1_exit": %d, "phase2_exit": %d, "args": "%s", "cores": %d, "loadavg_before": "%s", "date": "%s", "target_s": %s}\n' \
    "$tier" "$p1" "$p2" "$tot" "$a" "$b" "${args[*]:-}" "$(nproc)" "$LOADAVG0" "$(date -u +%FT%TZ)" \
    "$([ "$tier" = "slow" ] && echo null || echo 600)" > "$SUITE_JSON"
fi
[ $a -ne 0 ] && exit $a
exit $b
