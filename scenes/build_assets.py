"""Build the procedural assets of the bundled scenes (committed; re-run after changing this file).

    python scenes/build_assets.py

* scenes/fan/fan.ply: a four-blade fan (hub + blades, built with trimesh), axis +z, radius 0.25 m.
* scenes/*/text.png, letters.png: 8-bit grey textures with large text and a grid (OpenCV), so edges of every
  orientation exist; scenes/falling/text.png is the same in colour (blue-grey paper, red grid, dark green text),
  so that its RGB frames carry colour the luminance events do not.
* scenes/offaxis_cards/near.png, far.png: band-limited random texture (blurred noise), so depth from focus has
  texture at every pixel of the cards.
* scenes/moving_grid/grid.png: dark lines on white, both orientations (the paper's grid experiment).
* scenes/dart/dart_foam.ply, dart_band.ply: a foam dart (2x a real one: 14 cm long) split into its light foam
  segments and its dark bands + tip, so each gets its own BSDF; axis along the flight direction.
"""
import os

import cv2
import numpy as np
import trimesh

HERE = os.path.dirname(os.path.abspath(__file__))


def fan_mesh(radius=0.25, blades=4, hub_radius=0.05, thickness=0.01) -> trimesh.Trimesh:
    parts = [trimesh.creation.cylinder(radius=hub_radius, height=thickness * 2, sections=32)]
    blade_len = radius - hub_radius * 0.6
    for i in range(blades):
        blade = trimesh.creation.box(extents=[blade_len, 0.07, thickness])
        blade.apply_translation([hub_radius * 0.6 + blade_len / 2, 0, 0])
        blade.apply_transform(trimesh.transformations.rotation_matrix(np.radians(12), [1, 0, 0]))  # pitch
        blade.apply_transform(trimesh.transformations.rotation_matrix(2 * np.pi * i / blades, [0, 0, 1]))
        parts.append(blade)
    mesh = trimesh.util.concatenate(parts)
    mesh.merge_vertices()
    return mesh


DART_DIRECTION = np.array([np.sin(np.radians(35)), 0.0, -np.cos(np.radians(35))])   # keep in dart.motion.toml


def dart_meshes(length=0.14, radius=0.013, segments=7, tip=0.02):
    """(foam, bands): alternating body segments along +z, a rounded dark tip at +z, then turned so +z points
    along DART_DIRECTION (the flight direction) and centred on the origin."""
    seg = (length - tip) / segments
    foam, bands = [], []
    for i in range(segments):
        c = trimesh.creation.cylinder(radius=radius, height=seg, sections=24)
        c.apply_translation([0, 0, -length / 2 + (i + 0.5) * seg])
        (foam if i % 2 == 0 else bands).append(c)
    cap = trimesh.creation.capsule(height=tip * 0.6, radius=radius * 1.05, count=[16, 16])
    cap.apply_translation([0, 0, length / 2 - tip / 2])
    bands.append(cap)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, DART_DIRECTION)
    turn = trimesh.transformations.rotation_matrix(np.arccos(z @ DART_DIRECTION), axis)
    out = []
    for parts in (foam, bands):
        m = trimesh.util.concatenate(parts)
        m.apply_transform(turn)
        out.append(m)
    return out


def text_texture(path, words, size=(512, 256), grid=32, colors=None):
    """``colors``: None (grey 200 / 90 / 20) or (paper, grid, text), each a grey level or a BGR triple."""
    paper, lines, ink = colors or (200, 90, 20)
    rgb = any(isinstance(c, (tuple, list)) for c in (paper, lines, ink))
    img = np.full((size[1], size[0]) + ((3,) if rgb else ()), paper, np.uint8)
    img[::grid, :] = lines
    img[:, ::grid] = lines
    font = cv2.FONT_HERSHEY_DUPLEX
    for i, word in enumerate(words):
        (w, h), _ = cv2.getTextSize(word, font, 3.0, 8)
        y = int(size[1] * (i + 1) / (len(words) + 1) + h / 2)
        cv2.putText(img, word, ((size[0] - w) // 2, y), font, 3.0, ink, 8, cv2.LINE_AA)
    cv2.imwrite(path, img)


def grid_texture(path, size=256, pitch=32, width=4):
    img = np.full((size, size), 235, np.uint8)
    for k in range(pitch // 2, size, pitch):
        img[k - width // 2:k + width // 2, :] = 25
        img[:, k - width // 2:k + width // 2] = 25
    cv2.imwrite(path, img)


def noise_texture(path, seed, size=128, blob=3.0):
    """Blurred uniform noise stretched to grey levels 40-230: texture at every scale above ``blob`` texels."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), blob)
    t = (t - t.min()) / (t.max() - t.min())
    cv2.imwrite(path, (40 + 190 * t).astype(np.uint8))


if __name__ == "__main__":
    fan_mesh().export(os.path.join(HERE, "fan", "fan.ply"))
    text_texture(os.path.join(HERE, "fan", "text.png"), ["EVENT", "FIELDS"])
    text_texture(os.path.join(HERE, "fan", "label.png"), ["CVPR"], size=(256, 102), grid=256, colors=(230, 90, 30))
    text_texture(os.path.join(HERE, "galvo_static", "letters.png"), ["CVPR"], size=(256, 256))
    text_texture(os.path.join(HERE, "galvo_static", "text.png"), ["LIGHT", "FIELD"])
    grid_texture(os.path.join(HERE, "moving_grid", "grid.png"))
    text_texture(os.path.join(HERE, "falling", "text.png"), ["SLOW", "MOTION"], size=(480, 320),
                 colors=((215, 200, 180), (60, 60, 190), (40, 110, 20)))
    text_texture(os.path.join(HERE, "hdr_leds", "text.png"), ["DARK", "ROOM"])
    for name, mesh in zip(("dart_foam", "dart_band"), dart_meshes()):
        mesh.export(os.path.join(HERE, "dart", name + ".ply"))
    text_texture(os.path.join(HERE, "runner", "shirt.png"), ["RUN", "42"], size=(256, 384), grid=64)
    text_texture(os.path.join(HERE, "runner", "wall.png"), ["TRACK", "FIELD"])
    # a low-contrast wall: the dart, not the wall, should dominate a focus measure around it
    text_texture(os.path.join(HERE, "dart", "text.png"), ["NERF", "DART"], colors=(170, 130, 95))
    os.makedirs(os.path.join(HERE, "offaxis_cards"), exist_ok=True)
    noise_texture(os.path.join(HERE, "offaxis_cards", "near.png"), seed=14)
    noise_texture(os.path.join(HERE, "offaxis_cards", "far.png"), seed=15)
    print("assets written")


def design_assets():
    """scenes/designs/static.png, moving.png: coarse band-limited noise (features of about a tenth of a card),
    coarse enough that a kaleidoscope view (a third of the film per axis) still resolves it."""
    os.makedirs(os.path.join(HERE, "designs"), exist_ok=True)
    noise_texture(os.path.join(HERE, "designs", "static.png"), seed=21, size=64, blob=3.0)
    noise_texture(os.path.join(HERE, "designs", "moving.png"), seed=22, size=64, blob=3.0)


if __name__ == "__main__":
    design_assets()
