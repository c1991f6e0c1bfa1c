"""The ``shadeform`` command: a thin shell over the library.

Commands::

    shadeform reconstruct IMAGE -o OUT.wrl   photo -> mesh (+ depth map, normal map)
    shadeform fuse A.png B.png --angles 0,180 -o OUT.glb   views from several sides -> one closed model
    shadeform relief IMAGE -o OUT.stl --width 100   photo -> print-ready solid in millimetres
    shadeform maps IMAGE --out DIR           photo -> normal, height, occlusion and curvature maps
    shadeform rti SET -o OUT.ptm             photo set -> relightable PTM or HSH (.rti) for RTIViewer
    shadeform synth SCENE -o image.png       a synthetic image and its ground truth
    shadeform evaluate                       error table of the solvers on the synthetic scenes
    shadeform formats                        the mesh formats -o understands
    shadeform solvers                        the solvers and integrators --solver / --integrator take
    shadeform demo                           the main job on a shipped photograph
    shadeform app [IMAGE]                    the browser app, served on 127.0.0.1

Everything here is input parsing, file I/O, printing and progress display; the work is done by
the library (``shadeform.reconstruct``, ``shadeform.to_mesh``, ``shadeform.export``, ...).

Errors are handled in one place (:class:`_Group`): a user mistake (:class:`InputError`), a file
that cannot be read or written, or bad JSON prints ``error: <one line>`` on stderr and exits with
code 2, like a usage error. Output files are first written to hidden temporary files beside their
targets and renamed only once all of them are complete (:class:`OutputSet`), so a failing command
leaves no file behind.
"""

from __future__ import annotations

from shadeform.cli import batch, fuse, maps, photos, relief, rti, stereo, tools  # noqa: F401  (their commands register on the app)
from shadeform.cli._shell import USAGE_EXIT, app, main

__all__ = ["USAGE_EXIT", "app", "main"]
