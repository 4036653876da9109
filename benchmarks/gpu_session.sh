#!/usr/bin/env bash
# What issue 15 still needs measured on a CUDA GPU, in two device commands (device minutes are scarce; each
# command must finish within the device tool's 10 minutes). After ../shared/gpu/prepare.sh, from the device tool:
#   run(command="bash benchmarks/gpu_session.sh tests", carry=[".gpu"])   the suite under cuda_ad_mono
#   run(command="bash benchmarks/gpu_session.sh bench", carry=[".gpu"])   engine, converter, writer, pixel, fan 1280x720
# Everything lands under $OUT (the device tool brings it back): logs, the benchmarks' results files (written
# there, not into benchmarks/results/), nvidia-smi. Copy the results files into benchmarks/results/ here and
# commit them: they carry the GPU's name.
# A dry run on the CPU checks the script itself: PY=.venv/bin/python OUT=/tmp/gpu_dry bash benchmarks/gpu_session.sh bench --quick
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/gpu_session}
PY=${PY:-"bash .gpu/run.sh python"}
stage=${1:-bench}
quick=${2:-}
mkdir -p "$OUT"
(nvidia-smi || echo "no nvidia-smi") > "$OUT/nvidia-smi.txt" 2>&1
$PY -c "import mitsuba_eventfield as ef; ef.set_variant(None); import mitsuba as mi; print('variant', mi.variant())" \
    2>&1 | tee "$OUT/variant.txt"

case "$stage" in
    tests)
        # the default LLVM suite on CUDA; the regression references were made on LLVM and are compared with the
        # other-backend tolerances there (evaluation/regression.py); extras the image lacks are skipped
        EVENTFIELD_TEST_VARIANT=cuda_ad_mono timeout 560 $PY -m pytest -q -p no:cacheprovider tests \
            > "$OUT/tests_cuda.txt" 2>&1
        echo "pytest exit $?" >> "$OUT/tests_cuda.txt"
        tail -n 40 "$OUT/tests_cuda.txt" ;;
    bench)
        # engine + converter (device, per step, host) and the renders' cost beyond the radiance render
        EVENTFIELD_RESULTS_DIR="$OUT" timeout 300 $PY benchmarks/bench_event_engine.py $quick \
            > "$OUT/event_engine.txt" 2>&1
        # HDF5 writing with the chunks deflated on the host's cores (idle while the GPU renders) against HDF5's
        # own filters on one thread
        [ -z "$quick" ] && EVENTFIELD_RESULTS_DIR="$OUT" timeout 120 $PY benchmarks/bench_writer.py \
            > "$OUT/writer.txt" 2>&1
        # the realistic pixel (every effect, batched) against the ideal one, and a step at a time
        [ -z "$quick" ] && EVENTFIELD_RESULTS_DIR="$OUT" timeout 150 $PY benchmarks/bench_pixel.py \
            > "$OUT/pixel.txt" 2>&1
        # issue 15's own row: the fan at 1280x720, 400 steps, to HDF5 (render / events / motion / write split)
        sizes="-D width=1280 -D height=720"; steps=400
        if [ -n "$quick" ]; then sizes="-D width=96 -D height=72"; steps=80; fi
        timeout 200 $PY -m mitsuba_eventfield.cli render scenes/fan/fan.xml -o /tmp/fan_gpu.h5 $sizes \
            --duration 0.02 --steps $steps --quiet > "$OUT/fan_render.txt" 2>&1
        rm -f /tmp/fan_gpu.h5
        tail -n 25 "$OUT/event_engine.txt" "$OUT/fan_render.txt" ;;
    *) echo "usage: gpu_session.sh tests|bench [--quick]" >&2; exit 2 ;;
esac
