#!/usr/bin/env bash
# Install everything flexsheet needs on a bare Debian 12 / Ubuntu 24.04 machine (as root), into a virtual
# environment: the system Python of both is "externally managed" (PEP 668) and refuses pip.
# .ci/run calls this script, so CI installs the same things; docker/Dockerfile builds its image the same way.
#
#   bash docker/install.sh                 # the checkout's .venv, flexsheet linked into /usr/local/bin
#   FLEXSHEET_VENV=/opt/fs bash docker/install.sh      # another venv folder
#   PYTHON=python3.12 bash docker/install.sh           # another interpreter (>= 3.11) for the venv
#   FLEXSHEET_INSTALL=runtime bash docker/install.sh   # `pip install .` (not editable), no test extra, no npm
#
# Order (to overlap the two slow halves): apt's build dependencies first (PyGObject, pycairo and scikit-sparse have
# no wheels: pip compiles them against the Python headers, ~30 s + ~18 s; python3-venv and python3-dev where
# missing), then pip in the background (~1 min with an empty pip cache on the 2-core machine) while apt installs
# the runtime libraries (Mesa, X, Xvfb, Aravis with its GTK viewer, iproute2), which pip does not need.
set -euo pipefail
# any failing step ends the install with a non-zero exit and this line naming it (rc: the trap's own)
# shellcheck disable=SC2154
trap 'rc=$?; echo "[install] FAILED (exit $rc) at docker/install.sh line $LINENO: $BASH_COMMAND" >&2; exit $rc' ERR
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
APT_INSTALL=(apt-get install -y -qq --no-install-recommends)
PYTHON=${PYTHON:-python3}
VENV=${FLEXSHEET_VENV:-$PWD/.venv}
MODE=${FLEXSHEET_INSTALL:-dev}
case "$MODE" in dev|runtime) ;; *) echo "[install] FLEXSHEET_INSTALL must be dev or runtime, got '$MODE'" >&2; exit 2;; esac
pip_log=$(mktemp)
have_apt() { command -v apt-get >/dev/null 2>&1; }
if ! command -v "$PYTHON" >/dev/null 2>&1; then
  have_apt || { echo "[install] no $PYTHON and no apt-get: install Python >= 3.11 first" >&2; exit 1; }
  apt-get update -qq && "${APT_INSTALL[@]}" python3 >/dev/null
