"""An independent oracle for a galvo's image motion: distant points traced through the rotated mirrors
(``optics.galvo.project_point``, ray geometry alone), not the homographies (``GalvoGeometry``) that the renderer's
metadata and the motion-placed steps use."""
import numpy as np

from mitsuba_eventfield.optics.galvo import focal_length_px, project_point
from mitsuba_eventfield.optics.scan import curve_from_dict, scan_period

FAR_M = 1e4      # 10 km: the pivots' parallax is 1e-5 of the path, "at infinity" for these checks


def traced_scan_path_px(optics: dict, width: int, height: int, t0: float = 0.0, t1: float | None = None,
                        samples: int = 2048) -> float:
    """The longest image path over [t0, t1] (default one scan period) of a distant point seen at the image centre
    or a corner at rest, in pixels."""
    f = focal_length_px(width, optics["fov_x_deg"])
    t1 = scan_period(optics["scan"]) if t1 is None else t1
    ax, ay = curve_from_dict(optics["scan"]).angles(np.linspace(t0, t1, samples + 1))
    longest = 0.0
    for u, v in ((width / 2, height / 2), (0.0, 0.0), (width, 0.0), (0.0, height), (width, height)):
        far = FAR_M * np.array([(width / 2 - u) / f, (height / 2 - v) / f, 1.0])
        x, y = project_point(np, far, ax, ay, optics["mirror_distance"], optics["mirror_separation"], f, width,
                             height)
        longest = max(longest, float(np.hypot(np.diff(x), np.diff(y)).sum()))
    return longest
