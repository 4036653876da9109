import os
import sys

import pytest

import mitsuba_eventfield as ef

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(ROOT, "scenes", "demo", "demo.xml")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="session", autouse=True)
def mono_variant():
    ef.set_variant("llvm_ad_mono")


@pytest.fixture
def demo_small():
    """The bundled demo scene at 48x36 (its XML defaults make the resolution a parameter)."""
    return ef.load_scene(DEMO, width=48, height=36)
