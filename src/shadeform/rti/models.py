"""Relightable images fitted to a photo set: polynomial texture maps and hemispherical harmonics.

Each pixel's brightness as a function of the light's direction, fitted by least squares over the
photos of one still camera under one light each (an RTI set), so that a viewer can relight the
object from any direction:

- **PTM** (Malzbender, Gelb, Wolters 2001): the biquadratic
  ``L(lu, lv) = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5`` of the light's projection
  ``(lu, lv)`` (its x and y). ``"ptm-rgb"`` fits each channel; ``"ptm-lrgb"`` fits one luminance
  and keeps each pixel's colour (its chroma), as PTM's LRGB format stores them.
- **HSH** (hemispherical harmonics, Gautron et al. 2004), as RTIBuilder fits them and RTIViewer
  evaluates them: the first 4 (order 2) or 9 (order 3) functions of the light's polar angle
  ``theta`` (from the camera's axis) and azimuth ``phi``, each channel on its own.

The fit is one pseudo-inverse of the (N, terms) design applied to every pixel at once. Values are
whatever the photos hold (the command line fits display values, as RTIBuilder fits its JPEGs);
directions are unit vectors toward the light, x right, y up, z toward the camera
(``docs/conventions.md``).

References
----------
.. [1] T. Malzbender, D. Gelb, H. Wolters, "Polynomial texture maps", SIGGRAPH 2001.
.. [2] P. Gautron, J. Krivanek, S. Pattanaik, K. Bouatouch, "A novel hemispherical basis for
   accurate and efficient rendering", Eurographics Symposium on Rendering 2004.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shadeform.errors import InputError

__all__ = [
    "FORMATS",
    "RelightModel",
    "display_values",
    "fit",
    "hsh_basis",
    "ptm_basis",
    "relight",
    "rms_error",
]

#: The models, by name: how many terms each fits per pixel (and channel).
FORMATS = {"ptm-lrgb": 6, "ptm-rgb": 6, "hsh2": 4, "hsh3": 9}

#: The largest polar angle HSH is evaluated at, in radians: RTIViewer clamps the light there
#: (its ``Hsh::createImage``), since the basis is only defined over the upper hemisphere.
HSH_MAX_THETA = 1.52


@dataclass(frozen=True)
class RelightModel:
    """A relightable image: per-pixel coefficients of one of :data:`FORMATS`.

    Attributes
    ----------
    kind : {"ptm-lrgb", "ptm-rgb", "hsh2", "hsh3"}
    coefficients : (terms, H, W) or (terms, H, W, 3) float32
        The terms of each pixel: the luminance's for ``"ptm-lrgb"`` (``(terms, H, W)``), each
        channel's otherwise (``(terms, H, W, 3)``).
    chroma : (H, W, 3) float32 or None
        ``"ptm-lrgb"`` only: each pixel's colour, its largest channel 1 (0 where the pixel is
        black in every photo); a pixel is ``chroma * luminance``.
    """

    kind: str
    coefficients: np.ndarray
    chroma: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the image."""
        return self.coefficients.shape[1:3]


def ptm_basis(lights) -> np.ndarray:
    """PTM's six functions ``lu^2, lv^2, lu lv, lu, lv, 1`` of each light, (N, 6)."""
    lu, lv = _unit(lights)[:, :2].T
    return np.stack([lu * lu, lv * lv, lu * lv, lu, lv, np.ones_like(lu)], axis=1)


