"""Ray optics of spatial multiplexing (kaleidoscope and microlens array), as pure functions (NumPy or Dr.Jit).

Kaleidoscope (after Manakov et al. 2013), sensor-local frame, light travelling towards +z into the scene:

    relay pinhole --R-- tube exit ======= tube (W x H, length L) ======= entrance --D-- main lens --> scene
                                          four mirrors                   field lens     (focal f)

* The main lens (at z = 0, aperture ``aperture_radius``) images the focus plane z = S onto the tube entrance
  at z = -D, with 1/f = 1/D + 1/S.
* The relay looks from distance R behind the exit through the tube. Unfolding the mirror reflections, it sees
  the entrance plane repeated in an infinite grid of cells W x H, each cell a copy mirrored once more than its
  neighbour. The film covers the exit opening, so it shows n x n complete cells when (R + L) / R = n (odd).
* Cell (i, j), i, j in -(n-1)/2 .. (n-1)/2, is reached after |i| reflections in x and |j| in y. The real
  entrance point is the fold p = (-1)^i (q - i W), so odd cells are flipped.
* A field (pupil-matching) lens at the entrance images the relay pupil, seen through the reflections of cell
  (i, j), onto the main lens: every ray of cell (i, j) crosses the main lens in sub-aperture
  a_ij = (-1)^(i+1) (r - i W) D / (R + L), for relay pupil point r. Each tile is then a perspective view
  through its own sub-aperture, which is the view a light field needs.
* Rays that would hit the tube's rim at the exit are blocked (tile seams, vignetting), and so are rays outside
  the main lens aperture.

``tube_only`` mode stops at the entrance: the ray leaves the real entrance point with the folded direction.
A scene with four real mirror rectangles, fired at by the plain relay ray, must give the same image; that is
the test oracle (docs/design.md, "Measured facts and pitfalls").

Microlens array (plenoptic 1.0, the paper's x_s = x // n): pixel (x, y) sits under lenslet (x // n, y // n)
and sees sub-aperture cell (x % n, y % n) of the main lens.
"""
from __future__ import annotations

import math


# what describes a set-up of each layout (the ``kaleidoscope`` sensor's parameter table), e.g. in a nominal
# optics file for a camera recording (``kaleidoscope_sensor.optics_of``); the microlens image plane is
# tube_width x tube_height
SETUP_PARAMETERS = {"kaleidoscope": ("focal_length", "focus_distance", "aperture_radius", "tube_width", "tube_height",
                                     "tube_length", "relay_distance", "relay_aperture"),
                    "microlens": ("focal_length", "focus_distance", "aperture_radius", "tube_width", "tube_height",
                                  "views")}


def tiles(n: int, film_w: int, film_h: int) -> list:
    """The n x n views of a kaleidoscope on a ``film_w`` x ``film_h`` film, row by row: index (i, j) from the
    centre (-(n - 1) / 2 .. (n - 1) / 2), film tile [x0, y0, w, h] (equal tiles), and whether the view is
    mirrored along x / y (an odd number of reflections off the tube's walls: odd i, odd j). The one layout of
    the sensor's views (``kaleidoscope_sensor.view_layout``), a calibration's tiles and the views of a frame.
    Indices are whole for odd n (a kaleidoscope's always is) and halves for an even microlens count, as the ray
    mapping (``microlens_mapping``) has them: a whole-number half put an even count's sub-apertures half a cell
    off (views = 2: 0 and -7.3 mm where the rays pass at +-4.2)."""
    tw, th, half = film_w // n, film_h // n, (n - 1) / 2
    out = []
    for row in range(n):
        for col in range(n):
            i, j = (int(c) if c == int(c) else c for c in (col - half, row - half))
            # mirrored where an odd number of walls reflect it; an even (microlens) count's half indices never are
            out.append({"i": i, "j": j, "tile": [col * tw, row * th, tw, th],
                        "flip_x": isinstance(i, int) and i % 2 == 1, "flip_y": isinstance(j, int) and j % 2 == 1})
    return out


