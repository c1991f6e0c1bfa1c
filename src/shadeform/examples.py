"""Shipped examples: a real photograph from an installed package, and the synthetic scenes.

Nothing is downloaded. The photograph comes from scikit-image's sample images, which are bundled
inside the scikit-image wheel (a dependency of ``shadeform``); the synthetic scenes are rendered
on the fly by :mod:`shadeform.synth`.

========================= ===================================================================
``coin``                  One silver coin (a helmeted head in relief), cropped from
                          :func:`skimage.data.coins`: a matte-ish object under one light near
                          the camera on a dark background, what the 2002 method assumes. Its
                          light is not known: it is estimated from the photo.
``synth:<scene>``         A noise-free Lambertian rendering of a :data:`shadeform.synth.SCENES`
                          scene under the light ``(0, 0, 1)``, with its true mask.
``stereo:vase``           A photo set (:data:`PHOTO_SET_EXAMPLES`): a painted vase under 12
                          lights, for photometric stereo.
``views:<object>``        A view set (:data:`VIEW_SET_EXAMPLES`): a closed synthetic object
                          (:data:`shadeform.synth.CLOSED_OBJECTS`: lumpy, waisted)
                          photographed from four sides, for a complete model fused from
                          several views.
========================= ===================================================================
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from shadeform.errors import InputError
from shadeform.synth import SCENES

__all__ = [
    "EXAMPLES",
    "PHOTO_SET_EXAMPLES",
    "VIEW_SET_EXAMPLES",
    "load_example",
    "load_photo_set_example",
    "load_view_set_example",
]

# (rows, cols) of the coin in skimage.data.coins() (303 x 384): the large helmeted head on the
# right of the third row, with a few pixels of dark background all round.
_COIN_CROP = (slice(145, 225), slice(305, 384))

#: Example name -> one-line description.
EXAMPLES: dict[str, str] = {
    "coin": (
        "photograph: one silver coin (a helmeted head in relief), 79x80 pixels cropped from "
        "scikit-image's coins() sample, light near the camera (estimated), dark background"
    ),
    **{f"synth:{name}": f"synthetic: Lambertian {name}, light (0, 0, 1), true mask" for name in SCENES},
}

#: Photo-set example name -> one-line description (several photos, for photometric stereo).
PHOTO_SET_EXAMPLES: dict[str, str] = {
    "stereo:vase": (
        "synthetic: a painted Lambertian vase under 12 known lights (slant 45 degrees all "
        "round), with attached shadows, for photometric stereo and relighting"
    ),
}

#: View-set example name -> one-line description (photos of one object from several sides, fused
#: into one closed model).
VIEW_SET_EXAMPLES: dict[str, str] = {
    "views:lumpy": (
        "synthetic: a lumpy Lambertian sphere photographed from 4 sides (turntable 0, 90, 180 and "
        "270 degrees), light from the camera, true masks, fused into one closed model"
    ),
    "views:waisted": (
        "synthetic: two Lambertian lobes joined by a waist, photographed from 4 sides, light from "
        "the camera, true masks; the front and back photos read the waist as a hill top, the side "
        "views' silhouettes settle it"
    ),
}

_SYNTH_SIZE = 256


def load_example(name: str, *, size: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Load a shipped example image and the settings it is best reconstructed with.

    Parameters
    ----------
    name : str
        A key of :data:`EXAMPLES`.
    size : int, optional, keyword-only
        Side in pixels of a synthetic scene (default 256, at least 16). Photographs have a fixed
        size; giving ``size`` for one is an error.

    Returns
    -------
    image : (H, W) float32
        Intensities in ``[0, 1]``, row 0 at the top.
    info : dict
        ``name``, ``description``, ``source`` (where the pixels come from) and the suggested
        settings: ``light`` (3-tuple, or ``"estimate"`` for a photo whose light is not known),
        ``mask`` ((H, W) bool, or None to find it
        automatically), ``filter`` (a :func:`shadeform.preprocess.parse_filter` spec or None)
        ``step`` (mesh step in pixels) and ``solver`` (a ``reconstruct`` solver).

    Raises
    ------
    InputError
        If ``name`` is not an example, or ``size`` is given for a photograph or is invalid.

    Examples
    --------
    >>> image, info = load_example("coin")
    >>> image.shape, image.dtype, info["light"]
    ((80, 79), dtype('float32'), 'estimate')
    """
    if not isinstance(name, str) or name not in EXAMPLES:
        raise InputError(f"unknown example {name!r}; choose one of: {', '.join(EXAMPLES)}")
    info: dict[str, Any] = {"name": name, "description": EXAMPLES[name]}
    if name.startswith("synth:"):
        return _synthetic(name.removeprefix("synth:"), size, info)
    if size is not None:
        raise InputError(
            f"example {name!r} is a photograph of fixed size; size only applies to synth: examples"
        )
    return _coin(info)