def hsh_basis(lights, terms: int = 9) -> np.ndarray:
    """The first ``terms`` (4 or 9) hemispherical harmonics of each light, (N, terms), in the
    order and normalisation RTIViewer evaluates them (``getHSH``). ``theta`` is the angle from
    the camera's axis, clamped to :data:`HSH_MAX_THETA`; ``phi = atan2(y, x)``."""
    if terms not in (4, 9):
        raise InputError(f"hemispherical harmonics have 4 (order 2) or 9 (order 3) terms, not {terms}")
    x, y, z = _unit(lights).T
    phi = np.arctan2(y, x)
    c = np.cos(np.minimum(np.arccos(np.clip(z, -1.0, 1.0)), HSH_MAX_THETA))
    root = np.sqrt(np.maximum(c - c * c, 0.0))  # sin(theta) sqrt(cos(theta)) of the hemisphere's map
    columns = [
        np.full_like(c, 1.0 / np.sqrt(2.0 * np.pi)),
        np.sqrt(6.0 / np.pi) * np.cos(phi) * root,
        np.sqrt(3.0 / (2.0 * np.pi)) * (2.0 * c - 1.0),
        np.sqrt(6.0 / np.pi) * np.sin(phi) * root,
    ]
    if terms == 9:
        columns += [
            np.sqrt(30.0 / np.pi) * np.cos(2.0 * phi) * (c * c - c),
            np.sqrt(30.0 / np.pi) * np.cos(phi) * (2.0 * c - 1.0) * root,
            np.sqrt(5.0 / (2.0 * np.pi)) * (1.0 - 6.0 * c + 6.0 * c * c),
            np.sqrt(30.0 / np.pi) * np.sin(phi) * (2.0 * c - 1.0) * root,
            np.sqrt(30.0 / np.pi) * np.sin(2.0 * phi) * (c * c - c),
        ]
    return np.stack(columns, axis=1)


def fit(images, lights, *, kind: str = "ptm-lrgb") -> RelightModel:
    """Fit a relightable model to a photo set, by least squares per pixel.

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, 3) array_like
        The photos (a grey set is fitted as three equal channels).
    lights : (N, 3) array_like
        Direction toward each photo's light (normalised here).
    kind : {"ptm-lrgb", "ptm-rgb", "hsh2", "hsh3"}, keyword-only

    Returns
    -------
    RelightModel

    Raises
    ------
    InputError
        An unknown ``kind``, images and lights that do not match, fewer photos than the model
        has terms, or lights too alike to tell the terms apart.
    """
    if kind not in FORMATS:
        raise InputError(f"unknown RTI format {kind!r}; choose one of {', '.join(FORMATS)}")
    stack = np.asarray(images, dtype=np.float32)
    if stack.ndim == 3:
        stack = stack[..., None]
    if stack.ndim != 4 or stack.shape[3] not in (1, 3):
        raise InputError(f"images must be (N, H, W) or (N, H, W, 3), got shape {np.shape(images)}")
    count = stack.shape[0]
    lights = np.asarray(lights, dtype=np.float64)
    if lights.shape != (count, 3):
        raise InputError(f"give one light direction (x y z) per photo: {count} photos, lights {lights.shape}")
    terms = FORMATS[kind]
    if count < terms:
        raise InputError(
            f"a {kind} model has {terms} terms per pixel and needs at least {terms} photos under "
            f"different lights; the set has {count}"
        )
    design = _design(kind, lights)
    if np.linalg.matrix_rank(design, tol=1e-6 * np.abs(design).max()) < terms:
        raise InputError(
            f"the {count} lights are too alike to fit a {kind} model ({terms} terms); photograph the "
            "object under lights spread over the hemisphere"
        )
    if not np.isfinite(stack).all():
        raise InputError("the photos hold NaN or infinite values; give finite intensities")
    inverse = np.linalg.pinv(design).astype(np.float32)  # (terms, N)
    if kind != "ptm-lrgb":
        return RelightModel(kind, _colour(_solve(inverse, stack)))
    # LRGB: each photo's luminance is its colour along the pixel's chroma, a linear map; so the
    # luminance's fit is the channels' fits along the chroma (6 terms a pixel, not N photos),
    # and the chroma comes from the mean photo, one more row of the same product
    rows = np.vstack([inverse, np.full((1, count), 1.0 / count, dtype=np.float32)])
    solved = _colour(_solve(rows, stack))
    chroma = chroma_of(solved[-1])
    norm = (chroma * chroma).sum(axis=2)
    luminance = (solved[:-1] * chroma).sum(axis=3)
    np.divide(luminance, norm, out=luminance, where=norm > 0)
    return RelightModel(kind, luminance, chroma)


def chroma_of(mean: np.ndarray) -> np.ndarray:
    """Each pixel's colour, (H, W, 3), from its mean over the photos: its largest channel 1, 0
    where the pixel is black in every photo. A pixel of the LRGB model is its chroma times its
    luminance, the least-squares multiple of the chroma in each photo."""
    top = mean.max(axis=2, keepdims=True)
    return np.divide(mean, top, out=np.zeros_like(mean), where=top > 0).astype(np.float32)


