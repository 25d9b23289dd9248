#!/usr/bin/env bash
# The test suite, as the README and CI run it, in three phases on the 2-core machine:
#   1. the pure-computation modules (tests/unit/ and tests/test_*.py: marker `cpu`, set by folder in tests/conftest.py)
#      on two pytest-xdist workers, a module per worker (tests/conftest.py: groups; the longest groups first,
#      LONGEST_FIRST, so not xdist's reorder by test count), one BLAS/OpenMP thread each;
#   2. the nodes and launched graphs on two workers, a module per worker, each worker's graphs in a domain of
#      their own (FLEXSHEET_TEST_DOMAINS: tests/conftest.py sets FLEXSHEET_DOMAIN_ID 10 + the worker's number);
#   3. the tests that judge a live loop against the wall clock (marker `alone`, tests/conftest.py ALONE) one by
#      one, with the machine to themselves.
# Modes (docs/testing.md lists them and their times):
#   tests/run.sh           the every-day tier, phases 1-3 (the README's test command; CI gates on it)
#   tests/run.sh --slow    the slow tier's phases 1-2: end-to-end tests of over a minute each on the simulated
#                          clock (marker `slow`: the FEM experiment's study, the experiments' quick modes); CI gates
#   tests/run.sh --wall    the slow tier's phase 3: the whole graph live against the wall clock (faults, partition,
#                          three hosts in network namespaces, live registration, the MXT stroke); not in CI
#   tests/run.sh --soak    an hour of launch/lab_sim.yaml with a viewer and the recorder (tests/soak.py; not in CI)
#   tests/run.sh --image   builds docker/Dockerfile without a Docker engine (buildah) and runs the main job in it
#                          (docker/prove_image.sh: docs/figures/image/image.json; as root, not in CI)
#   tests/run.sh --bare    the README's first command in a bare Debian 12 made with debootstrap
#                          (docker/prove_bare.sh: docs/figures/image/bare.json; as root, not in CI)
# Other arguments go to every phase (e.g. tests/run.sh -x, tests/run.sh -p no:cacheprovider, tests/run.sh -k bridge);
# not -m, which replaces the phase's own marker selection. With -x a failure in phase 1 skips phase 2; an
# interrupt (Ctrl-C), an internal or a usage error in phase 1 ends the run. $SUITE_JSON=FILE writes the phases'
# wall times and exit codes there (docs/figures/testing/). Plain `python3 -m pytest -q` runs every test of
# both tiers in one process, one by one (slower).
set -u
cd "$(dirname "$0")/.." || exit 4
# the proofs of the image and of the install need no virtual environment: dispatched before it is looked for
case "${1:-}" in
  --image) shift; exec bash docker/prove_image.sh "$@";;
  --bare) shift; exec bash docker/prove_bare.sh "$@";;
esac
# the virtual environment docker/install.sh made ($FLEXSHEET_VENV, default .venv): its python3, pytest, flexsheet
venv=${FLEXSHEET_VENV:-$PWD/.venv}
if [ -x "$venv/bin/python" ]; then
  export VIRTUAL_ENV=$venv PATH="$venv/bin:$PATH"
elif ! python3 -c "import flexsheet, pytest" >/dev/null 2>&1; then
  echo "tests/run.sh: no virtual environment at $venv and python3 has no flexsheet: run bash docker/install.sh" >&2
  exit 4
fi
tier="not slow"
mode=everyday
phases="1 2 3"
args=()
for arg in "$@"; do
  case "$arg" in
    --slow) tier="slow"; mode=slow; phases="1 2";;
    --wall) tier="slow"; mode=wall; phases="3";;
    --soak) exec python3 tests/soak.py;;
    -m|-m*) echo "tests/run.sh: -m selects each phase's tests here; run python3 -m pytest $* instead" >&2; exit 4;;
    *) args+=("$arg");;
  esac
