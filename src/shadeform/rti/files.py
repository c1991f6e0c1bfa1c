"""RTI files that RTIViewer opens: PTM 1.2 (``.ptm``, LRGB or RGB) and HSH (``.rti``).

**PTM 1.2** (Malzbender, Gelb, Wolters, "Polynomial Texture Map (.ptm) File Format", HP Labs
HPL-2001-104): ASCII lines ``PTM_1.2``, the format (``PTM_FORMAT_LRGB`` or ``PTM_FORMAT_RGB``),
the width, the height (each on its own line, as RTIViewer reads them), six scale floats, six bias
integers; then bytes, with no separators. A byte ``c`` stands for the coefficient
``(c - bias) * scale`` in 0-255 units (the polynomial gives the 8-bit value). Pixels run left to
right, rows from the **bottom** up. LRGB: the six luminance bytes of every pixel, then the ``R G
B`` bytes of every pixel (a pixel is ``rgb * L / 255``). RGB: a block of six bytes per pixel for
red, then one for green, then one for blue.

**HSH** (RTIBuilder's "universal" RTI, read by RTIViewer's ``UniversalRti``): ASCII lines
``#HSH1.2`` (a comment), ``3`` (the type: hemispherical harmonics), ``width height 3`` (colour
channels), ``terms basis-type element-size`` (``9 2 1`` for order 3, ``4 2 1`` for order 2); then
``terms`` little-endian float32 scales and ``terms`` float32 biases; then bytes: for each pixel,
left to right and rows from the **top** down, the red terms, the green terms, the blue terms. A
byte ``c`` stands for ``c / 255 * scale + bias`` (the basis gives values in 0-1).

Both quantise each term to 8 bits over its range in the image (the scales and biases are per
term, shared by the pixels and channels).
"""

from __future__ import annotations

import os

import numpy as np

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_write
from shadeform.rti.models import RelightModel

__all__ = ["SUFFIXES", "encode", "file_size", "write_rti"]

#: Which file suffix holds which models.
SUFFIXES = {".ptm": ("ptm-lrgb", "ptm-rgb"), ".rti": ("hsh3", "hsh2")}

#: HSH's basis-type field in the header (RTIViewer reads it and does not use it; RTIBuilder's
#: and Relight's files say 2).
HSH_BASIS_TYPE = 2


def write_rti(path: str | os.PathLike, model: RelightModel) -> int:
    """Write a model to the file its suffix names (``.ptm``: a PTM model, ``.rti``: an HSH
    one), atomically; the number of bytes written.

    Raises
    ------
    InputError
        A suffix that does not hold the model's kind.
    """
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if model.kind not in SUFFIXES.get(suffix, ()):
        wanted = next(s for s, kinds in SUFFIXES.items() if model.kind in kinds)
        raise InputError(f"a {model.kind} model is written to a {wanted} file, not '{os.fspath(path)}'")
    data = encode(model)
    with atomic_write(path) as handle:
        handle.write(data)
    return len(data)


def encode(model: RelightModel) -> bytes:
    """The whole file of a model (its kind decides PTM or HSH), as bytes."""
    if model.kind.startswith("ptm"):
        return _encode_ptm(model)
    return _encode_hsh(model)


def file_size(kind: str, width: int, height: int) -> int:
    """The number of bytes after the header of a ``kind`` file of ``width x height`` pixels
    (for HSH, after the text lines: the scales, the biases and the coefficients)."""
    if kind == "ptm-lrgb":
        return width * height * (6 + 3)
    if kind == "ptm-rgb":
        return width * height * 6 * 3
    terms = 9 if kind == "hsh3" else 4
    return 2 * 4 * terms + width * height * 3 * terms


def _encode_ptm(model: RelightModel) -> bytes:
    height, width = model.shape
    values = model.coefficients.astype(np.float64) * 255.0  # the 8-bit value a pixel's polynomial gives
    planes = values if values.ndim == 3 else values.transpose(0, 3, 1, 2).reshape(6, -1)  # every channel
    scale, bias = zero_exact_quantiser(planes.reshape(6, -1))
    raw = quantised_bytes(values, scale, bias)  # (6, H, W) or (6, H, W, 3)
    bottom_up = raw[:, ::-1]
    if model.kind == "ptm-lrgb":
        colour = np.clip(np.rint(model.chroma[::-1] * 255.0), 0, 255).astype(np.uint8)
        body = [bottom_up.transpose(1, 2, 0).tobytes(), colour.tobytes()]
        name = "PTM_FORMAT_LRGB"
    else:
        body = [bottom_up[..., channel].transpose(1, 2, 0).tobytes() for channel in range(3)]
        name = "PTM_FORMAT_RGB"
    header = "\n".join(
        [
            "PTM_1.2",
            name,
            str(width),
            str(height),
            " ".join(f"{s:.9g}" for s in scale),
            " ".join(map(str, bias)),
        ]
    )
    return (header + "\n").encode("ascii") + b"".join(body)


def zero_exact_quantiser(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each coefficient's (row's) scale (float) and bias (integer 0-254) such that every value
    of its plane is ``(c - bias) * scale`` for a byte ``c``: the range (and 0, so that the bias
    stays a byte) over 254 steps, the bias rounded up so that the lowest value lands in [0, 1).
    A coefficient 0 (a pixel black in every photo) is the byte ``bias`` exactly."""
    low = np.minimum(planes.min(axis=1), 0.0)
    high = np.maximum(planes.max(axis=1), 0.0)
    scale = np.where(high > low, (high - low) / 254.0, 1.0)
    bias = np.ceil(-low / scale - 1e-9).astype(np.int64)
    return scale, bias


def quantised_bytes(values: np.ndarray, scale: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """``values`` (coefficients first) as the bytes of :func:`zero_exact_quantiser`'s scales and
    biases."""
    shape = (len(values),) + (1,) * (values.ndim - 1)
    raw = np.rint(values / scale.reshape(shape) + bias.reshape(shape))
    return np.clip(raw, 0, 255).astype(np.uint8)


def _encode_hsh(model: RelightModel) -> bytes:
    terms, height, width, _ = model.coefficients.shape
    values = model.coefficients.astype(np.float64)
    flat = values.reshape(terms, -1)
    bias = flat.min(axis=1)
    span = flat.max(axis=1) - bias
    scale = np.where(span > 0, span, 1.0)
    shape = (terms, 1, 1, 1)
    raw = np.rint((values - bias.reshape(shape)) / scale.reshape(shape) * 255.0)
    raw = np.clip(raw, 0, 255).astype(np.uint8)
    # per pixel, rows from the top: the red terms, the green terms, the blue terms
    body = raw.transpose(1, 2, 3, 0).tobytes()
    header = f"#HSH1.2\n3\n{width} {height} 3\n{terms} {HSH_BASIS_TYPE} 1\n".encode("ascii")
    floats = scale.astype("<f4").tobytes() + bias.astype("<f4").tobytes()
    return header + floats + body
