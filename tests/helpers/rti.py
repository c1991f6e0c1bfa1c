"""An independent reader of PTM 1.2 and HSH ``.rti`` files, written from the formats' published
descriptions (HP Labs' "Polynomial Texture Map (.ptm) File Format" 1.2; RTIViewer's
``UniversalRti`` and ``Hsh`` loaders), not from shadeform's writer, and an evaluator that lights
what it read the way RTIViewer does. Tests only."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from shadeform import synth
from shadeform.light import light_from_slant_tilt

#: A dome: one light at the camera, eight at 25 degrees of slant and eight at 50.
DOME = np.array(
    [[0.0, 0.0, 1.0]] + [light_from_slant_tilt(s, t) for s in (25, 50) for t in range(0, 360, 45)]
)
#: A light of the dome's range that no photo was taken under.
HELD_OUT = np.asarray(light_from_slant_tilt(38, 70))


def write_dome_set(folder: Path) -> Path:
    """A grey sphere under the :data:`DOME`'s 17 lights, written as a photo set's folder (16-bit
    photos, light_directions.txt)."""
    from helpers.photosets import write_photo_set

    scene = synth.scene("sphere", size=32)
    write_photo_set(folder, scene.normals, scene.mask, lights=DOME)
    return folder


class ReadRti:
    """What one file holds: ``kind``, ``width``, ``height``, ``header`` (the text lines),
    ``data_offset`` (where the bytes start), and the decoded coefficients, top row first:
    ``ptm`` (H, W, 6) luminance or (3, H, W, 6) per channel, in 0-255 units; ``rgb`` (H, W, 3)
    bytes for LRGB; ``hsh`` (3, H, W, terms) in 0-1 units."""

    ptm = rgb = hsh = None


def _line(data: bytes, at: int) -> tuple[str, int]:
    end = data.index(b"\n", at)
    return data[at:end].decode("ascii").strip(), end + 1


def read_ptm(data: bytes) -> ReadRti:
    out = ReadRti()
    at = 0
    version, at = _line(data, at)
    assert version == "PTM_1.2", version
    fmt, at = _line(data, at)
    width, at = _line(data, at)
    height, at = _line(data, at)
    scales, at = _line(data, at)
    biases, at = _line(data, at)
    out.width, out.height = int(width), int(height)
    scale = [float(v) for v in scales.split(" ")]
    bias = [int(v) for v in biases.split(" ")]
    assert len(scale) == 6 and len(bias) == 6
    out.header, out.data_offset = [version, fmt, width, height, scales, biases], at
    w, h = out.width, out.height
    blocks = 1 if fmt == "PTM_FORMAT_LRGB" else 3
    coefficients = np.zeros((blocks, h, w, 6))
    for block in range(blocks):
        for row_from_bottom in range(h):
            row = h - 1 - row_from_bottom
            for x in range(w):
                for k in range(6):
                    coefficients[block, row, x, k] = (data[at] - bias[k]) * scale[k]
                    at += 1
    if fmt == "PTM_FORMAT_LRGB":
        out.kind, out.ptm = "ptm-lrgb", coefficients[0]
        out.rgb = np.zeros((h, w, 3))
        for row_from_bottom in range(h):
            for x in range(w):
                out.rgb[h - 1 - row_from_bottom, x] = list(data[at : at + 3])
                at += 3
    else:
        assert fmt == "PTM_FORMAT_RGB", fmt
        out.kind, out.ptm = "ptm-rgb", coefficients
    assert at == len(data), (at, len(data))
    return out


def read_hsh(data: bytes) -> ReadRti:
    out = ReadRti()
    at = 0
    lines = []
    line, at = _line(data, at)
    while line.startswith("#"):
        lines.append(line)
        line, at = _line(data, at)
    assert line == "3", line
    size, at = _line(data, at)
    basis, at = _line(data, at)
    out.header, out.data_offset = [*lines, line, size, basis], at
    width, height, channels = (int(v) for v in size.split())
    terms, _basis_type, element = (int(v) for v in basis.split())
    assert channels == 3 and element == 1
    out.width, out.height, out.kind = width, height, {4: "hsh2", 9: "hsh3"}[terms]
    scale = struct.unpack(f"<{terms}f", data[at : at + 4 * terms])
    at += 4 * terms
    bias = struct.unpack(f"<{terms}f", data[at : at + 4 * terms])
    at += 4 * terms
    out.hsh = np.zeros((3, height, width, terms))
    for row in range(height):  # the top row first
        for x in range(width):
            for channel in range(3):
                for k in range(terms):
                    out.hsh[channel, row, x, k] = data[at] / 255.0 * scale[k] + bias[k]
                    at += 1
    assert at == len(data), (at, len(data))
    return out


def hsh_weights(light, terms):
    """RTIViewer's hemispherical harmonics of a light (its ``getHSH``, theta clamped at 1.52)."""
    x, y, z = np.asarray(light, dtype=float) / np.linalg.norm(light)
    phi = math.atan2(y, x)
    theta = min(math.acos(z), 1.52)
    ct = math.cos(theta)
    s = math.sqrt(ct - ct * ct)
    weights = [
        1 / math.sqrt(2 * math.pi),
        math.sqrt(6 / math.pi) * math.cos(phi) * s,
        math.sqrt(3 / (2 * math.pi)) * (-1 + 2 * ct),
        math.sqrt(6 / math.pi) * s * math.sin(phi),
        math.sqrt(30 / math.pi) * math.cos(2 * phi) * (-ct + ct * ct),
        math.sqrt(30 / math.pi) * math.cos(phi) * (-1 + 2 * ct) * s,
        math.sqrt(5 / (2 * math.pi)) * (1 - 6 * ct + 6 * ct * ct),
        math.sqrt(30 / math.pi) * (-1 + 2 * ct) * s * math.sin(phi),
        math.sqrt(30 / math.pi) * (-ct + ct * ct) * math.sin(2 * phi),
    ]
    return np.array(weights[:terms])


