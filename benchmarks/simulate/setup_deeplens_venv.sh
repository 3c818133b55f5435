#!/usr/bin/env bash
# Throwaway venv for the DeepLens peer (never a project dependency). deeplens-core 2.5.6 declares
# Python >=3.12 and torch/torchvision/lpips/opencv; the rendering code runs on 3.11 with the machine's CPU
# torch 2.13.0, so it is installed with --no-deps --ignore-requires-python plus the light dependencies it
# imports. torchvision and lpips (only used there for image saving and the LPIPS metric) are stubbed by
# benchmarks/simulate/peer_deeplens.py, because no CPU torchvision build is available here.
set -euo pipefail
VENV=${1:-/tmp/dl-venv}
python3.11 -m venv "$VENV"
"$VENV/bin/pip" install -q torch==2.13.0
"$VENV/bin/pip" download -q --no-deps --python-version 3.12 --only-binary=:all: deeplens-core==2.5.6 -d "$VENV/wheels"
"$VENV/bin/pip" install -q --no-deps --ignore-requires-python "$VENV"/wheels/deeplens_core-2.5.6-py3-none-any.whl
"$VENV/bin/pip" install -q numpy opencv-python-headless tqdm matplotlib einops pillow scikit-image
echo "DeepLens peer venv ready: $VENV"
