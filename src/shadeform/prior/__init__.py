"""The learned shape prior: what objects look like, from one photo and its mask.

A small network (:mod:`shadeform.prior.network`) trained only on photos the project generates
itself (:mod:`shadeform.prior.shapes`, :mod:`shadeform.prior.photos`; never on a benchmark's
photos) reads the photo as it was taken (paint, print and gloss left in) and the object's mask,
and gives a normal at every object pixel with the scale of its likely error. It ships inside the
package (``prior.onnx``) and runs on the CPU through onnxruntime; training is an extra
(``pip install 'shadeform[train]'``, ``python -m shadeform.prior.train``; ``docs/prior.md``).

The object is framed first (:class:`Window`): the square around its mask, with a margin, is
resampled to the network's size, so the prior sees every object at one scale whatever the
photo's resolution, and its normals are resampled back (a normal does not change when an
object is scaled).

Examples
--------
>>> import numpy as np
>>> from shadeform.synth import scene
>>> image, mask, truth, light = scene("sphere", size=96)[:4]  # doctest: +SKIP
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources

import numpy as np

from shadeform._checks import check_mask, shading_image
from shadeform.errors import InputError

__all__ = ["MARGIN", "Prior", "Window", "model_path", "predict", "scale_photo"]

#: Margin around the object's mask, a fraction of its larger side on each side, when framed (set
#: once, not tuned: room for a blurred outline and a mask off by a few pixels).
MARGIN = 0.06
#: The photo's brightness that reads as 1 to the network: this percentile inside the mask (a few
#: highlight pixels above it do not set the scale). SIRFS's protocol scales MIT-Berkeley's photos
#: the same way; the network divides by it anyway, so how a photo was exposed does not matter.
PERCENTILE = 99.9


@dataclass(frozen=True)
class Window:
    """The square of the photo the network sees, and the way back.

    Attributes
    ----------
    top, left : int
        The square's corner in the photo (may lie outside it: the photo is padded with zeros).
    side : int
        The square's side in photo pixels.
    size : int
        The network's side in pixels.
    """

    top: int
    left: int
    side: int
    size: int

    @classmethod
    def around(cls, mask: np.ndarray, *, size: int) -> Window:
        """The window around ``mask``'s object pixels, :data:`MARGIN` on each side."""
        rows, cols = np.nonzero(mask)
        if rows.size == 0:
            raise InputError("the mask holds no object pixel: draw or load a mask over the object")
        height, width = rows.max() - rows.min() + 1, cols.max() - cols.min() + 1
        side = max(int(np.ceil(max(height, width) * (1 + 2 * MARGIN))), 8)
        top = (rows.min() + rows.max() + 1 - side) // 2
        left = (cols.min() + cols.max() + 1 - side) // 2
        return cls(int(top), int(left), side, size)

    def cut(self, array: np.ndarray, *, order: int = 1) -> np.ndarray:
        """``array`` (H, W, ...) inside the window, resampled to ``(size, size, ...)``.

        ``order`` 1 is bilinear with anti-aliasing when shrinking; 0 is nearest (for labels).
        """
        from skimage.transform import resize

        pad = [(max(0, -self.top), max(0, self.top + self.side - array.shape[0]))]
        pad.append((max(0, -self.left), max(0, self.left + self.side - array.shape[1])))
        pad += [(0, 0)] * (array.ndim - 2)
        padded = np.pad(array, pad)
        top, left = self.top + pad[0][0], self.left + pad[1][0]
        square = padded[top : top + self.side, left : left + self.side]
        shape = (self.size, self.size) + array.shape[2:]
        return resize(
            square, shape, order=order, anti_aliasing=order > 0 and self.side > self.size, preserve_range=True
        )

    def paste(self, array: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """``array`` (size, size, ...) resampled back onto a photo of ``shape`` (bilinear between
        pixel centres, held at the ends): two small matrix products, not a resampling per pixel."""
        r0, c0 = max(self.top, 0), max(self.left, 0)
        r1, c1 = min(self.top + self.side, shape[0]), min(self.left + self.side, shape[1])
        rows = _bilinear(self.size, self.side)[r0 - self.top : r1 - self.top]
        cols = _bilinear(self.size, self.side)[c0 - self.left : c1 - self.left]
        flat = array.reshape(self.size, self.size, -1).astype(np.float64)
        grown = np.einsum("ri,ijc,sj->rsc", rows, flat, cols, optimize=True)
        out = np.zeros(tuple(shape) + array.shape[2:])
        out[r0:r1, c0:c1] = grown.reshape(grown.shape[:2] + array.shape[2:])
        return out


def _bilinear(size: int, side: int) -> np.ndarray:
    """(side, size) weights of linear interpolation from ``size`` samples to ``side`` (pixel
    centres aligned: sample ``i`` sits at ``(i + 0.5) * side / size - 0.5``)."""
    at = np.clip((np.arange(side) + 0.5) * size / side - 0.5, 0, size - 1)
    low = np.minimum(np.floor(at).astype(int), size - 2) if size > 1 else np.zeros(side, int)
    weights = np.zeros((side, size))
    t = at - low
    weights[np.arange(side), low] = 1 - t
    if size > 1:
        weights[np.arange(side), low + 1] += t
    return weights


@dataclass(frozen=True)
class Prior:
    """The network's reading of one photo.

    Attributes
    ----------
    normals : (H, W, 3) float64
        Unit normals in the camera frame (``docs/conventions.md``), NaN off the mask.
    spread : (H, W) float64
        The scale of each normal's likely error (radians; the network's learned Laplace scale),
        NaN off the mask: small where the photo settles the shape, large where it is a guess.
    """

    normals: np.ndarray
    spread: np.ndarray


def scale_photo(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The network's input brightness: ``image`` over its :data:`PERCENTILE` inside the mask,
    zero off the mask (so the background, whatever it is, never reaches the network).

    Parameters
    ----------
    image : (H, W) float
    mask : (H, W) bool

    Returns
    -------
    (H, W) float32
    """
    top = float(np.percentile(image[mask], PERCENTILE)) if mask.any() else 0.0
    scaled = np.where(mask, image / top, 0.0) if top > 0 else np.zeros(image.shape)
    return np.clip(scaled, 0.0, 2.0).astype(np.float32)


def network_input(image: np.ndarray, mask: np.ndarray, window: Window) -> np.ndarray:
    """``(2, size, size)`` float32: the scaled photo and the mask, framed by ``window``."""
    photo = window.cut(scale_photo(image, mask))
    inside = window.cut(mask.astype(np.float32)) > 0.5
    return np.stack([np.where(inside, photo, 0.0), inside]).astype(np.float32)


def model_path():
    """The shipped network (``prior.onnx`` inside the package)."""
    return resources.files(__name__).joinpath("prior.onnx")


@functools.lru_cache(maxsize=4)
def _session(path: str):
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.log_severity_level = 3
    return onnxruntime.InferenceSession(path, options, providers=["CPUExecutionProvider"])


def predict(image: np.ndarray, mask: np.ndarray, *, model=None) -> Prior:
    """The network's normals for one photo.

    Parameters
    ----------
    image : (H, W) array_like
        The photo's brightness, linear (as :func:`shadeform.load_image` gives it), paint, print
        and highlights left in.
    mask : (H, W) bool
        The object's pixels.
    model : path, optional
        An ONNX file of :mod:`shadeform.prior.network`'s layout; the shipped one by default.

    Returns
    -------
    Prior

    Raises
    ------
    InputError
        A shading image or mask the library cannot use.
    """
    image = shading_image(image)
    mask = check_mask(mask, image.shape)
    path = str(model or model_path())
    session = _session(path)
    window = Window.around(mask, size=session.get_inputs()[0].shape[2])
    x = network_input(image, mask, window)[None]
    y = session.run(None, {"x": x})[0][0].transpose(1, 2, 0)  # (S, S, 4)
    back = window.paste(y, image.shape)
    normals = back[..., :3] / np.maximum(np.linalg.norm(back[..., :3], axis=-1, keepdims=True), 1e-12)
    normals[~mask] = np.nan
    spread = np.exp(np.clip(back[..., 3], -6.0, 2.0))
    spread[~mask] = np.nan
    return Prior(normals, spread)