def light_up(read: ReadRti, light) -> np.ndarray:
    """The image RTIViewer shows for a light, (H, W, 3) in 0-1 (not clipped), top row first."""
    if read.hsh is not None:
        weights = hsh_weights(light, read.hsh.shape[-1])
        return np.moveaxis(read.hsh @ weights, 0, -1)
    x, y, z = np.asarray(light, dtype=float) / np.linalg.norm(light)
    poly = np.array([x * x, y * y, x * y, x, y, 1.0])
    if read.kind == "ptm-lrgb":
        luminance = read.ptm @ poly  # 0-255
        return read.rgb * luminance[..., None] / 255.0 / 255.0
    return np.moveaxis(read.ptm @ poly, 0, -1) / 255.0


def read_file(path) -> ReadRti:
    data = Path(path).read_bytes()
    return read_ptm(data) if data.startswith(b"PTM_") else read_hsh(data)


# --- Relight's web format ----------------------------------------------------------------------
# Written from OpenLIME's ShaderRTI and Relight's convert_rti (how they read info.json and the
# planes), not from shadeform's writer.


class ReadWeb:
    """A web set read back: ``info`` (info.json), ``planes`` (nplanes, H, W) coefficients
    (``(byte / 255 - bias) * scale``), ``bytes`` (nplanes, H, W) the decoded bytes."""


def read_web(folder) -> ReadWeb:
    import json

    from PIL import Image

    folder = Path(folder)
    out = ReadWeb()
    out.info = json.loads((folder / "info.json").read_text(encoding="utf-8"))
    nplanes = out.info["nplanes"]
    material = out.info["materials"][0]
    scale, bias = np.array(material["scale"]), np.array(material["bias"])
    assert len(scale) == len(bias) == nplanes
    layers = []
    for j in range(math.ceil(nplanes / 3)):
        with Image.open(folder / f"plane_{j}.jpg") as image:
            assert image.format == "JPEG" and image.mode == "RGB"
            layers.append(np.asarray(image, dtype=np.float64))
    out.bytes = np.concatenate([np.moveaxis(layer, -1, 0) for layer in layers])[:nplanes]
    out.planes = (out.bytes / 255.0 - bias[:, None, None]) * scale[:, None, None]
    return out


def web_weights(read: ReadWeb, light) -> np.ndarray:
    """The viewer's weights of the terms for a light: PTM in Relight's order (1, x, y, x^2, xy,
    y^2), HSH as RTIViewer's."""
    x, y, z = np.asarray(light, dtype=float) / np.linalg.norm(light)
    if read.info["type"] == "ptm":
        return np.array([1.0, x, y, x * x, x * y, y * y])
    return hsh_weights(light, read.info["nplanes"] // 3)


def light_up_web(read: ReadWeb, light) -> np.ndarray:
    """The image the viewer shows for a light, (H, W, 3) in 0-1 (not clipped)."""
    weights = web_weights(read, light)
    if read.info["colorspace"] == "lrgb":  # JPEG 0: the colour; the rest: the luminance's terms
        luminance = np.tensordot(weights, read.planes[3:9], axes=1)
        return np.moveaxis(read.planes[:3], 0, -1) * luminance[..., None]
    # rgb: JPEG j holds term j of the red, green and blue channels
    terms = read.planes.reshape(len(weights), 3, *read.planes.shape[1:])
    return np.moveaxis(np.tensordot(weights, terms, axes=1), 0, -1)
