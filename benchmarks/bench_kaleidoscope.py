"""Kaleidoscope benchmark (issue 4). Ratios from one run, never absolute times.

  * one kaleidoscope render (n x n views in one film) vs a plain perspective render of the same film and spp
    (target: <= 1.2x: the fold should cost almost nothing);
  * the same n x n views rendered as separate cameras (one render each, tile-sized film, camera at the
    view's sub-aperture) vs the single kaleidoscope render.

Writes benchmarks/results/kaleidoscope.json and .md.  Usage: ./run bench kaleidoscope
"""
import os
import re
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

SCENE = os.path.join(os.path.dirname(HERE), "scenes", "falling", "falling.xml")


def timed_render(mi, dr, scene, spp, sensor=0):
    dr.sync_thread()
    t = time.perf_counter()
    dr.eval(mi.render(scene, spp=spp, sensor=sensor))
    dr.sync_thread()
    return time.perf_counter() - t


def main(size=240, spp=4, reps=9):
    import drjit as dr
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant()
    with open(SCENE) as f:
        xml = f.read()
    sensor_block = re.search(r"<sensor .*?</sensor>", xml, flags=re.S).group(0)
    kaleido = mi.load_file(SCENE, views_px=str(size))
    meta = kaleido.sensors()[0].optics_metadata()
    n, D, S = meta["n"], meta["lens_to_image_plane"], meta["focus_distance"]
    W = meta["image_plane_size"][0]
    fov_view = 2 * __import__("math").degrees(__import__("math").atan(W / 2 / D))
    film = ('<film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{w}"/>'
            '<rfilter type="box"/></film>')
    # same film, same content per pixel: the pinhole sees one view's field (every ray meets the same surfaces
    # as the kaleidoscope's; a wider field would let rays escape past the wall and flatter the pinhole)
    persp_sensor = (f'<sensor type="perspective"><float name="fov" value="{fov_view:.6f}"/>'
                    + film.format(w=size) + "</sensor>")
    path = os.path.join(os.path.dirname(SCENE), ".bench_tmp.xml")

    def load(sensors_xml):
        with open(path, "w") as f:
            f.write(xml.replace(sensor_block, sensors_xml))
        try:
            return mi.load_file(path)
        finally:
            os.remove(path)

    plain = load(persp_sensor)
    # n x n separate cameras: a pinhole at each view's sub-aperture, looking at the focus plane, tile-sized film
    cams = []
    for v in meta["views"]:
        ax, ay = v["subaperture"]
        cams.append(f'<sensor type="perspective"><float name="fov" value="{fov_view:.6f}"/>'
                    f'<transform name="to_world"><lookat origin="{ax}, {ay}, 0" target="{ax}, {ay}, {S}" '
                    f'up="0, 1, 0"/></transform>' + film.format(w=size // n) + "</sensor>")
    separate = load("".join(cams))
    for _ in range(2):   # compile
        timed_render(mi, dr, kaleido, spp), timed_render(mi, dr, plain, spp)
        [timed_render(mi, dr, separate, spp, k) for k in range(n * n)]
    tk, tp, ts = [], [], []
    for _ in range(reps):
        tk.append(timed_render(mi, dr, kaleido, spp))
        tp.append(timed_render(mi, dr, plain, spp))
        ts.append(sum(timed_render(mi, dr, separate, spp, k) for k in range(n * n)))
    mk, mp, ms = (statistics.median(v) for v in (tk, tp, ts))
    res = {"film": f"{size}x{size}", "spp": spp, "views": f"{n}x{n}", "repetitions": reps,
           "kaleidoscope_over_perspective": mk / mp, "separate_cameras_over_kaleidoscope": ms / mk,
           "targets": {"kaleidoscope <= 1.2x perspective": mk / mp <= 1.2}}
    md = ["# Kaleidoscope benchmark", "",
          f"- one kaleidoscope render ({n}x{n} views, {size}x{size} film, {spp} spp) / plain perspective render of "
          f"the same film: **{mk / mp:.3f}** (target <= 1.2; median of {reps})",
          f"- {n}x{n} separate cameras (one render each, {size // n}x{size // n}) / one kaleidoscope render: "
          f"**{ms / mk:.2f}x**", ""]
    write_results("kaleidoscope", res, md)


if __name__ == "__main__":
    main()
