#!/usr/bin/env bash
# What issue 15 still needs measured on a CUDA GPU, in a few device commands (device minutes are scarce; each
# command must finish within the device tool's 10 minutes). After
# EXTRA="isal==1.9.1 threadpoolctl==3.6.0" ../shared/gpu/prepare.sh (wheels that machine lacks: ISA-L for the
# writer, threadpoolctl for the galvo solver), from the device tool:
#   run(command="bash benchmarks/gpu_session.sh known", carry=[".gpu"])   the tests to check first, with tracebacks
#   run(command="bash benchmarks/gpu_session.sh bench", carry=[".gpu"])   engine, converter, writer, pixel, fan
#                                                                         1280x720, memory, motion
#   run(command="bash benchmarks/gpu_session.sh tests", carry=[".gpu"])   the suite under cuda_ad_mono
#   run(command="bash benchmarks/gpu_session.sh verify", carry=[".gpu"])  known tests, fan to HDF5, the main job
#                                                                         (`./run demo`) timed, memory, overlap,
#                                                                         the converter's profile and chunk shape
#   run(command="bash benchmarks/gpu_session.sh engine", carry=[".gpu"])  known tests, chunk shape, engine, fan to
#                                                                         HDF5, memory, pixel, writer, the demo's
#                                                                         and the fan's render profiles
#   run(command="bash benchmarks/gpu_session.sh pixel", carry=[".gpu"])   known tests, the pixel model's tests under
#                                                                         CUDA, its cost, fan to HDF5, the main job, engine
#   run(command="bash benchmarks/gpu_session.sh write", carry=[".gpu"])   known tests, fan to HDF5 (and one writer
#                                                                         setting changed at a time), writer,
#                                                                         memory, render profiles, pixel
# Everything lands in one tarball under $OUT (the device tool brings it back): logs, the benchmarks' results
# files (written there, not into benchmarks/results/), nvidia-smi. Copy the results files into
# benchmarks/results/ here and commit them: they carry the GPU's name.
# Measured on an H100 (2026-11-26): the machine's start about 30 s; the bench stage about 170 s; the known
# stage 25 s on a warm machine, 150 s on a fresh one (kernels compiled); the whole suite on 14 workers more
# than 340 s (821 tests had passed by then). The known stage, the bench stage, then the suite with what is
# left (TEST_LIMIT; KNOWN_LIMIT=1 skips the known tests there; SIGINT first, so pytest prints what ran) fit
# in one session's 15 minutes if each command follows the last while the machine is warm (30 s). Two calls
# save a machine start: "bash benchmarks/gpu_session.sh known; bash benchmarks/gpu_session.sh bench" (each
# stage packs its own tarball), then "KNOWN_LIMIT=1 TEST_LIMIT=330 TEST_WORKERS=14 bash ... tests".
# On an H200 (2026-11-26, ninth session): verify 100 s, verify + bench 332 s, each on a fresh machine (Dr.Jit's
# kernel cache on that machine's disk was kept between them: the known stage took 30 s each time).
# Eleventh session (H200): verify + bench in one command 379 s; engine 210 s, each on a fresh machine.
# Twelfth session (H200): engine 194 s, write 82 s (before fan_writer and the profiles joined it), then 141 s;
# bench_fan_writer alone 41 s; each on a fresh machine (start about 30 s more).
# Seventeenth session (H200): pixel 229 s on a fresh machine; then the whole suite on 14 workers to its end in
# 437 s on the warm machine (KNOWN_LIMIT=1 TEST_LIMIT=430 TEST_WORKERS=14, timeout_s 480).
# Twenty-second session (H200): pixel 268 s on a fresh machine (its event engine cut off at 150 s); the whole
# suite on 14 workers to its end in 340 s on another fresh machine (KNOWN_LIMIT=1 TEST_LIMIT=430, timeout_s 500).
# Twenty-third session (H200): pixel 264 s on a fresh machine (its event engine 165 s of it).
# A dry run on the CPU checks the script itself: PY=.venv/bin/python OUT=/tmp/gpu_dry bash benchmarks/gpu_session.sh bench --quick
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/gpu_session}
PY=${PY:-"bash .gpu/run.sh python"}
stage=${1:-bench}
quick=${2:-}
# the device tool brings back at most 8 files: everything is written under $W and packed into one tarball after
# every step, so a step cut off by its limit still leaves the ones before it
W=${W:-/tmp/gpu_work}
mkdir -p "$OUT" "$W"
pack() { tar czf "$OUT/gpu_$stage.tgz" -C "$W" . ; }
(nvidia-smi || echo "no nvidia-smi") > "$W/nvidia-smi.txt" 2>&1
$PY -c "import mitsuba_eventfield as ef; ef.set_variant(None); import mitsuba as mi; print('variant', mi.variant())" \
    2>&1 | tee "$W/variant.txt"
