#!/usr/bin/env bash
# The whole test suite, as the README and CI run it, in two phases on the 2-core machine:
#   1. the pure-computation modules (tests/unit/ and tests/test_layout.py: marker `cpu`, set by folder in tests/conftest.py) on two pytest-xdist workers,
#      a module per worker (tests/conftest.py: groups; the longest groups first, LONGEST_FIRST, so not
#      xdist's reorder by test count), one BLAS/OpenMP thread each;
#   2. everything else (nodes, launches, sockets, windows, deadlines) one by one, with the machine to itself:
#      those tests judge a live loop against the clock.
# Arguments go to both phases (e.g. tests/run.sh -x, tests/run.sh -p no:cacheprovider, tests/run.sh -k bridge);
# not -m, which replaces the phase's own marker selection. With -x a failure in phase 1 skips phase 2; an
# interrupt (Ctrl-C), an internal or a usage error in phase 1 ends the run. Plain `python3 -m pytest -q` runs
# the same tests in one process, one by one (slower).
set -u
cd "$(dirname "$0")/.."
for arg in "$@"; do
  case "$arg" in
    -m|-m*) echo "tests/run.sh: -m selects each phase's tests here; run python3 -m pytest $* instead" >&2; exit 4;;
  esac
done
echo "[tests] phase 1/2: pure computation (-m cpu) on 2 workers"
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 python3 -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder -m cpu "$@"
a=$?
case $a in 2|3|4) echo "[tests] phase 1 ended with exit $a (interrupted or an error): phase 2 not run" >&2; exit $a;; esac
if [ $a -eq 1 ]; then
  for arg in "$@"; do
    case "$arg" in -x|--exitfirst) echo "[tests] phase 1 failed and -x: phase 2 not run" >&2; exit 1;; esac
  done
fi
echo "[tests] phase 2/2: nodes, launches and timing (-m 'not cpu'), one by one"
python3 -m pytest -q -m "not cpu" "$@"
b=$?
# 5 = no tests collected in that phase (e.g. a selection inside the other phase's modules)
if [ $a -eq 5 ] && [ $b -ne 5 ]; then a=0; fi
if [ $b -eq 5 ] && [ $a -ne 5 ]; then b=0; fi
echo "[tests] phase 1 exit $a, phase 2 exit $b"
[ $a -ne 0 ] && exit $a
exit $b
