"""Find the object in a photo: the automatic mask, and the masks from clicks or a box.

- :mod:`shadeform.masks.brightness`: the object by brightness (a dark lab backdrop, a sheet of
  paper), the rules written there; and by one threshold (:func:`threshold_object`).
- :mod:`shadeform.masks.graphcut`: the object by colour models and a graph cut (GrabCut), on a
  table, wood or cloth, and how sure it is.
- :mod:`shadeform.masks.objects`: :func:`find_object`, :func:`segment_from_seeds` and
  :func:`segment_from_box`, which use both.
"""

from shadeform.masks.brightness import LOW_CONFIDENCE, FoundObject, threshold_object
from shadeform.masks.objects import find_object, segment_from_box, segment_from_seeds

__all__ = [
    "FoundObject",
    "find_object",
    "threshold_object",
    "segment_from_seeds",
    "segment_from_box",
    "LOW_CONFIDENCE",
]
