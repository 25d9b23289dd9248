#!/usr/bin/env bash
# Install everything flexsheet needs on a bare Debian 12 machine (as root) or in the Docker image.
# .ci/run and docker/Dockerfile both call this script, so CI and the image install the same things.
#
# Order (to overlap the two slow halves): apt's build dependencies of the Python packages first (PyGObject,
# pycairo and scikit-sparse have no wheels: pip compiles them, ~30 s + ~18 s), then pip in the background (downloads, compiles, installs:
# ~1 min with an empty pip cache, measured on the 2-core machine) while apt installs the runtime libraries
# (Mesa, X, Xvfb, Aravis with its GTK viewer, iproute2), which pip does not need to install the wheels.
set -euo pipefail
# any failing step ends the install with a non-zero exit and this line naming it
trap 'rc=$?; echo "[install] FAILED (exit $rc) at docker/install.sh line $LINENO: $BASH_COMMAND" >&2; exit $rc' ERR
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
APT_INSTALL=(apt-get install -y -qq --no-install-recommends)
pip_log=$(mktemp)
if command -v apt-get >/dev/null 2>&1; then
  echo "[install] apt packages to build PyGObject, pycairo and scikit-sparse: gcc, pkg-config, GObject" \
       "introspection, cairo and SuiteSparse (CHOLMOD) headers; OpenBLAS as the system BLAS (CHOLMOD's" \
       "supernodal factorisation: 10.2 s -> 2.7 s on a 31 200-DOF FEM tangent against the reference BLAS)"
  apt-get update -qq
  "${APT_INSTALL[@]}" libgirepository1.0-dev libcairo2-dev pkg-config gobject-introspection gcc libc6-dev \
    libsuitesparse-dev libopenblas0-pthread >/dev/null
fi
echo "[install] python packages (pyproject.toml, with the test extra), in the background"
python3 -m pip install -q --disable-pip-version-check -e ".[test]" >"$pip_log" 2>&1 &
pip_pid=$!
if command -v apt-get >/dev/null 2>&1; then
  echo "[install] apt packages: headless EGL/Mesa (renderer), GLU/X libs (gmsh wheel), iproute2 (netns tests)," \
       "Xvfb (projector window test), Aravis + GObject introspection (GenICam cameras, fake GigE Vision camera)"
  "${APT_INSTALL[@]}" \
    libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 libgles2 \
    libglu1-mesa libxcursor1 libxft2 libxinerama1 libxrender1 libfontconfig1 \
    iproute2 procps \
    xvfb xauth aravis-tools aravis-tools-cli gir1.2-aravis-0.8 util-linux >/dev/null
fi
if ! command -v npm >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
  echo "[install] apt packages: Node.js and npm (the viewers' own readers in the tests)"
  "${APT_INSTALL[@]}" nodejs npm >/dev/null
fi
echo "[install] npm packages of the viewer checks (tests/js: the official Foxglove WebSocket client, MCAP reader)"
(cd tests/js && npm ci --no-audit --no-fund --loglevel=error)
if ! wait "$pip_pid"; then
  cat "$pip_log" >&2
  echo "[install] pip install failed (output above)" >&2
  exit 1
fi
cat "$pip_log"
rm -f "$pip_log"
python3 -c "import flexsheet, messages, nodes; print('[install] flexsheet', flexsheet.__version__, 'ready')"
# the FEM node's models for the shipped launch files and scenes, precomputed once here (not at every start on a
# fresh HOME: ~12 s for the cylinder); searched read-only by every FEM cache (flexsheet/fem/cache.py)
echo "[install] precomputing the FEM node's models (python3 -m nodes.fem.warm; exits 1 if any model failed)"
python3 -m nodes.fem.warm
echo "[install] done"
