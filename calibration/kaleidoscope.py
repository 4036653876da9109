"""Kaleidoscope calibration from a captured mosaic: tile seams, flips, sub-pixel view registration, flat-field.

* Seams: neighbouring tiles are mirror images of each other across their shared edge (one more reflection),
  so a seam is a line of mirror symmetry. The tile count n (odd) is the one whose n - 1 equally spaced seams
  are the most symmetric, per axis.
* Flips alternate with the distance from the centre tile (odd tiles are mirrored).
* Registration: each unflipped view against the centre view by upsampled cross-correlation (scikit-image),
  to 1/100 px.
  For a target at the focus plane the offsets measure the residual misalignment of the optics; for one at
  another depth they are its disparities.
* Refusal: registered views that do not show one scene (a galvo frame, blank or noise, whose seams are
  symmetric only by chance) stop the calibration (``MIN_VIEW_CONSISTENCY``).
* Flat-field: a capture of a uniform white target gives each view's gain map (vignetting at the seams).
* Use (``calibration.apply_to_lightfield``): every view's registration offset, less the parallax of the
  target's depth (``target_depth``; default the focus distance, where there is none), is what the instrument
  adds to that view's shift at every depth (``LightField.view_offsets``); the gain maps divide views whose
  levels come from a frame (events alone carry no gain: a log change is the same under any gain).
"""
from __future__ import annotations

import base64
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from mitsuba_eventfield.errors import ConfigError

from .galvo import CalibrationError
from .targets import check_flat_texture, quarter_spread, warn_not_flat

# Below this gain a view sees less than a twentieth of the light the centre view sees there (the relay pupil at a
# seam): dividing by it would raise the pixel's noise twentyfold, so a flat-fielded view is divided by at least this
GAIN_FLOOR = 0.05


def _symmetry_profile(img: np.ndarray, axis: int, half: int) -> np.ndarray:
    """Score per candidate seam (between pixel c-1 and c): correlation of the strips on either side, mirrored."""
    a = np.asarray(img, dtype=np.float64)
    if axis == 0:
        a = a.T
    w = a.shape[1]
    scores = np.full(w + 1, -1.0)
    for c in range(half, w - half + 1):
        left = a[:, c - half:c][:, ::-1].ravel()
        right = a[:, c:c + half].ravel()
        lc, rc = left - left.mean(), right - right.mean()
        den = np.sqrt((lc @ lc) * (rc @ rc))
        scores[c] = (lc @ rc) / den if den > 1e-12 else -1.0
    return scores


