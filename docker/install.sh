#!/usr/bin/env bash
# Install everything flexsheet needs on a bare Debian 12 machine (as root) or in the Docker image.
# .ci/run and docker/Dockerfile both call this script, so CI and the image install the same things.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
if command -v apt-get >/dev/null 2>&1; then
  echo "[install] apt packages: headless EGL/Mesa (renderer), GLU/X libs (gmsh wheel), iproute2 (netns tests)," \
       "Xvfb (projector window test), Aravis + GObject introspection (GenICam cameras, fake GigE Vision camera)"
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends \
    libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 libgles2 \
    libglu1-mesa libxcursor1 libxft2 libxinerama1 libxrender1 libfontconfig1 \
    iproute2 procps \
    xvfb xauth aravis-tools aravis-tools-cli gir1.2-aravis-0.8 util-linux \
    libgirepository1.0-dev libcairo2-dev pkg-config gobject-introspection gcc libc6-dev >/dev/null
fi
echo "[install] python packages (pyproject.toml, with the test extra)"
python3 -m pip install -q --disable-pip-version-check -e ".[test]"
python3 -c "import flexsheet, messages, nodes; print('[install] flexsheet', flexsheet.__version__, 'ready')"
