"""Photometric stereo: normals and albedo from several photos taken under known lights.

With a distant light ``l_j`` (unit, toward the light, strength folded into the image) a Lambertian
pixel of albedo ``rho`` and normal ``n`` reads ``I_j = rho max(0, n . l_j)``. Where three or more
non-coplanar lights reach it, ``g = rho n`` is the least-squares solution of ``L g = I`` (Woodham
1980): ``n = g / |g|``, ``rho = |g|``.

Real objects break that model: attached and cast shadows, specular highlights and a falloff
that is not the cosine (``benchmarks/results/stereo.md``). The models (what the fit per pixel
assumes of the surface), one module each in a registry (:data:`STEREO_MODELS`, :func:`register`,
:func:`available_stereo_models`; ``photometric_stereo(model=...)``, ``shadeform stereo --model``):

- ``"bivariate"`` (the default, :mod:`.bivariate`): a low-order reflectance model per pixel
  (powers of ``n . l`` and gloss lobes round the half vector), readings it cannot explain
  weighted out by Tukey's biweight; started from the robust Lambertian normal.
- ``"robust"`` (:mod:`.lambertian`): Lambertian, each pixel's shadowed, grazing and highlighted
  readings left out by the current estimate (Barsky & Petrou 2003, Mukaigawa et al. 2007), with
  thresholds set on synthetic Blinn-Phong spheres.
- ``"least_squares"``: Woodham's fit of every reading, the baseline.

Two things no per-pixel fit can do are done over the whole set:

- **Photos that contradict the rest** (a light calibrated wrongly, the object moved: DiLiGenT's
  ``bear`` has 20 faulty first photos) are found before the fit: after a robust fit on an even
  sample of the object's pixels, a photo whose typical deleted residual (the median over its lit
  pixels of ``|I - rho n . l| / rho``, over ``1 - h`` for readings the fit used with leverage
  ``h``) is more than :data:`FAULTY` times the typical photo's (and over :data:`AGREE`)
  disagrees. If one factor on its light's strength explains the disagreement and is more than
  :data:`TOLERANCE` off, the photo is rescaled by it; if none does, it is left out.
- **No holes**: a pixel that fewer than three usable, non-coplanar lights reached (or whose fit
  counts a reading its own normal puts in shadow) still gets a normal, the best its own lit
  readings allow with its neighbours' ``g`` as a prior (each neighbour weighs as much as one
  photo); one sparse solve over all such pixels.

Each normal comes with a **confidence** in [0, 1]: the smallest eigenvalue of ``sum_j l_j l_j^T``
over the photos its fit used, over the same for every photo of the set (the share of the set's
information about the normal in its weakest direction): 1 where every photo counted, 0 where the
data fix the normal in at most two directions and the neighbours did the rest.

Colour photos are solved on their mean channel (after dividing each channel by its light's
strength); each channel's albedo is then the least-squares fit with the normals held.

References
----------
.. [1] R. J. Woodham, "Photometric method for determining surface orientation from multiple
   images", Optical Engineering 19(1), 1980.
.. [2] S. Barsky, M. Petrou, "The 4-source photometric stereo technique for three-dimensional
   surfaces in the presence of highlights and shadows", IEEE PAMI 25(10), 2003.
.. [3] Y. Mukaigawa, Y. Ishii, T. Shakunaga, "Analysis of photometric factors based on photometric
   linearization", JOSA A 24(10), 2007.
.. [4] B. Shi et al., "A benchmark dataset and evaluation for non-Lambertian and uncalibrated
   photometric stereo", IEEE PAMI 41(2), 2019 (DiLiGenT).

Modules: :mod:`.registry` (the models), :mod:`.stereo` (:func:`photometric_stereo`: the fit over
the set), :mod:`.audit` (photos that contradict the rest), :mod:`.holes` (holes filled from
neighbours), :mod:`.reconstruct` (:func:`reconstruct_stereo`: normals, then depth), and the fits:
:mod:`.lambertian`, :mod:`.bivariate`, :mod:`.uncalibrated`.
"""

from __future__ import annotations

from shadeform._deprecated import renamed_attributes
from shadeform.photometric.audit import AGREE as AGREE
from shadeform.photometric.audit import FAULTY as FAULTY
from shadeform.photometric.audit import TOLERANCE as TOLERANCE
from shadeform.photometric.lambertian import HIGHLIGHT_ANGLE as HIGHLIGHT_ANGLE
from shadeform.photometric.lambertian import ITERATIONS as ITERATIONS
from shadeform.photometric.lambertian import MIN_SHADING as MIN_SHADING
from shadeform.photometric.reconstruct import reconstruct_stereo
from shadeform.photometric.registry import (
    OLD_NAMES,
    STEREO_MODELS,
    StereoModel,
    available_methods,
    available_stereo_models,
    register,
)
from shadeform.photometric.registry import available_stereo_methods as available_stereo_methods  # warns
from shadeform.photometric.stereo import CHUNK as CHUNK
from shadeform.photometric.stereo import SAMPLE as SAMPLE
from shadeform.photometric.stereo import SLANT_SAMPLE as SLANT_SAMPLE
from shadeform.photometric.stereo import UNCALIBRATED_PIXELS as UNCALIBRATED_PIXELS
from shadeform.photometric.stereo import PhotometricStereo, photometric_stereo

__all__ = [
    "MODELS",
    "STEREO_MODELS",
    "PhotometricStereo",
    "StereoModel",
    "available_methods",
    "available_stereo_models",
    "photometric_stereo",
    "reconstruct_stereo",
    "register",
]


# the old names (METHODS, STEREO_METHODS, StereoMethod) warn, as in the registry module
_renamed = renamed_attributes(__name__, OLD_NAMES)


def __getattr__(name: str):
    # MODELS follows the registry (a model registered after import is in it)
    if name == "MODELS":
        return STEREO_MODELS.names()
    return _renamed(name, stacklevel=3)
