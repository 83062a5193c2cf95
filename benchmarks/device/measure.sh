#!/usr/bin/env bash
# There, after install.sh on the same warm machine: issue 29's GPU figures, logged into $OUT.
#   measure.sh xfeat    (carry .device/weights-xfeat)  XFeat + LighterGlue: town10's map built
#                       on the GPU, the time per 800x600 query by stage, recall at k = 0
#   measure.sh aliked   (carry .device/weights-aliked) the same for ALIKED + LightGlue
#   measure.sh workers  episodes per hour on 1, 2, 4, 8 and 16 workers (SIFT; each worker count
#                       gets about the same episodes per worker, so the runs take about as long)
set -euo pipefail
what=${1:?xfeat, aliked or workers}
export PYTHONPATH=$PWD/src:$PWD/.device/weights-$what MUJOCO_GL=egl PYTHONUNBUFFERED=1
log=${OUT:-/tmp}/$what.log
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader | tee "$log"
case $what in
  xfeat | aliked)
    method=$([ "$what" = xfeat ] && echo xfeat-lighterglue || echo aliked-lightglue)
    python3 benchmarks/bench_loc.py --town town10 --methods "$method" --k 0 --every 4 \
      --speed-queries 40 --out /tmp/vlocbench/bench_loc 2>&1 | tee -a "$log"
    ;;
  workers)
    python3 benchmarks/bench_runner.py --workers 1,2,4,8,16 --repeats 1 --reps-per-worker 1 \
      --out /tmp/vlocbench/bench_runner 2>&1 | tee -a "$log"
    ;;
  *) echo "unknown: $what (xfeat, aliked, workers)" >&2 && exit 2 ;;
esac
