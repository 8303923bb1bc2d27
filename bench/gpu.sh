#!/usr/bin/env bash
# GPU figures in under 5 minutes on a lent GPU machine, set up from the repository alone:
#
#     bash bench/gpu.sh            # small / CPM / hourglass images/s at batch 1/8/32,
#                                  # training steps/s, Detector.predict of 8 cameras,
#                                  # DDP training steps/s at 1 and all GPUs
#     bash bench/gpu.sh --tiny     # a quick check of the script (CPU fallback here)
#
# Python: the repo's .venv when it has torch (a development machine); else a venv
# (.venv-gpu) over the machine's own Python when that has torch (the GPU machines ship a
# CUDA torch: requirements.txt pins the CPU wheel, which must not replace it), topped up
# from requirements.txt with what the bench imports and the machine lacks; else a fresh
# venv from requirements.txt. bench/gpu.py needs no ROS. Extra options go to bench/gpu.py.
set -euo pipefail
cd "$(dirname "$0")/.."
BUDGET_S=${MONET_GPU_BUDGET_S:-290}
has_torch() { "$1" -c 'import torch' >/dev/null 2>&1; }

if [ -x .venv/bin/python ] && has_torch .venv/bin/python; then
    PY=.venv/bin/python
elif has_torch python3; then
    PY=.venv-gpu/bin/python
    [ -x "$PY" ] || python3 -m venv --system-site-packages .venv-gpu
    missing=()
    for pair in numpy:numpy cv2:opencv-python-headless yaml:pyyaml scipy:scipy \
                onnxruntime:onnxruntime onnx:onnx; do
        "$PY" -c "import ${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        pins=()
        for name in "${missing[@]}"; do
            pins+=("$(grep -i "^${name}==" requirements.txt || echo "$name")")
        done
        echo "# installing ${pins[*]} (from requirements.txt)"
        "$PY" -m pip install -q --disable-pip-version-check --retries 0 --timeout 10 \
            "${pins[@]}" || echo "# could not install ${pins[*]}: those rows will say n/a"
    fi
else
    PY=.venv/bin/python
    python3 -m venv .venv
    "$PY" -m pip install -q --disable-pip-version-check -r requirements.txt
fi
"$PY" -c 'import torch; print("# python", __import__("sys").executable, "torch",
torch.__version__, "cuda" if torch.cuda.is_available() else "no cuda: CPU fallback")'
start=$SECONDS
timeout "$BUDGET_S" "$PY" bench/gpu.py "$@"
# DDP training steps/s at 1 process and at all GPUs (one rank each; CPU fallback: 1 and 2
# gloo processes), bench/train_scale.py, in what is left of the budget.
left=$(( BUDGET_S - (SECONDS - start) ))
scale=(--steps 20 --repeats 3)
for arg in "$@"; do [ "$arg" = --tiny ] && scale=(--steps 3 --repeats 1); done
if [ "$left" -gt 20 ]; then
    timeout "$left" "$PY" bench/train_scale.py "${scale[@]}" || \
        echo "# bench/train_scale.py did not finish in the ${left} s left of the budget"
else
    echo "# DDP scaling skipped: no budget left (MONET_GPU_BUDGET_S=$BUDGET_S)"
fi
