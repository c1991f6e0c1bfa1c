"""A relightable image for the web: the folder Relight's viewer and OpenLIME read.

Relight (Ponchio, Corsini, Scopigno, "Relight: a compact and accurate RTI representation for the
web", Graphical Models 2019; the open-source ``relight`` and ``openlime`` viewers) keeps an RTI
as a folder a web server hands out as it is:

- ``info.json``: ``width``, ``height``, ``format`` (``"jpg"``), ``type`` (``"ptm"`` or
  ``"hsh"``), ``colorspace`` (``"rgb"``: every channel its own terms; ``"lrgb"``: one luminance
  and a colour per pixel), ``lights`` (the photos' directions, x y z flattened; informative for
  these bases), ``nplanes`` (coefficient planes), ``quality`` (the JPEGs'), and ``materials``,
  one entry holding ``scale`` and ``bias``: one number per plane;
- ``plane_0.jpg`` ... ``plane_<n-1>.jpg``, ``n = ceil(nplanes / 3)``: three planes per JPEG, in
  its R, G and B, rows from the top. A byte ``c`` of plane ``p`` stands for the coefficient
  ``(c / 255 - bias[p]) * scale[p]``.

How the viewers read the planes (OpenLIME's ``ShaderRTI``, Relight's ``legacy_rti``/``convert_rti``):

- **HSH**, ``rgb``: JPEG ``j`` holds term ``j`` (the order RTIViewer evaluates, as
  :func:`~shadeform.rti.models.hsh_basis`) of the red, green and blue channels; ``nplanes`` is
  3 x the terms (27 or 12).
- **PTM**, ``rgb``: the same with the six terms in Relight's order ``1, x, y, x^2, xy, y^2`` (a
  ``.ptm`` file's is ``x^2, y^2, xy, x, y, 1``); ``nplanes`` 18.
- **PTM**, ``lrgb``: JPEG 0 holds the pixel's colour (scale 1, bias 0), JPEGs 1 and 2 the
  luminance's six terms in Relight's order; ``nplanes`` 9. A pixel is colour x luminance.

The coefficients give display values in 0-1, as the ``.ptm``/``.rti`` files do. Each term is
quantised over its range in the image (and 0, which gets a byte of its own, so that a background
black in every photo stays black), one scale and bias shared by the three channels as Relight's
own fitter writes them (its converter back to ``.rti`` and ``.ptm`` reads one per term). The
JPEGs hold three unrelated coefficients, so they are stored as RGB, not YCbCr (an Adobe marker
says so, as Relight's converter from ``.ptm``/``.rti`` writes them; every channel gets the fine
quantisation of a JPEG's luma), without chroma subsampling, at Relight's default quality (95):
on a colour test scene that halves the planes' error against YCbCr (0.95 levels RMS against 2.2).
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path

import numpy as np

from shadeform.errors import InputError
from shadeform.io.atomic import atomic_folder
from shadeform.rti.files import quantised_bytes, zero_exact_quantiser
from shadeform.rti.models import FORMATS, RelightModel

__all__ = ["QUALITY", "check_web_folder", "web_files", "web_set", "write_web"]

#: The JPEGs' quality: relight-cli's default (``-q 95``).
QUALITY = 95

#: Where each of Relight's PTM terms (``1, x, y, x^2, xy, y^2``) is in a model's (a ``.ptm``
#: file's order, ``x^2, y^2, xy, x, y, 1``).
PTM_ORDER = (5, 3, 4, 0, 2, 1)


def web_files(kind: str) -> list[str]:
    """The files of a web set of a ``kind`` model: ``info.json`` and its JPEG planes."""
    return ["info.json"] + [f"plane_{j}.jpg" for j in range(_jpegs(kind))]


def web_set(model: RelightModel, lights=None, *, quality: int = QUALITY) -> tuple[dict, list[np.ndarray]]:
    """A model as Relight's web format holds it: ``info.json``'s content and the JPEG planes.

    Parameters
    ----------
    model : RelightModel
    lights : (N, 3) array_like, optional
        The photos' light directions, recorded in ``info.json``.
    quality : int, keyword-only
        The JPEG quality recorded (1-100).

    Returns
    -------
    info : dict
    planes : list of (H, W, 3) uint8
        The images of ``plane_0.jpg``, ``plane_1.jpg``, ..., rows from the top.
    """
    height, width = model.shape
    values = model.coefficients.astype(np.float64)
    if model.kind == "ptm-lrgb":
        terms = values[list(PTM_ORDER)]  # (6, H, W)
        raw, scale, bias = _quantise(terms)
        colour = np.clip(np.rint(model.chroma * 255.0), 0, 255).astype(np.uint8)
        planes = [colour, np.stack(list(raw[:3]), axis=-1), np.stack(list(raw[3:]), axis=-1)]
        scales, biases = [1.0] * 3 + list(scale), [0.0] * 3 + list(bias)
    else:
        if model.kind == "ptm-rgb":
            values = values[list(PTM_ORDER)]
        raw, scale, bias = _quantise(values)  # (terms, H, W, 3)
        planes = list(raw)
        scales, biases = list(np.repeat(scale, 3)), list(np.repeat(bias, 3))
    info = {
        "width": int(width),
        "height": int(height),
        "format": "jpg",
        "type": "ptm" if model.kind.startswith("ptm") else "hsh",
        "colorspace": "lrgb" if model.kind == "ptm-lrgb" else "rgb",
        "nplanes": _nplanes(model.kind),
        "quality": int(quality),
        "materials": [{"scale": [float(s) for s in scales], "bias": [float(b) for b in biases]}],
    }
    if lights is not None:
        directions = np.asarray(lights, dtype=np.float64)
        directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        info["lights"] = [round(float(v), 6) for v in directions.ravel()]
    return info, planes


def write_web(folder: str | os.PathLike, model: RelightModel, *, lights=None, quality: int = QUALITY) -> int:
    """Write a model as Relight's web format into ``folder``, as a whole (the folder appears
    complete or not at all, replacing an earlier web set there); the number of bytes written.

    Raises
    ------
    InputError
        A ``folder`` that is a file, or an existing folder that holds other files than a web
        set's (:func:`check_web_folder`); a ``quality`` outside 1-100.
    """
    from PIL import Image

    if not 1 <= int(quality) <= 100:
        raise InputError(f"the JPEG quality must be 1 to 100, not {quality}")
    check_web_folder(folder)
    info, planes = web_set(model, lights, quality=quality)
    total = 0
    with atomic_folder(folder) as temporary:
        text = json.dumps(info, indent=1) + "\n"
        (temporary / "info.json").write_text(text, encoding="utf-8")
        total += len(text.encode("utf-8"))
        for j, plane in enumerate(planes):
            buffer = io.BytesIO()
            Image.fromarray(plane, "RGB").save(
                buffer, "JPEG", quality=int(quality), subsampling=0, keep_rgb=True
            )
            (temporary / f"plane_{j}.jpg").write_bytes(buffer.getvalue())
            total += buffer.tell()
    return total


def check_web_folder(folder: str | os.PathLike) -> None:
    """Refuse a ``folder`` a web set may not take the place of: a file, or a folder holding
    anything but an earlier web set's files (``info.json``, ``plane_<n>.jpg``). A missing or
    empty folder is fine."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"'{folder}' is a file; a web set is a folder: give a folder name")
    if not folder.is_dir():
        return
    names = [entry.name for entry in folder.iterdir()]
    others = [name for name in names if name != "info.json" and not _is_plane(name)]
    if others or (names and "info.json" not in names):
        shown = ", ".join(sorted(others or names)[:3])
        raise InputError(
            f"folder '{folder}' holds other files ({shown}); a web set replaces its whole folder: "
            "give a new folder name"
        )


def _is_plane(name: str) -> bool:
    stem, _, number = name.removesuffix(".jpg").partition("_")
    return name.endswith(".jpg") and stem == "plane" and number.isdigit()


def _quantise(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each term (the first axis) as bytes over its range in the image and channels, 0 on a
    byte of its own as a ``.ptm`` file has it (a pixel black in every photo stays black): the
    bytes, and each term's Relight scale and bias (``value = (byte / 255 - bias) * scale``)."""
    step, zero = zero_exact_quantiser(values.reshape(len(values), -1))
    return quantised_bytes(values, step, zero), 255.0 * step, zero / 255.0


def _nplanes(kind: str) -> int:
    return 9 if kind == "ptm-lrgb" else 3 * FORMATS[kind]


def _jpegs(kind: str) -> int:
    return math.ceil(_nplanes(kind) / 3)
