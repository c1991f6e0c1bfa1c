"""A painted object to paste on the generated backgrounds of ``benchmarks/composites.py``, and the
overlap of two masks, shared by the mask tests of the library and of the app."""

from __future__ import annotations

import sys

import numpy as np

from helpers import ROOT

if str(ROOT / "benchmarks") not in sys.path:
    sys.path.insert(0, str(ROOT / "benchmarks"))
import composites


def iou(a, b) -> float:
    return float((a & b).sum() / (a | b).sum())


def body(size=72, seed=0) -> composites.Cutout:
    """A painted, shaded object: a lit ellipsoid with a blob on top, bands of two colours."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:size, 0:size] / (size - 1) * 2 - 1
    main = (rows / 0.75) ** 2 + (cols / 0.95) ** 2
    head = ((rows + 0.7) / 0.3) ** 2 + ((cols - 0.3) / 0.3) ** 2
    mask = (main < 1) | (head < 1)
    z = np.sqrt(np.clip(1 - np.minimum(main, head), 0, 1))
    shade = 0.15 + 0.85 * (0.3 * -rows * np.sqrt(np.clip(1 - z**2, 0, 1)) + 0.9 * z).clip(0, 1)
    colours = rng.uniform(0.2, 0.9, (2, 3))
    paint = np.where((np.sin(8 * rows) > 0)[..., None], colours[0], colours[1])
    rgb = np.where(mask[..., None], paint * shade[..., None], 0.0)
    return composites.Cutout("body", np.clip(rgb, 0, 1), mask)