def relight(model: RelightModel, light) -> np.ndarray:
    """The model lit from one direction: (H, W, 3) float32 (not clipped).

    Parameters
    ----------
    model : RelightModel
    light : (3,) array_like
        Direction toward the light, x right, y up, z toward the camera.
    """
    weights = _design(model.kind, np.asarray(light, dtype=np.float64).reshape(1, 3))
    value = np.tensordot(weights[0].astype(np.float32), model.coefficients, axes=1)
    return value[..., None] * model.chroma if model.chroma is not None else value


def rms_error(model: RelightModel, images, lights, *, mask=None) -> float:
    """Root mean square of the relit model against the photos, over every photo and channel
    (and the ``mask``'s pixels, if given): in the photos' units. Grey photos are compared on
    each of the model's three equal channels. Computed a band of rows at a time (the photos
    relit as one product with the model's terms)."""
    stack = np.asarray(images, dtype=np.float32)
    if stack.ndim == 3:
        stack = stack[..., None]
    design = _design(model.kind, lights).astype(np.float32)  # (N, terms)
    rows = stack.shape[1]
    band = max(1, 2**22 // max(1, stack[0, 0].size * len(stack)))  # about 16 MB of photos a band
    keep = None if mask is None else np.asarray(mask, dtype=bool)
    total, count = 0.0, 0
    for top in range(0, rows, band):
        part = slice(top, top + band)
        terms = model.coefficients[:, part]
        lit = np.tensordot(design, terms, axes=1)  # (N, band, W[, 3])
        if model.chroma is not None:
            lit = lit[..., None] * model.chroma[part]
        difference = lit - stack[:, part]
        if keep is not None:
            difference = difference[:, keep[part]]
        flat = difference.ravel()
        total += float(np.dot(flat, flat))
        count += difference.size
    return float(np.sqrt(total / max(count, 1)))


def display_values(images, intensities=None) -> np.ndarray:
    """A set's linear photos as RTIViewer shows a file's values: each photo divided by its
    light's strength relative to the median light (if the set gives strengths), clipped to
    [0, 1] and sRGB-encoded, as RTIBuilder fits its JPEG photos.

    Parameters
    ----------
    images : (N, H, W) or (N, H, W, C) array_like
        Linear photos.
    intensities : (N,) or (N, C) array_like, optional
        Each light's strength (per channel); a grey set's photos take their mean over channels.

    Returns
    -------
    float32 array, the shape of ``images``

    Raises
    ------
    InputError
        Strengths that are not finite and positive.
    """
    from shadeform.io.colour import srgb_encode

    values = np.asarray(images, dtype=np.float32)
    if intensities is not None:
        strength = np.asarray(intensities, dtype=np.float64)
        if not (np.isfinite(strength).all() and (strength > 0).all()):
            raise InputError("the light intensities must be finite positive numbers (each light's strength)")
        relative = strength / np.median(strength, axis=0)
        if values.ndim == 3 and relative.ndim == 2:
            relative = relative.mean(axis=1)
        # one strength per photo (and channel): photos' axis first, the channel's last
        shape = (len(values),) + (1,) * (values.ndim - relative.ndim) + relative.shape[1:]
        values = values / relative.reshape(shape).astype(np.float32)
    return srgb_encode(np.clip(values, 0.0, 1.0))


def _colour(solved: np.ndarray) -> np.ndarray:
    """A grey set's fit as three equal channels (solved once, copied after)."""
    return np.repeat(solved, 3, axis=3) if solved.shape[3] == 1 else solved


def _design(kind: str, lights) -> np.ndarray:
    """The model's functions of each light, (N, terms)."""
    return ptm_basis(lights) if kind.startswith("ptm") else hsh_basis(lights, FORMATS[kind])


def _solve(inverse: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``inverse @ values`` over the photos' axis, every pixel (and channel) at once."""
    count = values.shape[0]
    flat = inverse @ values.reshape(count, -1)
    return flat.reshape(inverse.shape[0], *values.shape[1:])


def _unit(lights) -> np.ndarray:
    lights = np.atleast_2d(np.asarray(lights, dtype=np.float64))
    lengths = np.linalg.norm(lights, axis=1, keepdims=True)
    if lights.shape[1] != 3 or not (np.isfinite(lights).all() and (lengths > 0).all()):
        raise InputError("a light direction must be three finite numbers, not all zero")
    return lights / lengths