pack
step() {   # step NAME SECONDS COMMAND...: the command's output to $W/NAME.txt, then pack
    local name=$1 limit=$2; shift 2
    local t0=$SECONDS
    # SIGINT first: pytest then prints its summary of what ran (the failures' causes) before it stops
    EVENTFIELD_RESULTS_DIR="$W" timeout -s INT -k 30 "$limit" "$@" > "$W/$name.txt" 2>&1
    echo "[$name] exit $? after $((SECONDS - t0)) s" | tee -a "$W/steps.txt"
    pack
}

known_failures() {   # what failed under CUDA on the H100 (2026-11-26: benchmarks/results/gpu_h100.md) or changed
    # for CUDA since without being run there: the event-batch file (rounded(), frozen chunk passes), the
    # DLPack columns, the overlapped loop, moving shapes as instances (CUDA's default: the instancing file and
    # the static-pixel split), the scan tolerance, the freeze refusal (the README examples test needs more
    # than 120 s on a fresh machine: it runs in the suite)
    step tests_known "${KNOWN_LIMIT:-150}" env EVENTFIELD_TEST_VARIANT=cuda_ad_mono $PY -m pytest -v \
        --tb=long -rfEs -p no:cacheprovider -n 4 --timeout 120 \
        "tests/plugins/test_event_batch.py" \
        "tests/simulate/test_device_stream.py" \
        "tests/simulate/test_determinism.py::test_overlapped_steps_give_the_same_events" \
        "tests/scene/test_instancing.py" "tests/simulate/test_static_pixels.py" \
        "tests/optics/test_scan.py::test_numpy_and_drjit_agree" \
        "tests/simulate/test_frozen_render.py::test_frozen_steps_give_the_same_events" \
        "tests/simulate/test_sink.py" "tests/events/test_writer.py" \
        "tests/plugins/test_event_fill.py::test_stable_order_is_numpy_stable_argsort"
}

fan_to_hdf5() {   # issue 15's own row through the CLI: the fan at 1280x720, 400 steps, to HDF5 (render / events /
    # motion / write split, and whether the writer or the render was the bottleneck); with an argument N, the
    # writer deflating on N threads (EVENTFIELD_WRITER_THREADS), in fan_render_wN.txt
    local sizes="-D width=1280 -D height=720" steps=400 name=fan_render threads=()
    if [ -n "$quick" ]; then sizes="-D width=96 -D height=72"; steps=80; fi
    if [ -n "${1:-}" ]; then name="fan_render_w$1"; threads=(env "EVENTFIELD_WRITER_THREADS=$1"); fi
    step "$name" 90 "${threads[@]}" $PY -m mitsuba_eventfield.cli render scenes/fan/fan.xml -o /tmp/fan_gpu.h5 \
        $sizes --duration 0.02 --steps $steps
    rm -f /tmp/fan_gpu.h5
}

main_demo() {   # the README's main job (`./run demo`: the off-axis cards, one galvo period, refocus, depth) timed
    # end to end, twice (the first compiles; issue 16 asks for the demo's speed on a named GPU)
    local sizes=""
    if [ -n "$quick" ]; then sizes="--width 48 --height 36 --views 8"; fi
    for k in 1 2; do
        step "main_demo_$k" 120 bash -c "TIMEFORMAT='real %R s'; time $PY -m mitsuba_eventfield.cli demo -o /tmp/main_demo $sizes"
    done
    rm -rf /tmp/main_demo
}

fan_profile() {   # the render thread's host time by function, the fan at 1280x720 to HDF5 (three renders)
    local sizes="-D width=1280 -D height=720" steps=400
    if [ -n "$quick" ]; then sizes="-D width=96 -D height=72"; steps=80; fi
    step render_profile_fan 120 $PY benchmarks/profile_render.py scenes/fan/fan.xml --steps $steps \
        --duration 0.02 --output /tmp/fan_profile.h5 $sizes
}

