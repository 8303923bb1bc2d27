#!/usr/bin/env bash
# The full accuracy benchmark (bench/accuracy.py --full: ring8 + dome5, seeds 0 1 2, every
# mode and the null row, 46x46 heatmaps, 3000 steps) on one CUDA GPU, in one call.
#
#   bench/accuracy_gpu.sh [OUT] [extra bench/accuracy.py options]
#
# Environment: PYTHON (default .venv/bin/python; it needs a CUDA build of torch), JOBS
# (parallel training processes sharing the GPU, default 12: the CPU side, crop warps and
# optical-flow tracking, is the bottleneck of the small net), OUT (default
# /tmp/monet_accuracy_full). Target: under 8 minutes on one large GPU with 16 cores; not yet
# measured (no device was lent to the branch that wrote it): the wall time is printed last.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-.venv/bin/python}
OUT=${1:-${OUT:-/tmp/monet_accuracy_full}}
shift || true
JOBS=${JOBS:-12}
"$PYTHON" - <<'PY'
import sys
import torch
if not torch.cuda.is_available():
    sys.exit('bench/accuracy_gpu.sh: torch sees no CUDA device (torch ' + torch.__version__
             + '); set PYTHON to an environment with a CUDA build of torch')
print('CUDA:', torch.cuda.get_device_name(0), file=sys.stderr)
PY
exec "$PYTHON" bench/accuracy.py --full --device cuda --jobs "$JOBS" --out "$OUT" "$@"
