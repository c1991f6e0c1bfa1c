"""The light direction: unit vectors toward a distant light, slant and tilt, and estimation.

Frame and angles as in ``docs/conventions.md``: x right, y up, z toward the viewer; ``(0, 0, 1)``
is a light behind the camera, ``L = (sin s cos t, sin s sin t, cos s)`` for slant ``s`` and tilt
``t``. The 2002 system fixed the light at +z; every solver here takes any light the camera can see
lit surfaces under (z > 0), and :func:`estimate_light` reads it, with ``k * albedo``, from one
image.

Layout: :mod:`~shadeform.light.vectors` (checking and converting lights),
:mod:`~shadeform.light.estimate` (:func:`estimate_light`, which asks each kind of evidence in
turn), one module per kind of evidence (:mod:`~shadeform.light.contour`,
:mod:`~shadeform.light.rings`, :mod:`~shadeform.light.relief`) and the round-feature model of a
relief (:mod:`~shadeform.light.features`). The vectors are imported here at once (the pipeline
needs :func:`as_light` at its import time, so this stays numpy-only); the estimation names are
imported on first use.

The estimators' constants were set on the synthetic scenes of ``benchmarks/bench_light.py`` and
(the ring span of :mod:`~shadeform.light.rings`) on the DiLiGenT ball: the very data that
benchmark reports, so its table is not a held-out measure. Which constant came from which scene is
inferred from when it was added; the history records no per-constant sweep. The constants added
for real photographs (the shadow-edge test of :mod:`~shadeform.light.contour`, the clipped plateau
of :mod:`~shadeform.light._evidence`, the thinnest mask of :mod:`~shadeform.light.estimate`) were
chosen on synthetic scenes or from the pixel grid, not on the real photos the benchmark reports.
"""

from __future__ import annotations

import importlib

from shadeform._deprecated import renamed_attributes
from shadeform.light.vectors import as_light, light_from_slant_tilt, parse_light, slant_tilt

# public name -> submodule that defines it, imported on first use
_LAZY = {
    "LightEstimate": "shadeform.light.estimate",
    "estimate_light": "shadeform.light.estimate",
    "ESTIMATION_CUES": "shadeform.light.estimate",
    "MIN_OBJECT_PIXELS": "shadeform.light.estimate",
    "CONFIDENCE_ANGLE": "shadeform.light.estimate",
}

__all__ = [
    "as_light",
    "light_from_slant_tilt",
    "slant_tilt",
    "parse_light",
    "LightEstimate",
    "estimate_light",
    "CONFIDENCE_ANGLE",
]


# the old name of ESTIMATION_CUES, for one release: warns each time, never cached
_renamed = renamed_attributes(
    __name__, {"ESTIMATION_METHODS": ("ESTIMATION_CUES", lambda: __getattr__("ESTIMATION_CUES"))}
)


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    return _renamed(name, stacklevel=3)


def __dir__():
    return sorted(set(globals()) | set(__all__))
