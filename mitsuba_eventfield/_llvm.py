"""Point Dr.Jit at a libLLVM it can use, before drjit is first imported.

Dr.Jit 1.5's LLVM backend aborts with the system LLVM 15 of Debian 12 ("Cannot select ... fminimum");
LLVM >= 16 works (measured with Debian's libllvm19). Dr.Jit reads the ``DRJIT_LIBLLVM_PATH`` environment
variable once, when it is imported, so this module must run before anything imports drjit or mitsuba.
A path the user already set is respected.
"""
from __future__ import annotations

import glob
import os
import re
import sys

MIN_LLVM_MAJOR = 16
_SEARCH_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)


def find_libllvm(search_dirs=_SEARCH_DIRS) -> tuple[str | None, list[str]]:
    """Return (path of the newest libLLVM with major >= 16 or None, every libLLVM found)."""
    found: dict[str, int] = {}
    for d in search_dirs:
        for path in glob.glob(os.path.join(d, "libLLVM*.so*")) + glob.glob(os.path.join(d, "llvm-*/lib/libLLVM*.so*")) \
                + glob.glob(os.path.join(d, "libLLVM*.dylib")):
            m = re.search(r"libLLVM[-.]?(\d+)", os.path.basename(path)) or re.search(r"llvm-(\d+)", path)
            if m:
                found[path] = int(m.group(1))
    usable = sorted((v, p) for p, v in found.items() if v >= MIN_LLVM_MAJOR)
    return (usable[-1][1] if usable else None), sorted(found)


def configure() -> str | None:
    """Set DRJIT_LIBLLVM_PATH if unset and a usable libLLVM exists; return the path in force (or None)."""
    current = os.environ.get("DRJIT_LIBLLVM_PATH")
    if current:
        return current
    if "drjit" in sys.modules:  # too late to influence Dr.Jit; say nothing, backend selection reports problems
        return None
    path, _ = find_libllvm()
    if path:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path