def find_tiles(frame: np.ndarray, candidates=(3, 5, 7, 9), half: int = 4) -> dict:
    """Tile count per axis and seam positions from a mosaic (log or linear). Refuses if no count is clear."""
    frame = np.asarray(frame, dtype=np.float64)
    h, w = frame.shape
    if frame.std() < 1e-6:
        raise CalibrationError("the frame is uniform: seams cannot be found without texture")
    out = {}
    for axis, size, name in ((1, w, "x"), (0, h, "y")):
        prof = _symmetry_profile(frame, axis, half)
        best, ranking = None, []
        for n in candidates:
            if size % n:
                continue
            seams = [k * size // n for k in range(1, n)]
            score = float(np.mean([prof[c] for c in seams]))
            ranking.append((score, n))
            if best is None or score > best[0]:
                best = (score, n, seams)
        if best is None:
            raise CalibrationError(f"the {name} size {size} is not divisible by any tile count in {candidates}")
        ranking.sort(reverse=True)
        if best[0] < 0.5 or (len(ranking) > 1 and ranking[1][0] > best[0] - 0.05):
            raise CalibrationError(f"no clear tile count along {name}: symmetry scores "
                                   + ", ".join(f"n={n}: {s:.2f}" for s, n in ranking))
        out[name] = {"n": best[1], "seams": best[2], "score": best[0]}
    if out["x"]["n"] != out["y"]["n"]:
        raise CalibrationError(f"tile counts differ: {out['x']['n']} along x, {out['y']['n']} along y")
    return out


def _whole(value, lo: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= lo


def _check_view(v, n: int, tile: tuple, where: str) -> None:
    """One view record: indices within the n x n layout, flips, and an offset of finite pixels within its tile."""
    half = (n - 1) // 2
    if not isinstance(v, dict) or not all(k in v for k in ("i", "j", "offset")):
        raise ConfigError(f"{where}: each view needs i, j and offset (got {v!r:.80})")
    if not all(isinstance(v[k], int) and not isinstance(v[k], bool) and -half <= v[k] <= half for k in "ij"):
        raise ConfigError(f"{where}: view ({v['i']!r}, {v['j']!r}): i and j must be whole numbers in "
                          f"-{half}..{half}")
    off = v["offset"]
    if not (isinstance(off, (list, tuple)) and len(off) == 2 and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in off)):
        raise ConfigError(f"{where}: view ({v['i']}, {v['j']}): offset = {off!r}: must be [dx, dy] in pixels")
    if abs(off[0]) >= tile[0] / 2 or abs(off[1]) >= tile[1] / 2:
        raise ConfigError(f"{where}: view ({v['i']}, {v['j']}): offset = {list(off)} px: must be within half a "
                          f"tile ({tile[0] / 2:g} x {tile[1] / 2:g} px)")


def _check_layout(v: dict, layout: dict, where: str) -> None:
    """A view's ``tile``, ``flip_x`` and ``flip_y``, recorded for readers, against the sensor's layout, which is
    what every reader uses (``kaleido_optics.tiles``): a hand-edited value was never read, so never refused."""
    for key in ("tile", "flip_x", "flip_y"):
        if key in v and not _same_value(v[key], layout[key]):
            raise ConfigError(f"{where}: view ({v['i']}, {v['j']}): {key} = {v[key]!r}: the {layout['tile'][2]}x"
                              f"{layout['tile'][3]} px tiles' layout has {layout[key]!r} (the sensor's, recorded "
                              "for readers: re-run eventfield calibrate kaleidoscope rather than editing it)")


def _checked_crop(crop, n: int, tile: tuple, where: str) -> dict:
    """The crop record of a calibration made from a window of a larger sensor: the window, of the tiles' size,
    inside the sensor (``validate.crop_window``)."""
    from mitsuba_eventfield.validate import crop_window
    sensor = crop.get("sensor") if isinstance(crop, dict) else None
    if not (isinstance(sensor, (list, tuple)) and len(sensor) == 2 and all(_whole(v, 1) for v in sensor)):
        raise ConfigError(f"{where}: crop = {crop!r}: expected {{\"window\": [x0, y0, w, h], \"sensor\": [w, h]}}")
    window = crop_window(crop.get("window") or (), *sensor, f"{where}: crop window")
    if tuple(window[2:]) != (n * tile[0], n * tile[1]):
        raise ConfigError(f"{where}: crop window {list(window)}: its {window[2]}x{window[3]} px are not the "
                          f"{n}x{n} tiles' {n * tile[0]}x{n * tile[1]}")
    return {"window": list(window), "sensor": [int(v) for v in sensor]}


def _same_value(a, b) -> bool:
    if isinstance(b, bool):
        return isinstance(a, bool) and a == b
    return isinstance(a, (list, tuple)) and list(a) == list(b) and not any(isinstance(c, bool) for c in a)


def known_tiles(n: int, width: int, height: int) -> dict:
    """The tiles of an n x n kaleidoscope on a ``width`` x ``height`` film, for a frame whose sensor metadata
    says n: equal tiles, no search. The seam search needs mirror symmetry at every seam, which a misaligned tube
    (the thing being calibrated) weakens: 2 px of misalignment read as 5 tiles along y instead of 3."""
    if width % n or height % n:
        raise CalibrationError(f"a {width}x{height} frame does not split into {n}x{n} equal tiles")
    return {"x": {"n": n, "seams": [k * width // n for k in range(1, n)]},
            "y": {"n": n, "seams": [k * height // n for k in range(1, n)]}}


@dataclass
class KaleidoscopeCalibration:
    n: int
    tile: tuple                            # (width, height) in pixels
    views: list = field(default_factory=list)   # per view: i, j, tile rect, flips, offset (dx, dy), consistency
    flat_gain: list | None = None          # per view: mean gain
    seam_scores: dict = field(default_factory=dict)   # mirror symmetry at the seams, per axis (find_tiles)
    optics: dict = field(default_factory=dict)        # what it was made for (optics.optics_record), set when saved
    target_depth: float | None = None      # scene units: depth of the registered target; None: the focus distance
    flat_map: dict | None = None           # the flat field's gain over the film (``_encode_map``): float16, base64
    registration: str | None = None        # how the offsets were measured (``REGISTRATION``; None: before it)
    crop: dict | None = None               # the frame's window of a larger sensor ("window" x0, y0, w, h; "sensor")

    def __post_init__(self):
        """Every field checked, as a hand-edited file is read (a bad offset was a raw ValueError deep in refocus,
        an offset of 1e6 px asked for 262 TiB of padding, a negative gain map brightened every view 20x)."""
        where = "kaleidoscope calibration"
        n, tile = self.n, self.tile
        if isinstance(n, bool) or not isinstance(n, int) or n < 1 or n % 2 == 0:
            raise ConfigError(f"{where}: n = {n!r}: must be an odd whole number of views a side")
        if not (isinstance(tile, (list, tuple)) and len(tile) == 2 and all(_whole(v, 1) for v in tile)):
            raise ConfigError(f"{where}: tile = {tile!r}: must be (width, height) in whole pixels")
        self.tile = tuple(int(v) for v in tile)
        if not isinstance(self.views, list) or len(self.views) != n * n:
            raise ConfigError(f"{where}: views must list the {n * n} views of {n}x{n} tiles")
        from mitsuba_eventfield.plugins.kaleido_optics import tiles
        layout = {(v["i"], v["j"]): v for v in tiles(n, n * self.tile[0], n * self.tile[1])}
        for v in self.views:
            _check_view(v, n, self.tile, where)
            _check_layout(v, layout[(v["i"], v["j"])], where)
        if len({(v["i"], v["j"]) for v in self.views}) != n * n:
            raise ConfigError(f"{where}: views must list each of the {n * n} views of {n}x{n} tiles once")
        if self.target_depth is not None:
            z = self.target_depth
            if isinstance(z, bool) or not isinstance(z, (int, float)) or not math.isfinite(z) or z <= 0:
                raise ConfigError(f"{where}: target_depth = {z!r}: must be a number > 0 (scene units), or absent "
                                  "for a target at the focus distance")
            self.target_depth = float(z)
        if self.crop is not None:
            self.crop = _checked_crop(self.crop, n, self.tile, where)
        if self.flat_map is not None:
            gain = _decode_map(self.flat_map)
            tw, th = self.tile
            if gain.shape != (n * th, n * tw) or not np.all(np.isfinite(gain)) or gain.min() < 0:
                raise ConfigError(f"{where}: flat_map must be a finite, non-negative {n * tw}x{n * th} gain map (it "
                                  f"is {'x'.join(map(str, gain.shape[::-1]))}): re-run eventfield calibrate "
                                  "kaleidoscope --flat")

    @property
    def quality(self) -> dict:
        """How well the views agree once registered (``MIN_VIEW_CONSISTENCY``), the seams' symmetry, views used."""
        c = [v["consistency"] for v in self.views if "consistency" in v and (v["i"], v["j"]) != (0, 0)]
        spread = [v["quarter_spread_px"] for v in self.views if "quarter_spread_px" in v]
        return {"min_view_consistency": min(c) if c else None, "max_quarter_spread_px": max(spread, default=None),
                "median_view_consistency": float(np.median(c)) if c else None,
                "seam_scores": self.seam_scores, "samples": len(self.views)}

    def as_dict(self) -> dict:
        return {"kind": "kaleidoscope", **asdict(self), "quality": self.quality}

    def misalignment(self, ij, positions, disparity) -> np.ndarray:
        """(K, 2) pixels the instrument moves views (i, j) = ``ij`` by, whatever the depth: each view's measured
        offset less the parallax of the target's depth (``disparity.alpha(target_depth)`` times the view's
        ``positions``; none at the focus distance). A calibration from before the registration was refined
        (biased towards zero by 7 %) is refused."""
        if self.registration != REGISTRATION:
            raise ConfigError("kaleidoscope calibration: made by an earlier version, whose registration read "
                              "offsets 7 % short: re-run eventfield calibrate kaleidoscope")
        measured = {(v["i"], v["j"]): v["offset"] for v in self.views}
        missing = [tuple(k) for k in ij if tuple(k) not in measured]
        if missing:
            raise ConfigError(f"kaleidoscope calibration: no registration for view {missing[0]} ({self.n}x{self.n} "
                              "views were calibrated)")
        out = np.array([measured[tuple(k)] for k in ij], dtype=np.float64)
        if self.target_depth is not None:
            ax, ay = disparity.alpha(self.target_depth)
            out -= np.stack([ax * positions[:, 0], ay * positions[:, 1]], axis=-1)
        return out

    def view_gains(self, ij) -> np.ndarray | None:
        """(K, h, w) flat-field gains of views (i, j) = ``ij``, unflipped like the views (None without a flat
        field), at least ``GAIN_FLOOR``. A file with the mean gains of a flat field but not its map (written
        before the maps were stored) is refused: applied, it would silently leave the vignetting in."""
        if self.flat_map is None:
            if self.flat_gain is not None:
                raise ConfigError("kaleidoscope calibration: holds a flat field's mean gains but not its map (made "
                                  "by an earlier version): re-run eventfield calibrate kaleidoscope --flat")
            return None
        tw, th = self.tile
        gains = {(i, j): g for i, j, _, _, _, g in _unflipped(_decode_map(self.flat_map), self.n, tw, th)}
        return np.maximum(np.stack([gains[tuple(k)] for k in ij]), GAIN_FLOOR)


def _unflipped(frame, n, tw, th):
    """(i, j, tile, flip_x, flip_y, the tile's pixels unflipped) of every view (``kaleido_optics.tiles``)."""
    from mitsuba_eventfield.plugins.kaleido_optics import tiles
    out = []
    for v in tiles(n, n * tw, n * th):
        x0, y0 = v["tile"][:2]
        t = frame[y0:y0 + th, x0:x0 + tw]
        t = t[:, ::-1] if v["flip_x"] else t
        t = t[::-1] if v["flip_y"] else t
        out.append((v["i"], v["j"], v["tile"], v["flip_x"], v["flip_y"], np.ascontiguousarray(t)))
    return out


# Every tile of a kaleidoscope images the same scene (through another sub-aperture of the main lens), so once
# unflipped and registered, each view agrees with the centre view up to the parallax of other depths. The tiles of
# an ordinary image show different parts of the scene and do not. Measured: normalised correlation of each
# registered log view with the centre one, inside a border of a fifth of the tile; the worst view of each frame:
#   kaleidoscope renders, 48-192 px films: target at the focus distance 0.99-1.00; two planes (0.6 and 1.5 m,
#   focus 1 m) 0.71-0.80, and 0.70-0.80 with a 2 mm relay aperture vignetting every seam; scenes/moving_grid
#   (96-192 px) 0.82-0.99; scenes/falling 0.63-0.87;
#   galvo frames cut into 3x3 tiles (galvo_static, fan, runner, hdr_leds, demo, moving_grid, dart; 48x36 to
#   240x180): -0.14 at most (often -1: registration moved a view by most of a tile); white noise -0.06.
# 0.4 leaves 0.3 on the kaleidoscope side and more on the other. Without the border, the vignetting at the seams
# brought the worst kaleidoscope view down to 0.38.
MIN_VIEW_CONSISTENCY = 0.4
CONSISTENCY_BORDER = 5          # the border left out: a fifth of the tile (vignetting at the seams)


def _consistency(centre: np.ndarray, view: np.ndarray, offset) -> float:
    """Normalised correlation of ``view`` moved by -offset with ``centre``, inside the border."""
    from scipy.ndimage import shift
    h, w = centre.shape
    b = max(int(np.ceil(np.max(np.abs(offset)))) + 2, min(h, w) // CONSISTENCY_BORDER)
    if min(h, w) - 2 * b < 4:
        return -1.0                 # registration moved the view by most of a tile: nothing left in common
    moved = shift(view, (-offset[1], -offset[0]), order=1, mode="nearest")
    a, c = centre[b:h - b, b:w - b], moved[b:h - b, b:w - b]
    a, c = a - a.mean(), c - c.mean()
    den = np.sqrt((a * a).sum() * (c * c).sum())
    return float((a * c).sum() / den) if den > 1e-12 else -1.0


# The window is fixed while the content moves under it, which pulls one cross-correlation towards zero shift
# (measured on 80 px tiles of a smooth texture: whole-pixel shifts of 1 and 2 px read 0.93 and 1.85). So the view
# is moved back by the offset found and registered again, the residual added: two more passes left 0.00x px.
REGISTRATION_PASSES = 3
REGISTRATION = "upsampled cross-correlation, Hann window, 3 passes"     # recorded in each calibration


def _offset(centre_prepared: np.ndarray, tile: np.ndarray, margin: int, prep) -> tuple:
    """([dx, dy], error): how far ``tile``'s content sits from the centre view's, to 1/100 px."""
    from scipy.ndimage import shift
    from skimage.registration import phase_cross_correlation
    th, tw = tile.shape
    offset, error = np.zeros(2), 1.0
    for _ in range(REGISTRATION_PASSES):
        moved = shift(tile, (-offset[1], -offset[0]), order=3, mode="nearest") if offset.any() else tile
        v = moved[margin:th - margin, margin:tw - margin]
        # the shift that registers v onto the centre (upsampled cross-correlation)
        (sy, sx), error, _ = phase_cross_correlation(centre_prepared, prep(v), upsample_factor=100,
                                                     normalization=None)
        offset = offset - (sx, sy)
        if max(abs(sx), abs(sy)) < 0.005:
            break
    return [float(offset[0]), float(offset[1])], float(error)


def register(frame: np.ndarray, tiles: dict | None = None, margin: int = 2) -> KaleidoscopeCalibration:
    """Find the tiles (unless given), undo the flips and register every view to the centre one, sub-pixel.
    Refuses (CalibrationError) a frame whose registered views do not show one scene (``MIN_VIEW_CONSISTENCY``):
    a galvo frame, a blank or a noise frame has seams only by chance."""
    frame = np.asarray(frame, dtype=np.float64)
    if not np.all(np.isfinite(frame)):
        raise CalibrationError("the frame contains NaN or infinite values")
    tiles = tiles or find_tiles(frame)
    n = tiles["x"]["n"]
    h, w = frame.shape
    tw, th = w // n, h // n
    parts = _unflipped(frame, n, tw, th)
    centre = parts[len(parts) // 2][5][margin:th - margin, margin:tw - margin]
    # Hann window on mean-free views: content entering and leaving at the borders otherwise biases the shift
    # (measured on 64 px tiles: 0.19 px without, 0.06 px with; phase normalisation was worse either way)
    window = np.outer(np.hanning(centre.shape[0]), np.hanning(centre.shape[1]))
    prep = lambda a: (a - a.mean()) * window  # noqa: E731
    views = []
    for i, j, rect, fx, fy, img in parts:
        offset, error = _offset(prep(centre), img, margin, prep)
        v = img[margin:th - margin, margin:tw - margin]
        views.append({"i": i, "j": j, "tile": rect, "flip_x": fx, "flip_y": fy, "offset": offset,
                      "error": error, "consistency": _consistency(centre, v, offset),
                      "quarter_spread_px": quarter_spread(centre, v, offset)})
    worst = min((v for v in views if (v["i"], v["j"]) != (0, 0)), key=lambda v: v["consistency"])
    if worst["consistency"] < MIN_VIEW_CONSISTENCY:
        raise CalibrationError(f"not a kaleidoscope frame: registered view ({worst['i']}, {worst['j']}) agrees with "
                               f"the centre view to {worst['consistency']:.2f} (< {MIN_VIEW_CONSISTENCY}): its "
                               f"{n}x{n} tiles do not show one scene (a galvo, blank or noise frame?)")
    warn_not_flat(views)
    seams = {axis: tiles[axis]["score"] for axis in ("x", "y") if "score" in tiles[axis]}
    return KaleidoscopeCalibration(n=n, tile=(tw, th), views=views, seam_scores=seams, registration=REGISTRATION)


def _encode_map(gain: np.ndarray) -> dict:
    """A film-sized gain map for JSON: float16 (gains of order 1 to 1e-3 of themselves), base64."""
    a = np.ascontiguousarray(np.clip(gain, 0.0, 60000.0).astype("<f2"))
    return {"shape": list(a.shape), "dtype": "float16", "base64": base64.b64encode(a.tobytes()).decode("ascii")}


def _decode_map(record: dict) -> np.ndarray:
    try:
        shape = tuple(int(v) for v in record["shape"])
        a = np.frombuffer(base64.b64decode(record["base64"], validate=True), "<f2").reshape(shape)
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(f"kaleidoscope calibration: flat_map is not readable ({e}): re-run eventfield calibrate "
                          "kaleidoscope --flat") from None
    return a.astype(np.float64)


def flat_field(calibration: KaleidoscopeCalibration, flat_frame: np.ndarray) -> np.ndarray:
    """Per-view gain maps (n*n, th, tw) from a capture of a uniform target, normalised to the centre view's mean;
    divide extracted views by them. Records each view's mean gain and the film's gain map in the calibration."""
    n, (tw, th) = calibration.n, calibration.tile
    flat = np.asarray(flat_frame, dtype=np.float64)
    if flat.ndim != 2 or flat.shape[0] < n * th or flat.shape[1] < n * tw or not np.all(np.isfinite(flat)):
        raise CalibrationError(f"the flat-field frame ({flat.shape[-1]}x{flat.shape[0]}) must be a finite image "
                               f"covering the {n}x{n} tiles of {tw}x{th} px, like the registered frame")
    flat = flat[:n * th, :n * tw]            # a bare frame's tiles are its size over n, rounded down
    parts = _unflipped(flat, n, tw, th)
    check_flat_texture([p[5] for p in parts])
    maps = np.stack([p[5] for p in parts])
    ref = maps[len(maps) // 2].mean()
    if ref <= 0:
        raise CalibrationError("the flat-field frame is black")
    gains = maps / ref
    calibration.flat_gain = [float(g.mean()) for g in gains]
    calibration.flat_map = _encode_map(flat / ref)
    return np.maximum(gains, 1e-6)
