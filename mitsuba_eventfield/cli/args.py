"""The argument layer every command shares: one-line parser errors, number types built on ``validate`` (one
rule and one message for the command line and the library), one ``NAME=VALUE`` parser (``-D``, ``--plane``,
``--pixel``), and one check of every output path before any work starts."""
from __future__ import annotations

import argparse
import os

from ..errors import ConfigError, EventFieldError
from ..validate import number, number_list


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (the usage is one ``--help`` away); subcommands inherit the class."""

    def error(self, message):
        self.exit(2, f"eventfield: error: {message} (see {self.prog} --help)\n")


def num(lo=None, hi=None, integer=False, lo_open=False):
    """An argparse type: a finite number in [lo, hi] (``lo_open``: lo excluded), checked by ``validate.number``."""
    def parse(text):
        try:
            return number(text, "value", lo, hi, integer=integer, lo_open=lo_open)
        except ConfigError as e:
            raise argparse.ArgumentTypeError(str(e).replace("value = ", "", 1)) from None
    return parse


def velocity(text):
    """An argparse type: ``VX,VY``, two finite numbers (pixels per second)."""
    from ..validate import number_list
    try:
        values = number_list(text, "value")
    except ConfigError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    if len(values) != 2:
        raise argparse.ArgumentTypeError(f"{text}: expected VX,VY (pixels per second)")
    return tuple(values)


def pairs(items, what: str) -> dict:
    """{NAME: VALUE} of repeated ``NAME=VALUE`` arguments (values stay text; the scene or the caller converts)."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise EventFieldError(f"{what} {item!r}: expected NAME=VALUE")
        if out.get(key, value) != value:          # the last one won without a word
            raise EventFieldError(f"{what} {key} given twice ({out[key]} and {value}): give it once")
        out[key] = value
    return out


def add_defines(parser, default=None, help_text="value of an XML <default name=...> parameter, e.g. -D width=64 "
                                                 "(repeatable)"):
    parser.add_argument("-D", "--define", action="append", default=list(default or []), metavar="NAME=VALUE",
                        help=help_text)


def defines(args) -> dict:
    return pairs(args.define, "-D")


def times_ms(text, what="--times"):
    return number_list(text, what, lo=0, hi=1e9)


# Every output a subcommand writes, checked in one place before any work starts (a render must not run for
# minutes and then fail on its output path). Files: (argument, what); directories: the -o of the applications.
OUTPUT_FILES = {"render": (("output", "event file"), ("preview", "preview")), "preview": (("output", "preview"),),
                "convert": (("output", "event file"),),
                "frame": (("output", "frame"),), "refocus": (("output", "refocused image"),),
                "depth": (("output", "depth map"),), "calibrate": (("output", "calibration file"),),
                "device": (("metadata", "metadata"),)}
OUTPUT_DIRS = ("demo", "reconstruct", "bench", "hdr", "highspeed", "track-focus", "slomorf", "scanrate-depth", "paper")


# outputs whose kind their extension must name: a render's --preview was checked after the render (which had
# written its event file by then)
OUTPUT_SUFFIXES = {("render", "preview"): (".png",), ("preview", "output"): (".png",), ("frame", "output"): (".exr",),
                   ("refocus", "output"): (".png",), ("depth", "output"): (".png",),
                   ("calibrate", "output"): (".json",)}


# outputs that may be one of the command's inputs: a calibration file is created or extended
EXTENDED = {("calibrate", "output")}


def _path_like(value) -> bool:
    """An argument that can name an input file: a word with an extension or a directory in it (a choice such as
    ``--curve line`` or the command's own name is not one: ``--metadata line`` was refused as that input)."""
    return isinstance(value, str) and ("." in os.path.basename(value) or os.sep in value)


def check_outputs(args) -> None:
    """Every output path of the command (``OUTPUT_FILES``, ``OUTPUT_DIRS``) before any work: an empty one, an
    unwritable one, a wrong kind, and a file that is one of the command's inputs (any other argument naming
    an existing file, through a link too) are refused in one line."""
    from ..atomic import check_not_input, check_output_dir, check_writable
    files = OUTPUT_FILES.get(args.command, ())
    for name, what in files:
        path = getattr(args, name, None)
        if path is None:
            continue
        check_writable(path, what)
        suffixes = OUTPUT_SUFFIXES.get((args.command, name))
        if suffixes and not path.lower().endswith(suffixes):
            raise EventFieldError(f"{path}: {what} must be a {' or '.join(suffixes)} file")
        if (args.command, name) not in EXTENDED:
            check_not_input(path, [v for k, v in vars(args).items() if k != name and _path_like(v)], what)
    if args.command in OUTPUT_DIRS:
        if not str(args.output).strip():
            raise EventFieldError("-o/--output: empty: name an output directory")
        check_output_dir(args.output)


def check_files(paths, what: str) -> None:
    """Every file a command will write, checked before its work (``atomic.check_writable``)."""
    from ..atomic import check_writable
    for path in paths:
        check_writable(path, what)


def one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def save_image(png_path, linear, meta, suffix="", exr=None):
    """A linear image as EXR (values; ``exr``, else the PNG's name with .exr) and PNG (display) beside each
    other; returns their common root."""
    from ..images import to_uint8, write_exr, write_png
    root = os.path.splitext(png_path)[0] + suffix
    write_exr(exr or root + ".exr", {"Y": linear}, meta)
    write_png(root + ".png", to_uint8(linear))
    return root