fi
"$PYTHON" - <<'EOF' || { echo "[install] flexsheet needs Python >= 3.11 (PYTHON=$PYTHON)" >&2; exit 1; }
import sys
sys.exit(sys.version_info < (3, 11))
EOF
# what the interpreter lacks: the venv module (with ensurepip) and the headers the three source packages need
py_lacks() {
  "$PYTHON" - <<'EOF'
import importlib.util, os, sysconfig
lacks = []
if importlib.util.find_spec("venv") is None or importlib.util.find_spec("ensurepip") is None:
    lacks.append("venv")
if not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")):
    lacks.append("dev")
print(" ".join(lacks))
EOF
}
lacks=$(py_lacks)
if have_apt; then
  build=(pkg-config gcc libc6-dev libsuitesparse-dev libopenblas0-pthread libgirepository1.0-dev libcairo2-dev
         gobject-introspection)
  pyver=$("$PYTHON" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
  # Debian's packages serve Debian's own python3 only; another interpreter must bring its venv and headers
  [[ " $lacks " == *" venv "* ]] && build+=(python3-venv "python$pyver-venv")
  [[ " $lacks " == *" dev "* ]] && build+=(python3-dev "python$pyver-dev")
  echo "[install] apt packages to build PyGObject, pycairo and scikit-sparse: gcc, pkg-config, GObject" \
       "introspection, cairo and SuiteSparse (CHOLMOD) headers; OpenBLAS as the system BLAS (CHOLMOD's" \
       "supernodal factorisation: 10.2 s -> 2.7 s on a 31 200-DOF FEM tangent against the reference BLAS)" \
       "${lacks:+; the venv module and Python headers ($lacks missing)}"
  apt-get update -qq
  "${APT_INSTALL[@]}" "${build[@]}" >/dev/null
fi
lacks=$(py_lacks)
if [ -n "$lacks" ]; then
  echo "[install] $PYTHON ($("$PYTHON" -c 'import sys; print(sys.executable)')) still lacks: $lacks" \
       "(venv: the venv module and ensurepip; dev: Python.h). Install them, or set PYTHON to one that has them." >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import sys; sys.exit(sys.prefix == sys.base_prefix)'; then
  echo "[install] virtual environment $VENV (from $("$PYTHON" -c 'import sys; print(sys.executable)'))"
  "$PYTHON" -m venv --clear "$VENV"
fi
VPY="$VENV/bin/python"
if [ "$MODE" = dev ]; then
  echo "[install] python packages into $VENV (pyproject.toml, editable, with the test extra), in the background"
  "$VPY" -m pip install -q --disable-pip-version-check -e ".[test]" >"$pip_log" 2>&1 &
else
  echo "[install] python packages into $VENV (pyproject.toml, not editable), in the background"
  "$VPY" -m pip install -q --disable-pip-version-check --no-cache-dir . >"$pip_log" 2>&1 &
fi
pip_pid=$!
if have_apt; then
  echo "[install] apt packages: headless EGL/Mesa (renderer), GLU/X libs (gmsh wheel), iproute2 (netns tests)," \
       "Xvfb (projector window test), Aravis + GObject introspection (GenICam cameras, fake GigE Vision camera)"
  "${APT_INSTALL[@]}" \
    libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 libgles2 \
    libglu1-mesa libxcursor1 libxft2 libxinerama1 libxrender1 libfontconfig1 \
    iproute2 procps \
    xvfb xauth aravis-tools aravis-tools-cli gir1.2-aravis-0.8 util-linux >/dev/null
fi
if [ "$MODE" = dev ]; then
  if ! command -v npm >/dev/null 2>&1 && have_apt; then
    echo "[install] apt packages: Node.js and npm (the viewers' own readers in the tests)"
    "${APT_INSTALL[@]}" nodejs npm >/dev/null
  fi
  echo "[install] npm packages of the viewer checks (tests/js: the official Foxglove WebSocket client, MCAP reader)"
  (cd tests/js && npm ci --no-audit --no-fund --loglevel=error)
fi
if ! wait "$pip_pid"; then
  cat "$pip_log" >&2
  echo "[install] pip install failed (output above)" >&2
  exit 1
fi
grep -v "is ignored: it is neither a file nor a directory" "$pip_log" || true
rm -f "$pip_log"
"$VPY" -c "import flexsheet, messages, nodes; print('[install] flexsheet', flexsheet.__version__, 'ready in $VENV')"
# on PATH with no activation: links in /usr/local/bin (root), else ~/.local/bin
bindir=/usr/local/bin
[ -w "$bindir" ] || { bindir="$HOME/.local/bin"; mkdir -p "$bindir"; }
for exe in flexsheet register-python-argcomplete; do
  ln -sfn "$VENV/bin/$exe" "$bindir/$exe"
done
echo "[install] $bindir/flexsheet -> $VENV/bin/flexsheet"
case ":$PATH:" in *":$bindir:"*) ;; *) echo "[install] note: $bindir is not on PATH here; add it" >&2;; esac
# the link serves every user only if they can read the venv and (editable) the checkout: not so under a home
# folder such as /root (mode 700); tried as the user nobody
if [ "$(id -u)" -eq 0 ] && command -v setpriv >/dev/null 2>&1 \
   && ! (cd / && setpriv --reuid=65534 --regid=65534 --clear-groups env HOME=/ "$VPY" -c 'import flexsheet') \
        >/dev/null 2>&1; then
  echo "[install] note: only root can run $bindir/flexsheet: $VENV or $PWD is not readable to other users" \
       "(e.g. under /root). For every user, put the checkout in a readable folder such as /opt/flexsheet" \
       "(docs/install.md)" >&2
fi
found=$(command -v flexsheet || true)
if [ -n "$found" ] && [ "$(readlink -f "$found")" != "$(readlink -f "$VENV/bin/flexsheet")" ]; then
  echo "[install] note: 'flexsheet' on this PATH is $found (another install), before $bindir/flexsheet" >&2
fi
# the FEM node's models for the shipped launch files and scenes, precomputed once here (not at every start on a
# fresh HOME: ~12 s for the cylinder), into the machine's data folder (the user's when not root); searched
# read-only by every FEM cache (flexsheet/fem/cache.py, flexsheet/dirs.py)
echo "[install] precomputing the FEM node's models (python -m nodes.fem.warm; exits 1 if any model failed)"
"$VPY" -m nodes.fem.warm
echo "[install] done"
