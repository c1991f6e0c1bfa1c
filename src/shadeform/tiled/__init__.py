"""Images too large to solve whole: the same stages over overlapping tiles, on Dask.

Planetary and microscopy images run to hundreds of megapixels; the whole-image pipeline needs
about 200 bytes per pixel and its eikonal solver's cost grows with the number of singular points
times the pixels. :func:`reconstruct` cuts the image into tiles of ``tile`` pixels, each solved
with a halo of ``overlap`` pixels on every side by :func:`shadeform.pipeline.reconstruct` (any
solver, light or filter), and joins them:

1. **Tiles** (the expensive part, one Dask task each): every tile reads its own window of the
   input (a TIFF is read lazily through tifffile's Zarr store, never whole), is solved, and its
   depth is saved to the work folder (``<out>.tiles/``) as one ``.npy`` file, written atomically:
   a file there is a finished tile, so a rerun after an interruption solves only the missing
   ones (:attr:`TiledResult.skipped`).
2. **Coarse global solve**: each tile's depth is known up to an offset (``z = 0`` at its own
   reference pixel). One unknown per tile, the offset, is found by least squares from the
   median height difference of every pair of overlapping tiles (neighbours and diagonals), with
   ``z = 0`` at the reference pixel of the first tile. This is the coarse level of a two-level
   solve: a system with one unknown per tile instead of one per pixel.
3. **Blend and write**: the output is written band by band (one row of tiles): each pixel is
   the mean of the aligned tiles covering it, weighted by a smooth step that falls from 1 to 0
   across a band of ``overlap`` pixels centred on the tile border. The weights sum to one, so the
   depth is continuous across borders; the outer half of each halo is never used (the solvers'
   border effects stay there). Depth goes to a tiled BigTIFF (float32, with the input's
   GeoTIFF tags), and optionally a mesh sampled on a grid and decimated to ``max_triangles``.

Why tie the tiles through their overlaps rather than through a shape-from-shading solve of a
downsampled image (the first design): averaging an image does not average the shape it shows,
so such a solve is biased where detail is near its grid's size (on
:func:`shadeform.synth.bump_relief` of spacing 128 at 4096 x 4096, solved at 1/16 scale, the
heights come out 30 % low: a depth range of 9.5 px for 13.6), and aligning the tiles to it
imports that bias; and the eikonal solver's cost, about 1.6 us per pixel for each singular
point, makes a 1 Mpx coarse solve of a relief with thousands of bumps cost about an hour of
one core (2700 bumps), one task that no worker can share. The tiles' overlaps see the same pixels at full resolution, so their disagreement there
is exactly the seam to remove; :attr:`TiledResult.seam` reports what is left of it.

Why explicit tiles rather than ``dask.array.map_overlap``: ``map_overlap`` trims each block's
halo and returns disjoint blocks, so overlaps can be neither compared (for the offsets) nor
blended, and a block's result cannot be kept on disk for a rerun.

Schedulers. The eikonal solver's numba kernels hold the interpreter lock (compiled without
``nogil``), so threads queue behind one another: by default the tiles run in worker processes
(``benchmarks/results/tiled.md`` has the measured threads-versus-processes ratio). A Dask
distributed cluster (an address ``"tcp://host:8786"`` or a ``distributed.Client``) runs the
same tasks; its workers read the input and write the tiles by path, so the input and the work
folder must be on storage they all reach.

Memory. The main process holds one band of the output (``tile x width`` float32, twice) and, if
a mesh is asked for, its grid; each worker one tile with its halo through the whole-image
pipeline (about 200 bytes per pixel: 120 MB for a 512-pixel tile with a 128-pixel halo).

The object. A photo of an object is solved only on the object, as when solved whole: the
object is found once on a coarse overview of the whole image (the frame shows what is
background) and carried to every tile (:mod:`shadeform.tiled.objects`), or given as a mask;
off it the depth is NaN. A picture that is one surface filling the frame (a relief) is all
object, and ``mask="whole"`` says so outright. A seam above the solvers' own error
(:data:`SEAM_FRACTION` of the depth's range) comes with a warning (``info["seam_warning"]``).

Hostile files and stopping. A TIFF's header is checked against the file before anything is
allocated or made (:mod:`shadeform.tiled.reading`); every option is checked, and a cluster
reached, before the work folder exists; Ctrl-C or SIGTERM stop the workers at once and remove
the work folder unless it is kept for a rerun (``keep_work``) (:mod:`shadeform.tiled.tasks`).

Limits. Each tile is solved on its own, so what a tile cannot see it cannot know: with the
light at +z every slope must rise to a singular point (a fully lit top) within the tile's halo,
so the halo must be at least as wide as the widest feature's flank (the default, a quarter of
the tile, is 128 pixels), and a tile that holds no fully lit pixel takes its own brightest pixel
as facing the light, as a whole image would. Features wider than a tile come out only as well
as a tile sees them. A tile holds one offset: where the object's parts within one tile are
apart (two arms cut by the tile), they share it, and the seam says how well that held.
Dask (and ``distributed`` for a cluster) are optional: ``pip install 'shadeform[dask]'``.
"""

from shadeform.tiled.objects import OVERVIEW_PIXELS, WHOLE
from shadeform.tiled.reading import GEO_TAGS, MAX_TILED_PIXELS, TiffWindows, open_image
from shadeform.tiled.run import (
    DEFAULT_TILE,
    DEFAULT_TRIANGLES,
    MIN_TILE,
    SEAM_FRACTION,
    Progress,
    TiledResult,
    reconstruct,
    seam_warning,
)

__all__ = [
    "DEFAULT_TILE",
    "DEFAULT_TRIANGLES",
    "GEO_TAGS",
    "MAX_TILED_PIXELS",
    "MIN_TILE",
    "OVERVIEW_PIXELS",
    "SEAM_FRACTION",
    "WHOLE",
    "Progress",
    "TiffWindows",
    "TiledResult",
    "open_image",
    "reconstruct",
    "seam_warning",
]
