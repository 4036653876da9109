#!/usr/bin/env bash
# v2e's own virtualenv for benchmarks/bench_v2e.py: v2e is not on PyPI and is no dependency of ours.
#   bash benchmarks/setup_v2e.sh V2E_SOURCE [VENV]      (VENV default: /work/v2e-venv, where bench_v2e looks)
# V2E_SOURCE: a checkout of github.com/SensorsINI/v2e (1.5.1 was measured) with its dataset_scripts/ folder
# (its setup.py installs scripts from there). Torch: a CPU build (2.13.0 was measured; on a machine whose pip
# does not have it locally, add --index-url https://download.pytorch.org/whl/cpu, or plain PyPI pulls a CUDA
# build of several GB). The other packages are what v2ecore.emulator imports.
set -euo pipefail
src=${1:?usage: setup_v2e.sh V2E_SOURCE [VENV]}
venv=${2:-/work/v2e-venv}
python3 -m venv "$venv"
"$venv/bin/pip" install -q --upgrade pip
"$venv/bin/pip" install -q torch==2.13.0
"$venv/bin/pip" install -q numpy opencv-python-headless h5py engineering-notation tqdm scikit-image matplotlib \
    argcomplete easygui screeninfo numba dv-processing
"$venv/bin/pip" install -q --no-deps "$src"
"$venv/bin/python" -c "import importlib.metadata as m, v2ecore.emulator, torch; print('v2e', m.version('v2e'), 'torch', torch.__version__)"
