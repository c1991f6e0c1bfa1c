"""Surfaces filling the frame: a rough periodic material, and a relief of bumps made window by window."""

from __future__ import annotations

import numpy as np

from shadeform.errors import InputError
from shadeform.synth.checks import _check_size, _finite_float
from shadeform.synth.scenes import Scene, _normalise


def material_surface(size: int = 256, *, seed: int = 0, slope: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """A rough, periodic surface filling the frame (stone, plaster): for material-mode maps.

    Gaussian noise filtered to a ``1 / f^1.8`` amplitude spectrum (a fractal roughness) below a
    quarter of the sampling frequency, scaled so that the slopes' root mean square is ``slope``.

    Parameters
    ----------
    size : int, optional
        Side in pixels.
    seed : int, keyword-only
        Random seed.
    slope : float, keyword-only
        Root mean square of the height's gradient.

    Returns
    -------
    height : (size, size) float64
        Height in pixels, mean 0, periodic.
    normals : (size, size, 3) float64
        Its unit normals (spectral derivatives, so periodic too).
    """
    from shadeform.texture import spectral_normals, spectral_slopes

    size = _check_size(size)
    slope = _finite_float(slope, "slope")
    if not slope > 0:
        raise InputError(f"slope must be positive, got {slope!r}")
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(size)
    radius = np.hypot(f[:, None], f[None, :])
    amplitude = np.where(radius < 0.25, np.maximum(radius, 1.0 / size) ** -1.8, 0.0)
    amplitude[0, 0] = 0.0
    height = np.fft.ifft2(
        amplitude * (rng.normal(size=(size, size)) + 1j * rng.normal(size=(size, size)))
    ).real
    dx, dy = spectral_slopes(height)
    height = height * slope / np.sqrt(np.mean(dx * dx + dy * dy))
    return height, spectral_normals(height)


def bump_relief(
    shape: tuple[int, int],
    *,
    window: tuple[int, int, int, int] | None = None,
    spacing: float = 64.0,
    width: tuple[float, float] = (0.06, 0.09),
    seed: int = 0,
) -> Scene:
    """Gaussian bumps on a flat plate, one per cell of a jittered grid: a relief of any size.

    The relief fills the frame (every pixel is on the object) and is lit from +z. Each cell of a
    ``spacing``-pixel grid holds one bump whose top (on the pixel nearest a point within 0.1
    ``spacing`` of the cell's centre), width ``sigma`` (``width`` times ``spacing``) and height (0.5 to 1.2
    ``sigma``, slopes up to about 0.7) come from a hash of the cell and ``seed``. A bump is cut off 0.6
    ``spacing`` from its centre (6.7 ``sigma`` or more: below ``exp(-22)`` of its height), so only
    the bumps of a pixel's own and neighbouring cells reach it.
    Any ``window`` of the relief is therefore made on its own, with the same values the whole
    would have there: huge test images are written tile by tile (``benchmarks/bench_tiled.py``).

    Parameters
    ----------
    shape : (int, int)
        Rows and columns of the whole relief.
    window : (row, col, rows, cols), optional
        The part to make; the whole relief by default.
    spacing : float, keyword-only
        Grid cell size in pixels, >= 16.
    width : (float, float), keyword-only
        Least and largest ``sigma`` as fractions of ``spacing``, at most 0.09 (sparser bumps for
        smaller fractions).
    seed : int, keyword-only
        Seed of the bumps' hash.

    Returns
    -------
    Scene
        Named ``"bump_relief"``, the window's image ``n_z`` (light +z, albedo 1), an all-true
        mask, the analytic depth (z = 0 on the plate) and normals, all float64.
    """
    rows, cols = (int(v) for v in shape)
    if rows < 1 or cols < 1:
        raise InputError(f"shape must be two positive whole numbers, got {shape!r}")
    r0, c0, h, w = (0, 0, rows, cols) if window is None else (int(v) for v in window)
    if h < 1 or w < 1 or r0 < 0 or c0 < 0 or r0 + h > rows or c0 + w > cols:
        raise InputError(f"window {window!r} must lie inside the relief of shape {shape!r}")
    spacing = _finite_float(spacing, "spacing")
    if spacing < 16:
        raise InputError(f"spacing must be at least 16 pixels, got {spacing}")
    low, high = (_finite_float(v, "width") for v in width)
    if not 0 < low <= high <= 0.09:
        raise InputError(f"width must be two fractions 0 < least <= largest <= 0.09, got {width!r}")
    r = np.arange(r0, r0 + h, dtype=np.float64)[:, None]
    c = np.arange(c0, c0 + w, dtype=np.float64)[None, :]
    z = np.zeros((h, w))
    zr = np.zeros((h, w))  # dz / d row
    zc = np.zeros((h, w))  # dz / d col
    # the cells whose bumps reach the window (a bump ends, for our purpose, 0.5 spacing out)
    i_lo, i_hi = int(np.floor(r0 / spacing)) - 1, int(np.floor((r0 + h) / spacing)) + 1
    j_lo, j_hi = int(np.floor(c0 / spacing)) - 1, int(np.floor((c0 + w) / spacing)) + 1
    for i in range(i_lo, i_hi + 1):
        for j in range(j_lo, j_hi + 1):
            u = _cell_uniforms(i, j, seed)
            # tops on pixel centres: a top between pixels is seen below full brightness and the
            # eikonal solver's tolerance (1e-3) would miss narrow ones; the bump itself is made exactly
            centre_r = float(np.rint((i + 0.5 + 0.2 * (u[0] - 0.5)) * spacing))
            centre_c = float(np.rint((j + 0.5 + 0.2 * (u[1] - 0.5)) * spacing))
            sigma = (low + (high - low) * u[2]) * spacing
            height = (0.5 + 0.7 * u[3]) * sigma
            reach = 0.6 * spacing
            rs = slice(max(int(centre_r - reach) - r0, 0), min(int(centre_r + reach) + 1 - r0, h))
            cs = slice(max(int(centre_c - reach) - c0, 0), min(int(centre_c + reach) + 1 - c0, w))
            if rs.start >= rs.stop or cs.start >= cs.stop:
                continue
            dr, dc = r[rs] - centre_r, c[:, cs] - centre_c
            g = height * np.exp(-(dr * dr + dc * dc) / (2.0 * sigma * sigma))
            z[rs, cs] += g
            zr[rs, cs] -= g * dr / (sigma * sigma)
            zc[rs, cs] -= g * dc / (sigma * sigma)
    # x = col, y = -row: dz/dx = zc, dz/dy = -zr
    nx, ny, nz = _normalise(-zc, zr, np.ones_like(z))
    normals = np.stack([nx, ny, nz], axis=-1)
    mask = np.ones((h, w), dtype=bool)
    light = np.array([0.0, 0.0, 1.0])
    return Scene("bump_relief", nz.copy(), mask, z, normals, light, 1.0)


def _cell_uniforms(i: int, j: int, seed: int) -> np.ndarray:
    """Four uniform numbers in [0, 1) fixed by the cell ``(i, j)`` and ``seed``."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, int(i) & 0xFFFFFFFF, int(j) & 0xFFFFFFFF]).random(4)
