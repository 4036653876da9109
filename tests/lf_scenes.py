"""Two-plane scenes with known depths for refocus and depth-from-focus tests."""
import math

import numpy as np

NEAR, FAR = 0.6, 1.5          # depths of the two textured planes (m)


def texture(seed, size=256, blob=3):
    """Band-limited random texture in [0.15, 1]: sharp enough for focus measures, no aliasing."""
    import cv2
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), blob)
    t = (t - t.min()) / (t.max() - t.min())
    return (0.15 + 0.85 * t).astype(np.float32)


def two_planes(mi, sensor, blank_strip=True):
    """Far plane (whole background) and a near plane on the left half; a uniform strip on the far plane gives
    a textureless region (right edge of the image)."""
    T = mi.ScalarTransform4f
    far_tex = texture(1)
    if blank_strip:
        far_tex[:, 150:] = 0.6         # u runs to world -x: world x < -0.086 m, image columns 60-80 of 80
    plane = lambda tex, z, half, x: {  # noqa: E731
        "type": "rectangle", "to_world": T().translate([x, 0, z]).rotate([0, 1, 0], 180).scale(half),
        "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex[..., None]),
                                                 "raw": True, "filter_type": "bilinear"}}}
    return {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
            "far": plane(far_tex, FAR, 0.5, 0.0),
            "near": plane(texture(2), NEAR, 0.06, 0.06)}    # left half of the view (image left = +x)


def kaleido_sensor(film=240, spp=16, **kw):
    return dict({"type": "kaleidoscope", "focal_length": 0.05, "focus_distance": 1.0,
                 "film": {"type": "hdrfilm", "width": film, "height": film, "rfilter": {"type": "box"}},
                 "sampler": {"type": "stratified", "sample_count": spp, "jitter": False}}, **kw)


def view_fov_deg(optics):
    return 2 * math.degrees(math.atan(optics["image_plane_size"][0] / 2 / optics["lens_to_image_plane"]))
