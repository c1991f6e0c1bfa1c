"""Find the object in a photo: the automatic mask, and the masks from clicks or a box.

- :mod:`shadeform.masks.brightness`: the object by brightness (a dark lab backdrop, a sheet of
  paper), the rules written there; and by one threshold (:func:`threshold_object`).
- :mod:`shadeform.masks.graphcut`: the object by colour models and a graph cut (GrabCut), on a
  table, wood or cloth, and how sure it is.
- :mod:`shadeform.masks.objects`: :func:`find_object`, :func:`segment_from_seeds` and
  :func:`segment_from_box`, which use both.
- :mod:`shadeform.masks.stack`: :func:`find_object_in_set`, the object of a photo set found from
  all its photos (their median reading; holes that show the background or a dark inside kept
  open).
"""

from shadeform.masks.brightness import LOW_CONFIDENCE, FoundObject, threshold_object
from shadeform.masks.objects import find_object, segment_from_box, segment_from_seeds
from shadeform.masks.stack import find_object_in_set

__all__ = [
    "FoundObject",
    "find_object",
    "find_object_in_set",
    "threshold_object",
    "segment_from_seeds",
    "segment_from_box",
    "LOW_CONFIDENCE",
]