def _coin(info: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
    from skimage import data  # bundled in the scikit-image wheel; no download

    rows, cols = _COIN_CROP
    image = data.coins()[rows, cols].astype(np.float32) / np.float32(255)
    info.update(
        source=f"skimage.data.coins()[{rows.start}:{rows.stop}, {cols.start}:{cols.stop}]",
        # Nobody measured the light of this photo: the rim and the relief's edges place it about
        # 20 degrees off the camera, to the upper right, which a frontal light would read as shape.
        light="estimate",
        mask=None,
        filter="gaussian:1",
        step=1,
        # A low relief whose outline is a coin's edge, not an occluding contour: the 2002
        # propagation keeps the relief on a flat disc, where the photo solver (outline normals
        # in the image plane) rounds it into a dome.
        solver="propagation",
    )
    return image, info


def _synthetic(scene_name: str, size: int | None, info: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
    from shadeform.synth import scene

    if size is None:
        size = _SYNTH_SIZE
    if isinstance(size, bool) or not isinstance(size, numbers.Integral):
        raise InputError(f"size must be a whole number of pixels, got {size!r}")
    rendered = scene(scene_name, size=int(size))
    info.update(
        source=f"shadeform.synth.scene({scene_name!r}, size={int(size)})",
        light=tuple(float(v) for v in rendered.light),
        mask=np.array(rendered.mask),
        filter=None,
        step=max(1, int(size) // 128),
        solver="auto",
    )
    return rendered.image.astype(np.float32), info


def load_photo_set_example(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Load a shipped photo-set example (:data:`PHOTO_SET_EXAMPLES`).

    Returns
    -------
    images : (N, H, W, 3) float32
        Linear colour photos in ``[0, 1]``.
    lights : (N, 3) float64
        Unit directions toward each photo's light.
    mask : (H, W) bool
        The object.

    Raises
    ------
    InputError
        If ``name`` is not a photo-set example.
    """
    from shadeform.synth import render, surface

    if not isinstance(name, str) or name not in PHOTO_SET_EXAMPLES:
        raise InputError(f"unknown photo set {name!r}; choose one of: {', '.join(PHOTO_SET_EXAMPLES)}")
    _, normals, mask = surface("vase", size=_SYNTH_SIZE)
    # painted bands: three colours by height, so that relighting shows albedo and shading apart
    rows = np.arange(_SYNTH_SIZE)[:, None] * np.ones((1, _SYNTH_SIZE))
    band = (rows // 32).astype(int) % 3
    paint = np.array([[0.85, 0.55, 0.3], [0.35, 0.6, 0.8], [0.8, 0.8, 0.75]])[band]
    tilts = np.radians(np.arange(12) * 30.0)
    slant = np.radians(45.0)
    lights = np.stack(
        [np.sin(slant) * np.cos(tilts), np.sin(slant) * np.sin(tilts), np.full(12, np.cos(slant))], axis=1
    )
    shading = np.stack([render(normals, mask, light=light) for light in lights])
    images = (shading[..., None] * paint[None]).astype(np.float32)
    return images, lights, mask


def load_view_set_example(name: str) -> tuple[np.ndarray, np.ndarray, tuple[float, ...], dict[str, Any]]:
    """Load a shipped view-set example (:data:`VIEW_SET_EXAMPLES`): one object from several sides.

    Returns
    -------
    images : (N, H, W) float32
        Linear grey photos in ``[0, 1]``, one per view.
    masks : (N, H, W) bool
        Each view's true object mask.
    angles : tuple of float
        Each view's turntable angle in degrees (``docs/conventions.md``, "Turntable views").
    settings : dict
        What every view is best reconstructed with, as :func:`load_example` gives it: ``light``,
        ``filter``, ``step`` and ``solver``.

    Raises
    ------
    InputError
        If ``name`` is not a view-set example.

    Examples
    --------
    >>> images, masks, angles, settings = load_view_set_example("views:lumpy")
    >>> images.shape, angles
    ((4, 256, 256), (0.0, 90.0, 180.0, 270.0))
    """
    from shadeform.synth import TURNTABLE_ANGLES, render_views

    if not isinstance(name, str) or name not in VIEW_SET_EXAMPLES:
        raise InputError(f"unknown view set {name!r}; choose one of: {', '.join(VIEW_SET_EXAMPLES)}")
    views = render_views(name.removeprefix("views:"), TURNTABLE_ANGLES, size=_SYNTH_SIZE)
    images = np.stack([view.image for view in views]).astype(np.float32)
    masks = np.stack([view.mask for view in views])
    settings = {
        "light": tuple(float(v) for v in views[0].light),
        "filter": None,
        "step": max(1, _SYNTH_SIZE // 128),
        "solver": "auto",
    }
    return images, masks, tuple(float(view.angle) for view in views), settings
