"""The object mask on ordinary backgrounds: objects pasted on generated tables, paper, wood and
cloth (``benchmarks/composites.py``), saved as 8-bit sRGB and read back, with known masks.

The objects are made here (a shaded, painted body); no real data is needed. The brightness rules
alone took a fragment or half the wood on such pictures (``benchmarks/results/masks.md``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import composites
from shadeform import reconstruct
from shadeform.io.images import select_channel
from shadeform.masks import LOW_CONFIDENCE, find_object, segment_from_box, segment_from_seeds


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


def photo(family: str, seed: int, kind: str = "png"):
    picture, truth = composites.composite(body(seed=seed), family, seed, shadow=True)
    rgb = composites.as_file(picture, kind)
    return select_channel(rgb, "luma").astype(np.float64), rgb, truth


@pytest.mark.parametrize("family", composites.TRAINING)
def test_automatic_mask_on_ordinary_backgrounds(family):
    scores = []
    for seed in range(3):
        luma, _, truth = photo(family, seed, "jpeg" if seed % 2 else "png")
        scores.append(iou(find_object(luma).mask, truth))
    assert np.median(scores) >= 0.9, scores
    if family != "cloth":  # a plaid square like the object can still join it (masks.md)
        assert min(scores) >= 0.85, scores


def test_colour_photo_too():
    _, rgb, truth = photo("wood", 4)
    found = find_object(rgb)
    assert iou(found.mask, truth) >= 0.9
    assert 0 <= found.confidence <= 1


@pytest.mark.parametrize("family", ["table"])
def test_click_grows_the_whole_object(family):
    # on a grey table a click used to grow a fragment of the object
    luma, _, truth = photo(family, 7)
    mask = segment_from_seeds(luma, [composites.interior_point(truth)])
    assert iou(mask, truth) >= 0.9


@pytest.mark.parametrize("family", ["wood", "paper"])
def test_box(family):
    luma, _, truth = photo(family, 9)
    box = composites.padded_box(truth)
    mask, confidence = segment_from_box(luma, box, return_confidence=True)
    assert iou(mask, truth) >= 0.9
    top, left, bottom, right = box
    assert not mask[:top].any() and not mask[:, right:].any()
    assert 0 <= confidence <= 1


def test_box_errors():
    from shadeform.errors import InputError

    image = np.full((20, 20), 0.5)
    with pytest.raises(InputError, match="four whole pixel numbers"):
        segment_from_box(image, (1, 2, 3))
    with pytest.raises(InputError, match="less than 3x3"):
        segment_from_box(image, (5, 5, 6, 30))


def test_a_doubtful_mask_is_said_in_info(monkeypatch):
    # the plumbing: a doubtful automatic mask reaches the reconstruction's info in one line
    import shadeform.pipeline as pipeline
    from shadeform.masks import FoundObject

    luma, _, truth = photo("paper", 2)
    doubtful = FoundObject(truth, True, 0.5, 0.7, False, confidence=LOW_CONFIDENCE / 2)
    monkeypatch.setattr(pipeline, "find_object", lambda image: doubtful)
    rec = reconstruct(luma, method="propagation")
    assert rec.info["mask_warning"] == doubtful.warning
    assert "doubtful" in doubtful.warning and "\n" not in doubtful.warning


def test_a_clear_mask_has_no_warning():
    luma, _, truth = photo("paper", 2)
    rec = reconstruct(luma, method="propagation")
    assert "mask_warning" not in rec.info


@pytest.mark.parametrize("name", ["sphere", "cylinder", "bowl", "saddle"])
def test_a_render_on_black_is_not_doubtful(name):
    # the brightness mask and the cut agree exactly: two ways confirm it, whatever a third says
    from shadeform import synth

    scene = synth.scene(name, size=128)
    found = find_object(np.nan_to_num(scene.image))
    assert np.array_equal(found.mask, scene.mask)
    assert not found.doubtful and found.warning is None
