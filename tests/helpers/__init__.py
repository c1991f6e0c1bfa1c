"""Helpers shared by the test modules, by concern: a test module imports them from here, never
from another test module.

``tests/`` is on ``sys.path`` while pytest runs (its rootdir-relative ``prepend`` import mode puts
the folder of ``tests/conftest.py`` there, ``tests/`` having no ``__init__.py``), so every test
module, and the conftest, imports them as ``helpers``: ``from helpers.surfaces import normals_of``.

- :mod:`helpers.surfaces`: small hand-made surfaces of known depth and normals.
- :mod:`helpers.pngs`: pixel arrays and PNG files written by an encoder other than Pillow.
- :mod:`helpers.readers`: the independent readers of exported meshes (``ivinfo``, three.js).
- :mod:`helpers.rti`: an independent reader of PTM and HSH (``.rti``) files, and RTIViewer's lighting.
- :mod:`helpers.browser`: the app's real server and Chromium for the browser tests.
- :mod:`helpers.fusion`: true views of the closed synthetic objects, and their scores.
- :mod:`helpers.lights`: a rig of photos with a chrome sphere, angles between lights.
- :mod:`helpers.masks`: a painted object to paste on the composites' backgrounds.
- :mod:`helpers.projects`: a one-photo project as the client saves it.
- :mod:`helpers.app`: the app's answers decoded (its meshes) and its views fused.
- :mod:`helpers.cli`: what a refusal on the command line looks like (one line, exit code 2).
"""

from pathlib import Path

#: The repository, and the shared data beside it (``../shared/data``: DiLiGenT, MIT-Berkeley).
ROOT = Path(__file__).resolve().parents[2]
SHARED_DATA = ROOT.parent / "shared" / "data"