def kaleido_geometry(tube_width, tube_height, tube_length, relay_distance, focal_length, focus_distance,
                     aperture_radius, relay_aperture, where="sensor 'kaleidoscope'"):
    """Derived constants and checks; raises ValueError naming the parameter and what would be allowed."""
    for name, v in (("tube_width", tube_width), ("tube_height", tube_height), ("tube_length", tube_length),
                    ("relay_distance", relay_distance), ("focal_length", focal_length),
                    ("focus_distance", focus_distance)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{where}: {name} = {v!r}: must be a finite length > 0")
    for name, v in (("aperture_radius", aperture_radius), ("relay_aperture", relay_aperture)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{where}: {name} = {v!r}: must be a finite length >= 0")
    ratio = (relay_distance + tube_length) / relay_distance
    n = int(round(ratio))
    if abs(ratio - n) > 1e-3 * ratio or n % 2 == 0:
        want = ", ".join(f"{tube_length / (k - 1):.4g} for {k}x{k}" for k in (3, 5, 7))
        raise ValueError(f"{where}: (relay_distance + tube_length) / relay_distance = {ratio:.4g} must be an odd "
                         f"integer n for n x n complete views; relay_distance = {want}")
    if focus_distance <= focal_length:
        raise ValueError(f"{where}: focus_distance = {focus_distance} must exceed focal_length = {focal_length}")
    lens_to_entrance = 1.0 / (1.0 / focal_length - 1.0 / focus_distance)
    scale = lens_to_entrance / (relay_distance + tube_length)       # relay pupil -> main lens magnification
    spacing_x, spacing_y = tube_width * scale, tube_height * scale   # sub-aperture pitch
    sub_radius = relay_aperture * scale
    half = (n - 1) // 2
    if sub_radius > 0 and 2 * sub_radius > min(spacing_x, spacing_y):
        raise ValueError(f"{where}: relay_aperture = {relay_aperture}: the sub-apertures (radius {sub_radius:.4g}) "
                         f"overlap at their pitch {min(spacing_x, spacing_y):.4g}; relay_aperture must be < "
                         f"{min(tube_width, tube_height) / 2:.4g}")
    needed = math.hypot(half * spacing_x, half * spacing_y) + sub_radius
    if aperture_radius < needed * (1 - 1e-9):
        raise ValueError(f"{where}: aperture_radius = {aperture_radius}: the main lens cuts the outer views "
                         f"(no complete {n}x{n} views); it must be >= {needed:.4g}")
    return {"n": n, "lens_to_entrance": lens_to_entrance, "subaperture_pitch": (spacing_x, spacing_y),
            "subaperture_radius": sub_radius, "half": half}


def fold(xp, q, cell):
    """Unfolded coordinate q -> (cell index, real coordinate in [-cell/2, cell/2], mirror sign (+1/-1))."""
    i = xp.round(q / cell)
    odd = i - 2.0 * xp.floor(i / 2.0)          # 0 or 1, also for negative i
    sign = 1.0 - 2.0 * odd
    return i, sign * (q - i * cell), sign


def film_to_exit(u, v, tube_width, tube_height):
    """Film point (u, v) in [0, 1]^2 -> exit-plane point.

    Chosen so that, after the main lens inverts the image, the centre view is oriented exactly like Mitsuba's
    ``perspective`` camera (scene local +x on the image left, +y at the top); tile column c then holds view
    i = c - (n - 1) / 2, row r view j = r - (n - 1) / 2.
    """
    return (u - 0.5) * tube_width, (v - 0.5) * tube_height


def subaperture(i, j, rx, ry, tube_width, tube_height, scale, xp, signs=None):
    """Main-lens crossing of the rays of cell (i, j) from relay pupil point (rx, ry). ``signs``: the cells' mirror
    signs (-1)^i, (-1)^j when the caller already has them from :func:`fold`."""
    if signs is None:
        _, _, sx = fold(xp, i * tube_width, tube_width)
        _, _, sy = fold(xp, j * tube_height, tube_height)
    else:
        sx, sy = signs
    return -sx * (rx - i * tube_width) * scale, -sy * (ry - j * tube_height) * scale


def main_lens_ray(xp, px, py, ax, ay, lens_to_entrance, focus_distance):
    """Ray leaving the main lens at (ax, ay, 0) that came from entrance point (px, py, -D): it heads for the
    conjugate point of p on the focus plane, P = -p S / D (inverted image)."""
    k = focus_distance / lens_to_entrance
    dx, dy, dz = -px * k - ax, -py * k - ay, focus_distance
    n = xp.sqrt(dx * dx + dy * dy + dz * dz)
    return (ax, ay, 0.0 * ax), (dx / n, dy / n, dz / n)


def microlens_mapping(xp, px_index, py_index, sx, sy, n, film_w, film_h, image_w, image_h):
    """Pixel (integer indices) + sub-pixel sample -> (view i, j centred, image-plane point (x, y), fractional
    position inside the sub-aperture cell in [-0.5, 0.5]^2).

    The image plane spans image_w x image_h, split into (film_w / n) x (film_h / n) lenslets.
    """
    lx, ly = xp.floor(px_index / n), xp.floor(py_index / n)
    vi, vj = px_index - lx * n, py_index - ly * n
    lenses_x, lenses_y = film_w / n, film_h / n
    x = ((lx + 0.5) / lenses_x - 0.5) * image_w       # same orientation as the kaleidoscope's image plane
    y = ((ly + 0.5) / lenses_y - 0.5) * image_h
    half = (n - 1) / 2.0
    # the pixel under a lenslet sees the opposite side of the main lens (the lenslet inverts)
    return half - vi, half - vj, x, y, sx - 0.5, sy - 0.5
