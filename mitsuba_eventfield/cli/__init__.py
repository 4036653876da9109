"""Command line ``eventfield``: a thin layer over the Python API, one module per command group (``events``:
render, frame, info, preview; ``lightfield``: reconstruct, refocus, depth; ``calibrate``; ``evaluate``: bench,
regression; ``apps``: the paper's applications; ``device``: the galvo), sharing one argument layer
(``args``: number types, ``-D``, output checks). Errors print as one line."""
from .main import COMMANDS, main  # noqa: F401
