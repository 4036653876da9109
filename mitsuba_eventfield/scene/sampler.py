"""The sensor's sampler: the scene's own when it names one, else the project's default.

Mitsuba gives a sensor without a ``<sampler>`` its independent sampler. The speed-against-accuracy chart
(``eventfield bench``, benchmarks/results/bench_suite.md, 5 seeds per setting, 2-core CPU) measured that a
multi-jittered sampler at the same spp is more accurate on every scene of the suite for 8-16 % more time:
analytic scene at 4 spp / 100 steps, median timestamp error 12.4 -> 4.0 us, p99 98 -> 41 us, per-pixel count error
0.023 -> 0.007; fan 0.42 -> 0.29 and refocus PSNR 13.9 -> 19.3 dB; kaleidoscope grid 2.11 -> 1.04; demo 1.17 -> 1.09.
With a fixed seed the sample positions of a pixel are the same every step (the frozen-noise rule), and
stratified positions move a pixel's estimate less as an edge crosses it. So a scene that names no sampler is
loaded with ``DEFAULT_SAMPLER``; one that names a sampler keeps it; ``load_scene(..., sampler=...)`` chooses.

The sampler is set by rewriting the scene's XML text (Mitsuba has no setter on a loaded sensor): the text is
copied into a temporary folder and loaded with the scene's own folder first on Mitsuba's file resolver, so its
textures, meshes and includes are found as before.
"""
from __future__ import annotations

import os
import re
import tempfile

DEFAULT_SAMPLER = {"type": "multijitter"}
# the samplers a plan or a frame may take in place of a scene's own (plugin names)
SAMPLERS = ("independent", "multijitter", "stratified", "ldsampler")

_SENSOR_OPEN = re.compile(r"<sensor\b[^>]*?(/?)>")
_SAMPLER = re.compile(r"<sampler\b[^>]*/>|<sampler\b.*?</sampler>", re.S)


def plugin_name(class_name: str) -> str:
    """A Mitsuba sampler's plugin name from its class name: MultijitterSampler -> multijitter,
    LowDiscrepancySampler -> ldsampler (what ``<sampler type=...>`` and ``load_scene(sampler=)`` take)."""
    name = str(class_name).removesuffix("Sampler").lower()
    return {"lowdiscrepancy": "ldsampler"}.get(name, name)


def sampler_xml(sampler: dict) -> str:
    """``{"type": "multijitter", "sample_count": 16}`` as a Mitsuba ``<sampler>`` element."""
    def prop(k, v):
        if isinstance(v, bool):
            return f'<boolean name="{k}" value="{str(v).lower()}"/>'
        if isinstance(v, int) or type(v).__name__.startswith(("int", "uint")):
            return f'<integer name="{k}" value="{int(v)}"/>'
        return f'<float name="{k}" value="{float(v)!r}"/>'
    props = "".join(prop(k, v) for k, v in sampler.items() if k != "type")
    return f'<sampler type="{sampler["type"]}">{props}</sampler>'


def _sensor_body(text: str):
    """(start, end) of the first sensor element's body in ``text``, or None (no sensor, or an empty one)."""
    opening = _SENSOR_OPEN.search(text)
    if opening is None or opening[1]:
        return None
    end = text.find("</sensor>", opening.end())
    return (opening.end(), end) if end >= 0 else None


def names_sampler(text: str) -> bool | None:
    """Whether the scene's first sensor names a sampler; None when the text has no sensor body to look in
    (a sensor from an include, or none): such a scene is loaded as it is."""
    body = _sensor_body(text)
    return None if body is None else bool(_SAMPLER.search(text, body[0], body[1]))


def with_sampler(text: str, sampler: dict) -> str | None:
    """The scene text with its first sensor's sampler replaced by (or given) ``sampler``; None without a sensor."""
    body = _sensor_body(text)
    if body is None:
        return None
    start, end = body
    inner = _SAMPLER.sub("", text[start:end], count=1)
    return text[:start] + sampler_xml(sampler) + inner + text[end:]


def load_text(mi, text: str, path: str, params: dict):
    """``mi.load_file`` of ``text`` as if it were the file at ``path`` (its folder first on the resolver)."""
    resolver = mi.file_resolver()
    saved = [resolver[i] for i in range(len(resolver))]
    resolver.prepend(os.path.dirname(os.path.abspath(path)))
    try:
        with tempfile.TemporaryDirectory() as folder:
            copy = os.path.join(folder, os.path.basename(path))
            with open(copy, "w") as f:
                f.write(text)
            try:
                return mi.load_file(copy, **params)
            except RuntimeError as e:       # its messages name the copy: name the user's file
                raise RuntimeError(str(e).replace(copy, path)) from None
    finally:
        resolver.clear()
        for p in saved:
            resolver.append(p)


def choose(text: str, sampler: dict | None):
    """(text to load or None for the file as it is, what was chosen for the metadata)."""
    if sampler is not None:
        rewritten = with_sampler(text, sampler)
        if rewritten is None:
            raise ValueError("no <sensor> element whose sampler could be chosen")
        return rewritten, f"{sampler['type']} (chosen)"
    named = names_sampler(text)
    if named or named is None:
        return None, "the scene's own"
    return with_sampler(text, DEFAULT_SAMPLER), f"{DEFAULT_SAMPLER['type']} (default: the scene names none)"
