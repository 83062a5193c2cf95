#!/usr/bin/env bash
# There, the first call to a fresh GPU machine (carry: .gl and .device/wheels, from prepare.sh):
# installs what vlocbench needs beyond the machine's image into its python3, then checks that
# torch sees the GPU and that MuJoCo renders an 800x600 frame through EGL. What it installs
# lasts while the machine stays warm (30 s after a call): make the next call at once.
set -euo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
python3 -m pip install --quiet --no-deps --no-index .device/wheels/*.whl
export PYTHONPATH=$PWD/src MUJOCO_GL=egl
python3 - <<'PY'
import time

import torch

from vlocbench.sim import Simulator, gallery_camera
from vlocbench.sim.town import generate_town, load_town_spec

print("torch", torch.__version__, "sees", torch.cuda.get_device_name(0))
sim = Simulator(generate_town(load_town_spec("town10")))
cam = gallery_camera()
sim.render([cam])
t = time.perf_counter()
for _ in range(20):
    image = sim.render([cam])[0].image
print(f"render {image.shape}: {1000 * (time.perf_counter() - t) / 20:.1f} ms a frame")
PY
# what this machine computes (bench.platform: its GL driver's pixels, its CPU's kernels, torch on
# the GPU), to set beside the CPU machines' records with `vlocbench platform --json` here
python3 -m vlocbench.cli platform --json > "${OUT:-/tmp}/platform.json" \
  || echo "no platform record: vlocbench platform failed (above)"
