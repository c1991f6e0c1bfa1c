"""A project document as the app's client saves it, shared by the project tests of the API and of
the browser."""

from __future__ import annotations

from shadeform.app.schema import ReconstructParams


def photo_document(name="bowl.png", **params) -> dict:
    """A one-photo project as the client autosaves it: the image by its id in the server's store."""
    info = {"image_id": "0123abcd", "name": name, "width": 64, "height": 48, "channels": 1, "suggested": None}
    return {
        "format": "shadeform-project",
        "version": 1,
        "name": None,
        "image": {
            "name": name,
            "type": "image/png",
            "data": None,
            "example": None,
            "source": {"kind": "upload", "name": name, "type": "image/png", "index": None},
            "info": info,
        },
        # every field, as the client sends them (its parameters are the server's defaults, edited)
        "params": ReconstructParams(
            filter={"kind": "gaussian", "size": 1.5},
            concave={"regions": [{"polygon": [[1, 2], [30, 2], [15, 40]], "axis": "x"}]},
            **params,
        ).model_dump(mode="json"),
        "view": {
            "wireframe": True,
            "normalColours": False,
            "texture": False,
            "maskOverlay": True,
            "lightArrow": True,
        },
        "photo_set": None,
        "views": None,
    }