case "$stage" in
    known)
        # those failures alone, with their tracebacks (-v --tb=long)
        known_failures
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_known.txt" | tail -n 40 ;;
    tests)
        # the default LLVM suite under cuda_ad_mono, spread over the machine's cores (each worker its own CUDA
        # context; Dr.Jit's kernel cache on disk is shared); the regression references were made on LLVM and are
        # compared with the other-backend tolerances there (evaluation/regression.py); extras the image lacks
        # are skipped with their reason
        n=${TEST_WORKERS:-8}
        # first the tests that failed under CUDA, with their tracebacks, so that their causes come back even if
        # the whole suite runs out of time
        known_failures
        # (-v: each test's outcome as it ends; a run cut short still names what failed; TESTS picks a subset)
        step tests_cuda "${TEST_LIMIT:-450}" env EVENTFIELD_TEST_VARIANT=cuda_ad_mono $PY -m pytest -v \
            --tb=short -rfEs -p no:cacheprovider -n "$n" --timeout 420 ${TESTS:-tests}
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_cuda.txt" | tail -n 60 ;;
    bench)
        # engine + converter (device, per step, host) and issue 15's render rows (demo 0.1 s; fan 1280x720,
        # 400 steps) with their cost beyond the radiance render
        step event_engine 240 $PY benchmarks/bench_event_engine.py $quick
        fan_to_hdf5
        # the realistic pixel (every effect, batched) against the ideal one
        step pixel 90 $PY benchmarks/bench_pixel.py
        # host and GPU memory for 10x the duration (fan 346x260, every pixel, to HDF5)
        [ -z "$quick" ] && step memory 120 $PY benchmarks/bench_memory.py --every-pixel-only
        # HDF5 writing on the host's cores against HDF5's own filters on one thread
        [ -z "$quick" ] && step writer 150 $PY benchmarks/bench_writer.py
        # motion a step: Mitsuba's update against ours, meshes against instances, the loop's sync after a render
        step motion 150 $PY benchmarks/bench_motion.py $quick
        # the loop's overlap of host and device, overlapped against synced in alternating pairs
        step overlap 150 $PY benchmarks/bench_overlap.py $quick
        cat "$W/steps.txt"; tail -n 30 "$W/event_engine.txt" "$W/fan_render.txt" "$W/motion.txt" "$W/overlap.txt" ;;
    engine)
        # after a change to the event engine's chunking or sort (210 s on a fresh H200, before the render
        # profile was added; the step limits add up to more than a command may take): the known tests, the
        # chunk shape, the engine and its renders, the fan to HDF5, memory against the duration, the pixel, the
        # writer (with its serial floor), the demo's render profile
        known_failures
        step chunk_shape 150 $PY benchmarks/bench_chunk_shape.py $quick
        step event_engine 240 $PY benchmarks/bench_event_engine.py $quick
        fan_to_hdf5
        # the same with the writer on fewer threads (with a task a column, 16 deflated slower than 2 on the
        # H200's host; with a task a chunk, 4, 8 and 16 agree: results/gpu_h200.md)
        for n in ${FAN_WRITER_THREADS:-4 8}; do fan_to_hdf5 "$n"; done
        [ -z "$quick" ] && step memory 120 $PY benchmarks/bench_memory.py --every-pixel-only
        step pixel 90 $PY benchmarks/bench_pixel.py
        [ -z "$quick" ] && step writer 150 $PY benchmarks/bench_writer.py
        # the demo's host time by function (its wall is well above its renders alone: where does it go?)
        step render_profile 60 $PY benchmarks/profile_render.py
        fan_profile
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_known.txt" | tail -n 20
        cat "$W/steps.txt"; head -n 40 "$W/chunk_shape.txt"; tail -n 25 "$W/event_engine.txt"
        for f in "$W"/fan_render*.txt; do echo "== $f"; grep -E "^[0-9]+ steps|^file writer" "$f"; done
        tail -n 8 "$W/memory.txt" "$W/pixel.txt"; grep -E "^\| [0-9]|floor" "$W/writer.txt" ;;
    write)
        # after a change to the event files' writer or the sink (about 120 s on a fresh H200): the known tests,
        # the fan to HDF5 through the CLI, the same with one writer setting changed at a time (queue depth, GIL
        # switch interval, deflating threads), the writer's own rows, memory against the duration, the render
        # thread's profile of the fan to HDF5, and the demo's render profile with the ideal and a realistic pixel
        # (where the realistic pixel's host time goes: the pixel-cost target), and that cost
        known_failures
        fan_to_hdf5
        main_demo
        step fan_writer 150 $PY benchmarks/bench_fan_writer.py $( [ -n "$quick" ] && echo "--width 96 --height 72 --steps 80" )
        step writer 150 $PY benchmarks/bench_writer.py
        [ -z "$quick" ] && step memory 120 $PY benchmarks/bench_memory.py --every-pixel-only
        fan_profile
        step render_profile 60 $PY benchmarks/profile_render.py
        step render_profile_davis346 60 $PY benchmarks/profile_render.py --preset davis346
        step pixel 90 $PY benchmarks/bench_pixel.py
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_known.txt" | tail -n 20
        cat "$W/steps.txt"; grep -E "^real" "$W"/main_demo_*.txt
        for f in "$W"/fan_render*.txt; do echo "== $f"; grep -E "^[0-9]+ steps|^file writer" "$f"; done
        grep -E "^\| " "$W/fan_writer.md"; grep -E "^\| [0-9]|floor" "$W/writer.txt"; tail -n 8 "$W/memory.txt"
        tail -n 12 "$W/pixel.txt" ;;
    pixel)
        # after a change to the realistic pixel's kernels (counter-based draws, the hazard clock, one count lane
        # a pixel): the known tests, the pixel model's own tests under cuda_ad_mono, its cost against the ideal,
        # the fan to HDF5, the main job timed, the event engine and converter rows (about 230 s on a fresh H200;
        # the step limits add up to more than a command may take: what ran comes back if time runs out)
        KNOWN_LIMIT=${KNOWN_LIMIT:-90} known_failures
        step tests_pixel "${PIXEL_LIMIT:-150}" env EVENTFIELD_TEST_VARIANT=cuda_ad_mono $PY -m pytest -v \
            --tb=short -rfEs -p no:cacheprovider -n "${TEST_WORKERS:-8}" --timeout 120 \
            tests/plugins/test_counter_rng.py tests/plugins/test_pixel_model.py \
            tests/plugins/test_pixel_realism.py tests/plugins/test_pixel_jitter.py tests/plugins/test_readout.py \
            tests/plugins/test_event_fill.py tests/simulate/test_determinism.py tests/simulate/test_convert.py \
            tests/simulate/test_checkpoint.py
        step pixel 90 $PY benchmarks/bench_pixel.py
        # what the events add to the fan's render at 1280x720, kernels against host (33 s on a fresh H200)
        step render_kernels 90 $PY benchmarks/profile_render_kernels.py $quick
        fan_to_hdf5
        main_demo
        # (240 s: on a slower host, 2026-11-27, its fan rows' host path alone ran it past 150 s)
        step event_engine 240 $PY benchmarks/bench_event_engine.py $quick
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_known.txt" "$W/tests_pixel.txt" | tail -n 40
        cat "$W/steps.txt"; grep -E "^real" "$W"/main_demo_*.txt
        grep -E "^[0-9]+ steps|^file writer" "$W/fan_render.txt"; tail -n 14 "$W/pixel.txt"
        grep -E "^\| (renders|events)|^With the history" "$W/render_kernels.md"; tail -n 20 "$W/event_engine.txt" ;;
    verify)
        # after a change made without a GPU: the known tests, the fan to HDF5 (the write's time), host and GPU
        # memory against the duration, the overlap's A/B, the converter's profile; 100 s on an H200
        known_failures
        fan_to_hdf5
        main_demo
        [ -z "$quick" ] && step memory 120 $PY benchmarks/bench_memory.py --every-pixel-only
        step overlap 150 $PY benchmarks/bench_overlap.py $quick
        # the converter kernel by kernel (what bounds its pixel-steps a second), then its chunk shape: frames a
        # kernel against the sort's pass width (fewer syncs against a longer key; CPU: results/chunk_shape.md)
        step profile 90 $PY benchmarks/profile_converter.py $quick
        step chunk_shape 150 $PY benchmarks/bench_chunk_shape.py $quick
        grep -E " (FAILED|ERROR) |passed|failed" "$W/tests_known.txt" | tail -n 20
        cat "$W/steps.txt"; grep -E "^real" "$W"/main_demo_*.txt; grep -v "rendering:" "$W/fan_render.txt" | tail -n 12; tail -n 8 "$W/memory.txt" "$W/overlap.txt"; head -n 30 "$W/profile.txt"; head -n 40 "$W/chunk_shape.txt" ;;
    *) echo "usage: gpu_session.sh tests|known|bench|verify|engine|write|pixel [--quick]" >&2; exit 2 ;;
esac