done
want() { case " $phases " in *" $1 "*) return 0;; esac; return 1; }
# each phase collects only its own folders (a collection of every module costs ~10 s a phase); a path among the
# arguments selects instead, then each phase keeps what of it its marker takes
paths1=(tests/unit tests/test_*.py); paths2=(tests/nodes tests/system tests/test_docs_run.py)
mapfile -t paths3 < <(python3 -c "import ast, pathlib; t = ast.parse(pathlib.Path('tests/conftest.py').read_text())
print('\n'.join(f'tests/{m}.py' for n in t.body if isinstance(n, ast.Assign) and getattr(n.targets[0], 'id', '') == 'ALONE'
                 for m in ast.literal_eval(n.value)))")
for arg in ${args[@]+"${args[@]}"}; do
  case "$arg" in -*) ;; *) if [ -e "${arg%%::*}" ]; then paths1=(); paths2=(); paths3=(); fi;; esac
done
LOADAVG0=$(cut -d' ' -f1-3 /proc/loadavg)
t0=$(date +%s)
a=5; b=5; c=5
if want 1; then
  echo "[tests] $mode: tier $tier; phase 1/3: pure computation (-m 'cpu and $tier') on 2 workers"
  OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 python3 -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder -m "cpu and $tier" ${paths1[@]+"${paths1[@]}"} ${args[@]+"${args[@]}"}
  a=$?
fi
t1=$(date +%s)
case $a in 2|3|4) echo "[tests] phase 1 ended with exit $a (interrupted or an error): phase 2 not run" >&2; exit $a;; esac
if [ $a -eq 1 ]; then
  for arg in "${args[@]}"; do
    case "$arg" in -x|--exitfirst) echo "[tests] phase 1 failed and -x: phase 2 not run" >&2; exit 1;; esac
  done
fi
if want 2; then
  echo "[tests] phase 2/3: nodes and launched graphs (-m 'not cpu and not alone and $tier') on 2 workers, a domain each"
  FLEXSHEET_TEST_DOMAINS=1 python3 -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder --durations=15 \
    -m "not cpu and not alone and $tier" ${paths2[@]+"${paths2[@]}"} ${args[@]+"${args[@]}"}
  b=$?
fi
t2=$(date +%s)
case $b in 2|3|4) echo "[tests] phase 2 ended with exit $b (interrupted or an error): phase 3 not run" >&2; exit $b;; esac
if want 3; then
  echo "[tests] phase 3/3: live loops against the wall clock (-m 'not cpu and alone and $tier'), one by one"
  python3 -m pytest -q -m "not cpu and alone and $tier" ${paths3[@]+"${paths3[@]}"} ${args[@]+"${args[@]}"}
  c=$?
fi
t3=$(date +%s)
# 5 = no tests collected in that phase (e.g. a selection inside another phase's modules)
ran=0
for x in $a $b $c; do [ "$x" -ne 5 ] && ran=1; done
if [ $ran -eq 1 ]; then
  [ $a -eq 5 ] && a=0; [ $b -eq 5 ] && b=0; [ $c -eq 5 ] && c=0
fi
p1=$((t1 - t0)); p2=$((t2 - t1)); p3=$((t3 - t2)); tot=$((t3 - t0))
echo "[tests] $mode (tier '$tier', phases $phases): phase 1 exit $a in $p1 s, phase 2 exit $b in $p2 s, phase 3 exit $c in $p3 s, $tot s in all"
if [ -n "${SUITE_JSON:-}" ]; then
  mkdir -p "$(dirname "$SUITE_JSON")"
  printf '{"mode": "%s", "tier": "%s", "phase1_s": %d, "phase2_s": %d, "phase3_s": %d, "total_s": %d, "phase1_exit": %d, "phase2_exit": %d, "phase3_exit": %d, "args": "%s", "cores": %d, "loadavg_before": "%s", "date": "%s", "target_s": %s}\n' \
    "$mode" "$tier" "$p1" "$p2" "$p3" "$tot" "$a" "$b" "$c" "${args[*]:-}" "$(nproc)" "$LOADAVG0" "$(date -u +%FT%TZ)" \
    "$(case $mode in everyday) echo 480;; slow) echo 720;; *) echo null;; esac)" > "$SUITE_JSON"
fi
[ $a -ne 0 ] && exit $a
[ $b -ne 0 ] && exit $b
exit $c
