"""The summary ``shadeform reconstruct`` prints, in words a newcomer reads (issue 34, item 6): where
depth 0 is, as x (column) and y (row) like the CLI's other notes, not "reference pixel(s) (r, c)"."""

from __future__ import annotations

import numpy as np
from PIL import Image
from typer.testing import CliRunner

from shadeform import synth
from shadeform.cli import app


def test_the_summary_says_where_depth_0_is_in_words(tmp_path):
    scene = synth.scene("sphere", size=48)
    photo = tmp_path / "ball.png"
    Image.fromarray(np.rint(scene.image * 255).astype(np.uint8)).save(photo)
    result = CliRunner().invoke(
        app, ["reconstruct", str(photo), "-o", str(tmp_path / "ball.obj"), "--reference", "20,30"]
    )
    assert result.exit_code == 0, result.output
    line = next(text for text in result.stdout.splitlines() if text.strip().startswith("object "))
    assert "reference pixel" not in line and "part(s)" not in line
    assert line.strip().endswith("in 1 part, depth 0 at x=30, y=20"), line
