"""shadeform: recover 3D shape from photographs by shading.

One photo of a matte object under one light -> normals -> depth -> triangle mesh -> export::

    import shadeform
    image = shadeform.load_image("photo.png")
    rec = shadeform.reconstruct(image)
    shadeform.export(shadeform.to_mesh(rec, step=2), "model.wrl")

Conventions (frames, units, file formats) are on one page: ``docs/conventions.md``.
Submodules are imported lazily so that ``import shadeform`` stays fast.
"""

from __future__ import annotations

import importlib
import os

# The compiled kernels' OpenMP threads sleep when idle instead of spinning: a spinning thread
# competes with any other program for its core, and on a loaded machine the spinning made parallel
# kernels 2-3x slower with rare much worse runs (benchmarks/results/stalls.md). Read once, when
# OpenMP starts (at the first parallel kernel); a user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "InputError": "shadeform.errors",
    "load_image": "shadeform.io.images",
    "load_mask": "shadeform.io.images",
    "load_image_rgb": "shadeform.io.images",
    "read_photo": "shadeform.io.images",
    "Photo": "shadeform.io.images",
    "save_normal_map": "shadeform.io.maps",
    "load_normal_map": "shadeform.io.maps",
    "save_depth": "shadeform.io.maps",
    "load_depth": "shadeform.io.maps",
    "export": "shadeform.io.exporters",
    "available_formats": "shadeform.io.exporters",
    "available_solvers": "shadeform.solvers",
    "reconstruct": "shadeform.pipeline",
    "estimate_light": "shadeform.light",
    "LightEstimate": "shadeform.light",
    "Reconstruction": "shadeform.reconstruction",
    "to_mesh": "shadeform.mesh",
    "Mesh": "shadeform.mesh",
    "parse_regions": "shadeform.regions",
    "integrate": "shadeform.integration",
    "photometric_stereo": "shadeform.photometric",
    "PhotometricStereo": "shadeform.photometric",
    "calibrate_lights": "shadeform.light.sphere",
    "LightCalibration": "shadeform.light.sphere",
    "fuse": "shadeform.fusion",
    "close": "shadeform.fusion",
    "relief": "shadeform.solid",
    "Relief": "shadeform.solid",
    "maps": "shadeform.texture",
}
_SUBMODULES = {
    "synth",
    "metrics",
    "preprocess",
    "masks",
    "light",
    "regions",
    "solvers",
    "integration",
    "io",
    "mesh",
    "render",
    "examples",
    "photometric",
    "fusion",
    "texture",
    "solid",
}

# old names, for one release: their module warns (DeprecationWarning) when they are asked for
_DEPRECATED = {"available_methods": "shadeform.solvers"}

__all__ = sorted([*_EXPORTS, *_SUBMODULES])


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    if name in _DEPRECATED:
        return getattr(importlib.import_module(_DEPRECATED[name]), name)
    if name in _SUBMODULES:
        return importlib.import_module(f"shadeform.{name}")
    raise AttributeError(f"module 'shadeform' has no attribute {name!r}")


def __dir__():
    return __all__
