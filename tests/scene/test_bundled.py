"""The library works from an installed wheel: the bundled scenes are package data found through
``importlib.resources`` (``scene.bundled_scene``), and no module finds files through ``tests/`` or by walking up
from its own ``__file__`` (which from site-packages leads nowhere)."""
import ast
import configparser
import fnmatch
import glob
import os
import subprocess
import sys

import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.scene import bundled_scene, scenes_dir

PACKAGE_FOLDERS = ("mitsuba_eventfield", "plugins", "calibration", "device", "scenes")   # what the wheel holds


def _source_files(pattern):
    src = os.path.join(ROOT, "scenes")
    return sorted(os.path.relpath(p, src).replace(os.sep, "/") for p in glob.glob(os.path.join(src, "**", pattern),
                                                                                 recursive=True)
                  if "__pycache__" not in p)


def test_every_bundled_scene_resolves_to_an_existing_file():
    xmls = _source_files("*.xml")
    assert len(xmls) >= 10 and "fan/fan.xml" in xmls
    for name in xmls:
        path = bundled_scene(name)
        assert os.path.isfile(path) and os.path.samefile(path, os.path.join(ROOT, "scenes", *name.split("/")))
    assert os.path.samefile(scenes_dir(), os.path.join(ROOT, "scenes"))     # here: the checkout (pip install -e)
    with pytest.raises(ef.EventFieldError, match="no bundled scene 'nope.xml'; available: .*fan/fan.xml"):
        bundled_scene("nope.xml")


def test_every_scene_file_is_package_data():
    """Each file a scene needs (meshes, textures, motion) matches setup.cfg's package_data, so it is in the
    wheel (a new kind of asset needs a new pattern there)."""
    cfg = configparser.ConfigParser()
    cfg.read(os.path.join(ROOT, "setup.cfg"))
    patterns = [p.strip() for p in cfg["options.package_data"]["mitsuba_eventfield.scenes"].split(",")]
    assert "mitsuba_eventfield.scenes = scenes" in cfg["options"]["package_dir"].splitlines()
    data = [f for f in _source_files("*") if os.path.isfile(os.path.join(ROOT, "scenes", f)) and not f.endswith(".py")]
    assert data and [f for f in data if not any(fnmatch.fnmatch(f, p) for p in patterns)] == []


# the command line's default for `eventfield regression --references`: relative to the current folder (the
# repository root), used only when it exists there; never a path from the package's own location
ALLOWED = {(os.path.join("mitsuba_eventfield", "cli", "evaluate.py"), "tests")}


def _package_modules():
    for folder in PACKAGE_FOLDERS:
        yield from glob.glob(os.path.join(ROOT, folder, "**", "*.py"), recursive=True)


def _docstrings(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                yield first.value


def _levels_up(name_node, parents):
    """How many folders up an expression built on ``__file__`` goes (dirname, .parent, .parents[k])."""
    ups, node = 0, name_node
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.Call):
            fn = node.func
            called = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
            if called == "dirname":
                ups += 1
            elif called not in ("abspath", "realpath", "normpath", "Path", "resolve", "absolute"):
                break
        elif isinstance(node, ast.Attribute) and node.attr == "parent":
            ups += 1
        elif isinstance(node, ast.Attribute) and node.attr == "parents":
            ups += 2
        elif not (isinstance(node, ast.Attribute) and node.attr in ("resolve", "absolute")):
            break
    return ups


def test_no_module_reaches_into_tests_or_up_from_its_file():
    problems = []
    for path in _package_modules():
        rel = os.path.relpath(path, ROOT)
        tree = ast.parse(open(path).read())
        parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        docs = {id(d) for d in _docstrings(tree)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs \
                    and not isinstance(parents.get(node), ast.JoinedStr):      # f-string text: "{lo}..{hi}"
                parts = node.value.replace("\\", "/").split("/")
                if ("tests" in parts or ".." in parts) and (rel, node.value) not in ALLOWED:
                    problems.append(f"{rel}:{node.lineno}: path string {node.value!r}")
            if isinstance(node, ast.Name) and node.id == "__file__" and _levels_up(node, parents) >= 2:
                problems.append(f"{rel}:{node.lineno}: walks up from __file__")
    assert problems == []


def test_the_check_above_catches_what_it_should(tmp_path):
    """The AST rules find the patterns they are meant to (a check that finds nothing proves little)."""
    samples = {"os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'scenes')": 2,
               "Path(__file__).resolve().parent.parent / 'scenes'": 2, "Path(__file__).parents[1]": 2,
               "os.path.dirname(os.path.abspath(__file__))": 1}
    for code, ups in samples.items():
        tree = ast.parse(code)
        parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        name = next(n for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id == "__file__")
        assert _levels_up(name, parents) == ups, code


def test_regression_command_needs_references_outside_the_repository(tmp_path):
    """The library has no path into tests/: the command takes the repository's tests/regression only when run
    from its root, otherwise it asks for --references."""
    r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "regression"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--references DIR is required" in r.stderr, r.stderr
    assert os.listdir(tmp_path) == []
