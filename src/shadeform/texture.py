"""Texture maps from a reconstruction, for texture artists: normal, height, ambient occlusion and
curvature maps, each an image in [0, 1] the size of the photo.

- **Normal map** ``RGB = (n + 1) / 2`` in the camera frame: OpenGL convention (green = +y, up in
  the image; Blender, Unity, glTF) or DirectX (green flipped: Unreal, 3ds Max).
- **Height** (displacement) map: the depth over the object, lowest 0, highest 1; its range in
  pixels is ``nanmax(depth) - nanmin(depth)`` (what a displacement strength of 1 stands for).
- **Ambient occlusion**, horizon-based, from the height field: along each of :data:`DIRECTIONS`
  azimuths the horizon's elevation ``h`` over the pixel (the steepest rise to the object's
  points within ``reach`` pixels); a height field lit by a uniform sky receives, from that
  azimuth's slice, the cosine-weighted visible fraction ``cos^2 h`` (``h > 0``; 1 when nothing
  rises above the tangent plane's horizontal). The map is the mean over azimuths: 1 unoccluded,
  toward 0 in deep cavities (Bavoil et al. 2008 for screen space; here exact on the height
  field up to the sampling along each azimuth).
- **Curvature**: the mean curvature's sum of principal curvatures from the normals,
  ``k = d n_x / dx + d n_y / dy`` (1/pixel; ``2 / R`` on a sphere of radius ``R``, positive
  convex), shown as ``0.5 + 0.5 tanh(k / s)``: 0.5 flat, brighter convex, darker cavities, with
  ``s`` the 98th percentile of ``|k|`` over the object (the map uses its range whatever the
  object's size; :func:`curvature` gives ``k`` itself).

Outside the object the maps hold what a flat, open surface would: normal ``(0, 0, 1)``,
height 0, occlusion 1, curvature 0.5.

**Material mode** (:func:`material`): a photo of a textured surface filling the frame (stone,
bark, fabric), no outline. The lighting's large-scale variation (a gradient across the frame, a
flash's fall-off) is removed by dividing out a quadratic fitted to the log image; the periodic
component of what remains (Moisan's periodic plus smooth decomposition) leaves no seams at the
frame's edges; and the height comes from the fine-scale shading by linear shape from shading
(Pentland 1990): for small slopes, ``I / mean(I) - 1 = -(l_x h_x + l_y h_y) / l_z``, solved
for ``h`` in the Fourier domain. The shading says nothing at first order about slopes across
the light, nor anything about the light's side (a bump lit from the left looks like a pit lit
from the right; exactly so for Lambertian shading, whatever the slopes): the light's axis is read
from the shading gradients' dominant direction, its side is the one nearer to above, slightly
left (:data:`PRIOR_TILT`: the prior people themselves use, Sun and Perona 1998; photos are mostly
lit from above), and its slant (which scales the relief) is 45 degrees unless given. Texture tools instead take the brightness
itself for height, which under an oblique light is the slope along the light, not the height
(``benchmarks/results/material.md`` compares the two against rendered surfaces, and
``material-real.md`` on patches of real photos with measured normals, where it is far weaker).

References
----------
.. [1] L. Bavoil, M. Sainz, R. Dimitrov, "Image-space horizon-based ambient occlusion",
   SIGGRAPH 2008 talks.
.. [2] A. P. Pentland, "Linear shape from shading", IJCV 4, 1990.
.. [3] L. Moisan, "Periodic plus smooth image decomposition", J. Math. Imaging Vis. 39, 2011.
.. [4] J. Sun, P. Perona, "Where is the sun?", Nature Neuroscience 1(3), 1998.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numba import prange
from scipy import ndimage

from shadeform.errors import InputError

__all__ = [
    "ALBEDO",
    "DIRECTIONS",
    "LEGEND",
    "MAPS",
    "Material",
    "ambient_occlusion",
    "curvature",
    "legend",
    "maps",
    "material",
]

#: Each map's bits per sample and legend (what its values mean): the files' README and the app's captions.
LEGEND = {
    "normal_opengl": (16, "normal map, OpenGL convention (green up): Blender, Unity, glTF"),
    "normal_directx": (16, "normal map, DirectX convention (green down): Unreal, 3ds Max"),
    "height": (16, "height / displacement: black lowest, white highest{range}"),
    "ambient_occlusion": (8, "ambient occlusion: white open sky, dark cavities"),
    "curvature": (8, "curvature: mid-grey flat, brighter convex edges, darker cavities"),
}
ALBEDO = (8, "albedo: the photo with its shading and uneven lighting divided out")
#: A photo set's albedo map, from its photometric stereo (:func:`albedo_map`).
STEREO_ALBEDO = (16, "albedo: the surface's own colour read by the photometric stereo, linear{white}")
#: The albedo map's white: this percentile of the object's albedo (a few specks may clip).
ALBEDO_WHITE_PERCENTILE = 99.5


def legend(
    relief_px: float | None = None, *, albedo: str | None = None, white: float | None = None
) -> dict[str, tuple[int, str]]:
    """Each map's bits per sample and legend line (:data:`LEGEND`), the height's with its range in
    pixels when known: ``shadeform maps`` and the app write it beside the maps. ``albedo``:
    ``"material"`` adds the material mode's albedo (:data:`ALBEDO`), ``"stereo"`` a photo set's
    (:data:`STEREO_ALBEDO`, with its ``white`` when known)."""
    shown = "" if relief_px is None else f" ({relief_px:.3g} px of relief)"
    every = dict(LEGEND)
    if albedo is not None:
        every["albedo"] = {"material": ALBEDO, "stereo": STEREO_ALBEDO}[albedo]
    white_text = "" if white is None else f", white = {white:.4g} ({ALBEDO_WHITE_PERCENTILE:g}th percentile)"
    return {name: (bits, text.format(range=shown, white=white_text)) for name, (bits, text) in every.items()}


#: Azimuths the occlusion is averaged over (every 22.5 degrees); not swept.
DIRECTIONS = 16
#: The percentile of ``|k|`` that the curvature map's ``tanh`` is scaled to; not swept.
CURVATURE_PERCENTILE = 98.0
#: The maps :func:`maps` returns, in order.
MAPS = ("normal_opengl", "normal_directx", "height", "ambient_occlusion", "curvature")
#: Material mode: the light's slant (degrees) when it is not given; it scales the relief.
MATERIAL_SLANT = 45.0
#: Material mode: of the two sides of the light's axis read from a photo, the one nearer this
#: tilt (degrees, from +x toward +y: up and 12 degrees to the left, the light people assume,
#: Sun and Perona 1998).
PRIOR_TILT = 102.0
#: Material mode: Tikhonov weight on the height's gradient, relative to the shading's own
#: weight, which damps the frequencies the light barely sees (within about 6 degrees of across
#: it); not swept.
MATERIAL_DAMPING = 0.01


def maps(reconstruction, *, reach: float | None = None) -> dict[str, np.ndarray]:
    """Every texture map of a reconstruction.

    Parameters
    ----------
    reconstruction : Reconstruction
        From :func:`shadeform.reconstruct` (or any object with ``normals`` (H, W, 3), ``depth``
        (H, W) and ``mask`` (H, W)).
    reach : float, optional
        How far (pixels) the occlusion looks for occluders; default the radius of the largest
        disc inside the object (:func:`default_reach`), so it follows the object's size.

    Returns
    -------
    dict of str to ndarray
        ``normal_opengl``, ``normal_directx`` (H, W, 3); ``height``, ``ambient_occlusion``,
        ``curvature`` (H, W); all float64 in [0, 1] (:data:`MAPS`). A reconstruction whose albedo
        is per pixel (a photo set's photometric stereo; one photo's is one number) adds
        ``albedo`` (H, W) or (H, W, 3) (:func:`albedo_map`).
    """
    normals, depth, mask = _check(reconstruction.normals, reconstruction.depth, reconstruction.mask)
    opengl = np.where(mask[..., None], (normals + 1.0) / 2.0, [0.5, 0.5, 1.0])
    directx = opengl.copy()
    directx[..., 1] = 1.0 - directx[..., 1]
    low, high = np.nanmin(depth[mask]), np.nanmax(depth[mask])
    height = np.where(mask, (depth - low) / (high - low) if high > low else 0.0, 0.0)
    k = curvature(normals, mask)
    scale = np.percentile(np.abs(k[mask]), CURVATURE_PERCENTILE)
    shown = 0.5 + 0.5 * np.tanh(k / scale) if scale > 0 else np.full(k.shape, 0.5)
    made = {
        "normal_opengl": opengl,
        "normal_directx": directx,
        "height": height,
        "ambient_occlusion": ambient_occlusion(depth, mask, reach=reach),
        "curvature": np.where(mask, shown, 0.5),
    }
    albedo = np.asarray(getattr(reconstruction, "albedo", 0.0), dtype=np.float64)
    if albedo.ndim >= 2:
        made["albedo"] = albedo_map(albedo, mask)[0]
    return made


def albedo_map(albedo: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """A per-pixel albedo as an image: its :data:`ALBEDO_WHITE_PERCENTILE` on the object white,
    0 off it, and the value that became white.

    Parameters
    ----------
    albedo : (H, W) or (H, W, 3) float
        Linear, any scale (photometric stereo's: the light's strength times the surface's).
        Three equal channels (grey photos) give a grey map.
    mask : (H, W) bool

    Returns
    -------
    (H, W) or (H, W, 3) float64 in [0, 1], float
    """
    albedo = np.nan_to_num(np.asarray(albedo, dtype=np.float64))
    if (
        albedo.ndim == 3
        and np.array_equal(albedo[..., 0], albedo[..., 1])
        and np.array_equal(albedo[..., 0], albedo[..., 2])
    ):
        albedo = albedo[..., 0]
    values = np.where(mask if albedo.ndim == 2 else mask[..., None], albedo, 0.0)
    white = float(np.percentile(values[mask], ALBEDO_WHITE_PERCENTILE)) if mask.any() else 0.0
    return np.clip(values / white, 0.0, 1.0) if white > 0 else values, white


def default_reach(mask: np.ndarray) -> float:
    """The radius (pixels) of the largest disc inside ``mask``: the occlusion's default reach."""
    return max(1.0, float(ndimage.distance_transform_edt(np.pad(mask, 1)).max()))


def curvature(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The sum of the principal curvatures ``k = d n_x / dx + d n_y / dy`` (H, W), 1/pixel,
    positive where the surface is convex toward the viewer; 0 outside ``mask`` and where a
    neighbour needed for the central differences is off the object."""
    normals, mask = np.asarray(normals, dtype=np.float64), np.asarray(mask, dtype=bool)
    # x = column, y = -row (docs/conventions.md)
    k = np.gradient(normals[..., 0], axis=1) - np.gradient(normals[..., 1], axis=0)
    return np.where(mask & np.isfinite(k), k, 0.0)


def ambient_occlusion(
    depth: np.ndarray, mask: np.ndarray, *, reach: float | None = None, directions: int = DIRECTIONS
) -> np.ndarray:
    """Horizon-based ambient occlusion of a height field (module docstring): (H, W) in [0, 1],
    1 outside ``mask``.

    Along each azimuth the horizon is sought at distances growing by ``sqrt(2)`` from one pixel
    to ``reach`` (about 2 log2(reach) samples, depth read bilinearly from object pixels): fine
    near the pixel, where occluders matter most, and the cost grows with the log of the reach.
    """
    mask = np.asarray(mask, dtype=bool)
    depth = np.where(mask, np.asarray(depth, dtype=np.float64), np.nan)
    reach = default_reach(mask) if reach is None else float(reach)
    if not (np.isfinite(reach) and reach >= 1):
        raise InputError(f"the occlusion's reach must be at least 1 pixel, got {reach!r}")
    if int(directions) != directions or directions < 1:
        raise InputError(f"directions must be a whole number >= 1, got {directions!r}")
    out = np.ones(depth.shape)
    _occlusion_kernel(depth, mask, _distances(reach), _azimuths(int(directions)), out)
    return out


def _distances(reach: float) -> np.ndarray:
    steps = [1.0]
    while steps[-1] * np.sqrt(2.0) <= reach:
        steps.append(steps[-1] * np.sqrt(2.0))
    return np.array(steps)


def _azimuths(count: int) -> np.ndarray:
    angles = 2 * np.pi * np.arange(count) / count
    return np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (column, row) steps


def ambient_occlusion_reference(depth, mask, *, reach, directions=DIRECTIONS):
    """:func:`ambient_occlusion` one pixel, azimuth and sample at a time in plain Python (slow,
    obviously correct: the compiled kernel is tested against it)."""
    depth = np.where(mask, np.asarray(depth, dtype=np.float64), np.nan)
    out = np.ones(depth.shape)
    for r, c in zip(*np.nonzero(mask)):
        total = 0.0
        for dc, dr in _azimuths(directions):
            rise = 0.0  # tan of the horizon's elevation, never below the horizontal
            for t in _distances(reach):
                z = _bilinear_reference(depth, r + t * dr, c + t * dc)
                if np.isfinite(z):
                    rise = max(rise, (z - depth[r, c]) / t)
            total += 1.0 / (1.0 + rise * rise)  # cos^2 of the elevation
        out[r, c] = total / directions
    return out


def _bilinear_reference(depth, row, col):
    """Bilinear depth at ``(row, col)``, NaN if any of the four pixels is off the object."""
    r0, c0 = int(np.floor(row)), int(np.floor(col))
    if r0 < 0 or c0 < 0 or r0 + 1 >= depth.shape[0] or c0 + 1 >= depth.shape[1]:
        return np.nan
    fr, fc = row - r0, col - c0
    patch = depth[r0 : r0 + 2, c0 : c0 + 2]
    return float(np.array([1 - fr, fr]) @ patch @ np.array([1 - fc, fc]))


@numba.njit(cache=True, parallel=True)
def _occlusion_kernel(depth, mask, distances, azimuths, out):
    rows, cols = depth.shape
    for r in prange(rows):
        for c in range(cols):
            if not mask[r, c]:
                continue
            here = depth[r, c]
            total = 0.0
            for a in range(azimuths.shape[0]):
                dc, dr = azimuths[a, 0], azimuths[a, 1]
                rise = 0.0
                for t in distances:
                    row, col = r + t * dr, c + t * dc
                    r0, c0 = int(np.floor(row)), int(np.floor(col))
                    if r0 < 0 or c0 < 0 or r0 + 1 >= rows or c0 + 1 >= cols:
                        break  # the rest of this azimuth is off the image too
                    fr, fc = row - r0, col - c0
                    z = (1 - fr) * ((1 - fc) * depth[r0, c0] + fc * depth[r0, c0 + 1]) + fr * (
                        (1 - fc) * depth[r0 + 1, c0] + fc * depth[r0 + 1, c0 + 1]
                    )
                    if z == z:  # all four on the object (NaN otherwise)
                        rise = max(rise, (z - here) / t)
                total += 1.0 / (1.0 + rise * rise)
            out[r, c] = total / azimuths.shape[0]


def _check(normals, depth, mask):
    normals = np.asarray(normals, dtype=np.float64)
    depth = np.asarray(depth, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    if normals.shape != depth.shape + (3,) or mask.shape != depth.shape or depth.ndim != 2:
        raise InputError(
            f"normals (H, W, 3), depth and mask (H, W) must match, got {normals.shape}, {depth.shape}, "
            f"{mask.shape}"
        )
    mask = mask & np.isfinite(depth) & np.isfinite(normals).all(axis=2)
    if not mask.any():
        raise InputError("the reconstruction has no object pixels to make maps of")
    return normals, depth, mask


@dataclass(frozen=True)
class Material:
    """The maps of a photo of a material (:func:`material`).

    Attributes
    ----------
    maps : dict of str to ndarray
        :data:`MAPS` as :func:`maps` makes them, and ``albedo`` (H, W) or (H, W, 3): the photo
        with the shading and the lighting's large-scale variation divided out, in [0, 1].
    light : (3,) float64
        The light direction used.
    light_estimated : bool
        Whether the light's tilt was read from the photo (up to its side, taken nearer
        :data:`PRIOR_TILT`; its slant is then :data:`MATERIAL_SLANT`): if the relief comes out inverted, give the
        light with its tilt turned by 180 degrees.
    """

    maps: dict
    light: np.ndarray
    light_estimated: bool


def material(image: np.ndarray, *, light=None, tile: bool = False, reach: float | None = None) -> Material:
    """Texture maps of a photo of a textured surface that fills the frame (module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like
        Linear intensities (:func:`shadeform.load_image_rgb` or :func:`shadeform.load_image`);
        colour is used for the albedo map, its luma for the shape.
    light : (3,) array_like, optional
        Direction toward the light in the camera frame; default: tilt read from the photo, slant
        :data:`MATERIAL_SLANT`.
    tile : bool, keyword-only
        Make the albedo map tile seamlessly too (the shape maps always do).
    reach : float, optional
        The occlusion's reach in pixels (:func:`ambient_occlusion`); default a sixteenth of the
        shorter side.

    Returns
    -------
    Material
    """
    from shadeform.light import as_light

    pixels = np.asarray(image, dtype=np.float64)
    if pixels.ndim not in (2, 3) or (pixels.ndim == 3 and pixels.shape[2] != 3) or min(pixels.shape[:2]) < 8:
        raise InputError(f"a material photo must be (H, W) or (H, W, 3), at least 8x8, got {pixels.shape}")
    if not np.isfinite(pixels).all() or (pixels < 0).any():
        raise InputError("the photo has negative, NaN or infinite values; give linear intensities")
    gray = pixels if pixels.ndim == 2 else pixels @ np.array([0.2126, 0.7152, 0.0722])
    if np.count_nonzero(gray > 0) < gray.size / 2:
        raise InputError(
            "the photo is mostly black; a material photo must show the lit surface across the frame"
        )
    lighting = _lighting(gray)
    shading = periodic_component(gray / lighting)
    shading = shading / shading.mean() - 1.0
    estimated = light is None
    if estimated:
        tilt = _tilt_axis(shading)
        if np.cos(tilt - np.radians(PRIOR_TILT)) < 0:  # the other side of the axis
            tilt += np.pi
        light = np.array([np.cos(tilt), np.sin(tilt), 1 / np.tan(np.radians(MATERIAL_SLANT))])
    light = as_light(light)
    if light[0] == 0 and light[1] == 0:
        raise InputError(
            "a light straight from the viewer shows no slopes at first order; give an oblique light "
            "(--slant, --tilt) or a photo lit from one side"
        )
    height = linear_shading_height(shading, light)
    mask = np.ones(gray.shape, dtype=bool)
    reach = max(1.0, min(gray.shape) / 16) if reach is None else reach
    normals = spectral_normals(height)
    shape_maps = maps(_Surface(normals, height, mask), reach=reach)
    predicted = np.clip(normals @ light, 1e-3, None) / light[2]  # shading relative to a flat patch
    source = pixels / (lighting if pixels.ndim == 2 else lighting[..., None])
    if tile:
        source = (
            periodic_component(source)
            if source.ndim == 2
            else np.dstack([periodic_component(source[..., c]) for c in range(3)])
        )
    albedo = source / (predicted if source.ndim == 2 else predicted[..., None])
    albedo = np.clip(albedo / (2 * np.median(albedo)), 0.0, 1.0)  # the median albedo at mid-grey
    return Material({**shape_maps, "albedo": albedo}, light, estimated)


@dataclass(frozen=True)
class _Surface:
    normals: np.ndarray
    depth: np.ndarray
    mask: np.ndarray


def _lighting(gray: np.ndarray) -> np.ndarray:
    """The lighting's large-scale variation: ``exp`` of a quadratic in ``x, y`` fitted to the
    log intensities (least squares over the lit pixels)."""
    rows, cols = gray.shape
    y, x = np.mgrid[:rows, :cols]
    x, y = x / cols - 0.5, y / rows - 0.5
    terms = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    lit = gray > 0
    coefficients, *_ = np.linalg.lstsq(terms[lit], np.log(gray[lit]), rcond=None)
    return np.exp(terms @ coefficients)


def periodic_component(image: np.ndarray) -> np.ndarray:
    """Moisan's periodic component of ``image`` (H, W): the image less the smooth field whose
    Laplacian is the jump across the frame's opposite edges, so that it tiles without seams and
    its Fourier transform has no cross of edge artefacts."""
    u = np.asarray(image, dtype=np.float64)
    rows, cols = u.shape
    jump = np.zeros_like(u)
    jump[0, :] += u[-1, :] - u[0, :]
    jump[-1, :] += u[0, :] - u[-1, :]
    jump[:, 0] += u[:, -1] - u[:, 0]
    jump[:, -1] += u[:, 0] - u[:, -1]
    laplacian = (
        2 * np.cos(2 * np.pi * np.fft.fftfreq(rows))[:, None]
        + 2 * np.cos(2 * np.pi * np.fft.fftfreq(cols))
        - 4
    )
    laplacian[0, 0] = 1.0
    smooth = np.fft.fft2(jump) / laplacian
    smooth[0, 0] = 0.0
    return u - np.fft.ifft2(smooth).real


def _frequencies(shape):
    """Angular frequencies along rows and columns (radians per pixel), broadcastable."""
    rows, cols = shape
    return 2 * np.pi * np.fft.fftfreq(rows)[:, None], 2 * np.pi * np.fft.fftfreq(cols)[None, :]


def linear_shading_height(shading: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Pentland's linear shape from shading: the periodic height (H, W) in pixels, mean 0, whose
    slopes explain ``shading = I / mean(I) - 1 = -(l_x h_x + l_y h_y) / l_z`` in least squares,
    with :data:`MATERIAL_DAMPING` on the gradient (``x`` = column, ``y`` = -row)."""
    a = np.asarray(light[:2], dtype=np.float64) / light[2]
    w_row, w_col = _frequencies(shading.shape)
    # d/dx = i w_col, d/dy = -d/drow = -i w_row
    response = -1j * (a[0] * w_col - a[1] * w_row)
    damping = MATERIAL_DAMPING * (a @ a) * (w_row**2 + w_col**2)
    spectrum = np.conj(response) * np.fft.fft2(shading) / (np.abs(response) ** 2 + damping + 1e-300)
    spectrum[0, 0] = 0.0
    return np.fft.ifft2(spectrum).real


def spectral_slopes(height: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slopes ``(dz/dx, dz/dy)`` (each (H, W)) of a periodic height field by spectral
    derivatives (``x`` = column, ``y`` = -row)."""
    w_row, w_col = _frequencies(height.shape)
    spectrum = np.fft.fft2(height)
    return np.fft.ifft2(1j * w_col * spectrum).real, -np.fft.ifft2(1j * w_row * spectrum).real


def spectral_normals(height: np.ndarray) -> np.ndarray:
    """Unit normals (H, W, 3) of a periodic height field (:func:`spectral_slopes`)."""
    slope_x, slope_y = spectral_slopes(height)
    normals = np.stack([-slope_x, -slope_y, np.ones_like(height)], axis=-1)
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def _tilt_axis(shading: np.ndarray) -> float:
    """The light's tilt (radians, up to a half turn) as the dominant direction of the shading's
    gradients: under a light of tilt ``t`` the shading varies with the slope along ``t`` only."""
    gx = np.gradient(shading, axis=1)
    gy = -np.gradient(shading, axis=0)
    tensor = np.array([[np.sum(gx * gx), np.sum(gx * gy)], [np.sum(gx * gy), np.sum(gy * gy)]])
    _, vectors = np.linalg.eigh(tensor)
    return float(np.arctan2(vectors[1, 1], vectors[0, 1]))
