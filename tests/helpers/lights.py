"""Lights from a chrome sphere: a rig of photos showing one beside the object, and the angles
between two sets of lights, shared by the light and photometric-stereo tests."""

from __future__ import annotations

import numpy as np
from PIL import Image

from shadeform import synth
from shadeform.light import light_from_slant_tilt


def angles(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))


def sphere_rig(folder):
    """Sixteen 16-bit photos of a matte sphere (the object) beside a chrome sphere on a matte
    table, in ``folder``: (folder, lights, object scene)."""
    rng = np.random.default_rng(4)
    lights = np.array(
        [light_from_slant_tilt(s, t) for s, t in zip(rng.uniform(15, 50, 16), rng.uniform(0, 360, 16))]
    )
    obj = synth.scene("sphere", size=120)
    for i, light in enumerate(lights):
        photo, _ = synth.chrome_sphere(light, size=260, centre=(200, 55), radius=50, background=0.4)
        photo[130:250, 10:130] = synth.render(obj.normals, obj.mask, light=light, albedo=0.8)
        Image.fromarray((photo * 65535).astype(np.uint16)).save(folder / f"{i:02d}.png")
    return folder, lights, obj
