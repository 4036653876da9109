"""The package is shaped like the pipeline: every module imports only from its own layer or lower ones (at
module level and inside functions), module-level imports have no cycles, library code never imports the
package facade, and no docstring or comment names a repository file that does not exist."""
import ast
import glob
import os
import re

from conftest import ROOT

PACKAGES = {"mitsuba_eventfield": "mitsuba_eventfield", "mitsuba_eventfield.plugins": "plugins",
            "mitsuba_eventfield.calibration": "calibration", "mitsuba_eventfield.device": "device"}
# lower layers first; a module may import from its layer and those before it
LAYERS = [
    {"errors", "_version", "_llvm", "validate", "atomic", "output_folders", "images", "workers"},
    {"optics"},
    {"events", "device"},
    {"plugins"},
    {"backend"},
    {"scene"},
    {"simulate"},
    {"lightfield"},
    {"focus"},
    {"calibration"},
    {"evaluation"},
    {"apps"},
    {"cli"},
]
FACADE_ALLOWED = {"mitsuba_eventfield"}
MAPPED = {"plugins", "calibration", "device", "scenes"}     # subpackages installed from top-level folders


def _modules():
    for pkg, folder in PACKAGES.items():
        for path in glob.glob(os.path.join(ROOT, folder, "**", "*.py"), recursive=True):
            rel = os.path.relpath(path, os.path.join(ROOT, folder))[:-3].replace(os.sep, ".")
            name = pkg if rel == "__init__" else pkg + "." + rel.removesuffix(".__init__")
            if folder == "mitsuba_eventfield" and rel.split(".")[0] in ("plugins", "calibration", "device"):
                continue
            yield name, path


def _imports(name, path, top_level_only=False):
    tree = ast.parse(open(path).read())
    is_pkg = path.endswith("__init__.py")
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("mitsuba_eventfield"):
                yield from (f"{mod}.{a.name}" for a in node.names)
                yield mod
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names if a.name.startswith("mitsuba_eventfield"))


def _layer(module):
    parts = module.split(".")
    key = parts[1] if len(parts) > 1 else None
    for i, layer in enumerate(LAYERS):
        if key in layer:
            return i
    return None


def test_no_upward_imports():
    wrong = []
    for name, path in _modules():
        own = _layer(name)
        if own is None:
            continue
        for target in set(_imports(name, path)):
            other = _layer(target)
            if other is not None and other > own:
                wrong.append(f"{name} -> {target}")
    assert not wrong, "imports from a higher layer:\n" + "\n".join(sorted(wrong))


def test_no_import_cycles_between_modules():
    known = dict(_modules())
    graph = {name: {t for t in _imports(name, path, top_level_only=True) if t in known and t != name}
             for name, path in known.items()}
    # a package's __init__ re-exporting its modules is not a cycle through them
    graph = {n: {t for t in ts if not n.startswith(t + ".")} for n, ts in graph.items()}
    state, cycle = {}, []

    def visit(node, stack):
        state[node] = "open"
        for nxt in graph.get(node, ()):
            if state.get(nxt) == "open":
                cycle.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = "done"
    for n in graph:
        if n not in state:
            visit(n, [n])
    assert not cycle, f"import cycle: {' -> '.join(cycle[0])}"


def _imports_facade(name, path):
    """``import mitsuba_eventfield`` or a name (not a submodule) taken from the package's ``__init__``."""
    top = os.path.join(ROOT, "mitsuba_eventfield")
    for node in ast.walk(ast.parse(open(path).read())):
        if isinstance(node, ast.Import) and any(a.name == "mitsuba_eventfield" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom):
            depth = name.count(".") + (1 if path.endswith("__init__.py") else 0)
            is_root = (node.level == 0 and node.module == "mitsuba_eventfield") or \
                (node.level == depth and node.module is None and name.startswith("mitsuba_eventfield."))
            if is_root and any(not (os.path.exists(os.path.join(top, a.name + ".py")) or a.name in MAPPED
                                    or os.path.isdir(os.path.join(top, a.name))) for a in node.names):
                return True
    return False


def test_library_code_does_not_import_the_facade():
    offenders = [name for name, path in _modules() if name not in FACADE_ALLOWED and _imports_facade(name, path)]
    assert not offenders, offenders


def test_every_repository_path_named_in_code_and_docs_exists():
    pattern = re.compile(r"(?<![\w/.-])((?:mitsuba_eventfield|plugins|calibration|device|docs|scenes|tests|"
                         r"benchmarks)/[\w./-]*\w)")
    files = [p for _, p in _modules()] + [os.path.join(ROOT, "README.md")]
    files += glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)
    missing = []
    for path in files:
        for i, line in enumerate(open(path), 1):
            for ref in pattern.findall(line):
                ref = ref.rstrip(".")
                full = os.path.join(ROOT, ref)
                if "*" not in ref and "<" not in ref and not (os.path.exists(full) or glob.glob(full + "*")):
                    missing.append(f"{os.path.relpath(path, ROOT)}:{i}: {ref}")
    assert not missing, "\n".join(missing)


def test_every_application_returns_the_one_result_type():
    from mitsuba_eventfield.apps.demo import DemoResult
    from mitsuba_eventfield.apps.hdr import HDRComparison
    from mitsuba_eventfield.apps.highspeed import FocusTrack, PlaneRefocus
    from mitsuba_eventfield.apps.result import AppResult
    from mitsuba_eventfield.apps.scanrate import ScanRateDepth
    from mitsuba_eventfield.apps.slomorf import SloMoRFResult
    for cls in (DemoResult, HDRComparison, FocusTrack, PlaneRefocus, ScanRateDepth, SloMoRFResult):
        assert issubclass(cls, AppResult)
        for method in ("report", "write", "figure"):
            assert getattr(cls, method) is not getattr(AppResult, method), (cls.__name__, method)


def test_small_pieces():
    """No library file over ~400 lines and no function over ~60 (a little slack for docstrings)."""
    too_big = []
    for name, path in _modules():
        source = open(path).read()
        if len(source.splitlines()) > 420:
            too_big.append(f"{name}: {len(source.splitlines())} lines")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno >= 65:
                too_big.append(f"{name}.{node.name}: {node.end_lineno - node.lineno + 1} lines")
    assert not too_big, "\n".join(too_big)
