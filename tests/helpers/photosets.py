"""Photo sets written as a user has them: one folder of 16-bit photos and its light_directions.txt."""

from __future__ import annotations

import numpy as np

from shadeform import synth
from shadeform.io.maps import save_gray
from shadeform.light import light_from_slant_tilt

#: Six lights: one at the camera and five around it at 30 degrees of slant.
SIX_LIGHTS = np.array(
    [[0.0, 0.0, 1.0], *(light_from_slant_tilt(30, tilt) for tilt in (0, 72, 144, 216, 288))]
)


def write_photo_set(folder, normals, mask, *, lights=SIX_LIGHTS, albedo=0.8):
    """Render ``normals`` on ``mask`` under each light (:func:`shadeform.synth.render`) into
    ``folder`` as ``000.png``, ``001.png``, ... with its ``light_directions.txt``; the photos' paths."""
    folder.mkdir(parents=True, exist_ok=True)
    photos = []
    for i, light in enumerate(np.asarray(lights, dtype=np.float64)):
        path = folder / f"{i:03d}.png"
        save_gray(synth.render(normals, mask, light=light, albedo=albedo), path, bitdepth=16)
        photos.append(path)
    np.savetxt(folder / "light_directions.txt", lights)
    return photos
