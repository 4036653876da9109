import importlib.util
import os
import sys

import pytest

import mitsuba_eventfield as ef

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(ROOT, "scenes", "demo", "demo.xml")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


# The variant the suite runs under: LLVM by default (CI has no GPU); EVENTFIELD_TEST_VARIANT=cuda_ad_mono runs
# it on a GPU. The regression references were made on LLVM: on another backend their events are compared with
# the wider tolerances of evaluation/regression.py, measured against last-bit shifts of the scan (tested). Run
# under CUDA on an H100 and an H200 (benchmarks/results/gpu_h100.md, gpu_h200.md: the tests that failed there
# pass since); optional extras missing there are skipped (``needs``).
TEST_VARIANT = os.environ.get("EVENTFIELD_TEST_VARIANT", "llvm_ad_mono")


def needs(module: str, extra: str):
    """Import an optional dependency (one of setup.cfg's extras) that a test needs. Where it is absent the test
    is skipped with the reason (a GPU image without the extras, a user's own environment), except under CI
    (CI set), whose set-up installs the test extra: there a missing one is a broken set-up, and fails."""
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError as e:
        if os.environ.get("CI"):
            pytest.fail(f"{module} is missing under CI, whose set-up installs the test extra: {e}")
        pytest.skip(f"{module} is not installed (optional: pip install '.[{extra}]')")


def pytest_configure(config):
    config.addinivalue_line("markers", "needs(module, extra): the test needs an optional dependency; skipped "
                            "with the reason where it is absent (failed under CI): see needs()")
    # a shell's background job (`./run tests &`, `bash -c '...' &`) starts with Ctrl-C ignored, and Python then
    # keeps it ignored, in this process and in every process it starts: the tests of what a Ctrl-C does saw
    # nothing happen (a second Ctrl-C during a galvo's ramp-down, a sweep's cancelled queue)
    import signal
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_runtest_setup(item):
    for mark in item.iter_markers("needs"):
        needs(*mark.args)


# AEDAT4 files are written and read through faery, a dependency (dv-processing, the aedat4 extra, reads them where
# faery is absent), which the GPU image lacks (its bundle carries Mitsuba, Dr.Jit, OpenEXR, trimesh): skipped there
AEDAT4 = pytest.param(".aedat4", marks=pytest.mark.skipif(importlib.util.find_spec("faery") is None,
                                                          reason="faery is not installed (the GPU image lacks it)"))


@pytest.fixture(scope="session", autouse=True)
def mono_variant():
    ef.set_variant(TEST_VARIANT)


@pytest.fixture
def demo_small():
    """The bundled demo scene at 48x36 (its XML defaults make the resolution a parameter)."""
    return ef.load_scene(DEMO, width=48, height=36)


def steady_state_kernels(history, steps):
    """JIT kernels after the first three of ``steps`` (+1 initial) steps, and those among them that were not
    in-memory cache hits. A disk-cache load counts as a miss (the kernel was new to this process). The first
    steps may meet one variant of a kernel keyed on a buffer's runtime memory alignment: not a per-step
    recompilation, so they are left out."""
    import drjit as dr
    jit = [k for k in history if k.get("type") == dr.KernelType.JIT]
    steady = jit[int(round(3 * len(jit) / (steps + 1))):]
    return steady, [k for k in steady if not k.get("cache_hit") or k.get("cache_disk")]


class FreedOn:
    """A buffer that records, in ``freed``, the thread that frees it: the stand-in for Dr.Jit's pinned host
    memory, which must be freed on the thread that allocated it (events/writer.py). ``np.asarray`` of it is a
    view of ``a``."""

    def __init__(self, a, freed: list):
        self.a, self.freed = a, freed
        self.__array_interface__ = a.__array_interface__

    def __del__(self):
        import threading
        self.freed.append(threading.get_ident())


def refused_when_edited(path: str, part: str, edit, message: str) -> None:
    """A calibration file with its ``part`` changed by ``edit`` (a hand edit) is refused on loading, in one line
    that starts with the file's path and matches ``message``."""
    import json

    import mitsuba_eventfield as ef
    from mitsuba_eventfield.calibration import load_calibration
    with open(path) as f:
        data = json.load(f)
    edit(data[part])
    with open(path, "w") as f:
        json.dump(data, f)
    with pytest.raises(ef.EventFieldError, match=message) as e:
        load_calibration(path)
    assert str(e.value).startswith(path) and "\n" not in str(e.value)
