"""The schema of projects (``shadeform.app.projects``): the user's work on one photo, a photo set
or views, as a project file holds it and as the server keeps and lists it."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import AliasChoices, Field, model_validator

from shadeform.app.schema.common import _Model
from shadeform.app.schema.reconstruct import ImageInfo, ReconstructParams
from shadeform.app.schema.stereo import PhotoSetInfo, StereoParams

#: A project's id: chosen by the client, so that it can save before the server answers.
PROJECT_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"

_Name = Annotated[str, Field(max_length=1000)]


class ProjectSource(_Model):
    """Where a project's photo came from, to open it again: a shipped example (by name), an upload,
    the image the server was started with, photo ``index`` of a shipped view set, or a photo set
    (a view that is one: ``ProjectViewEntry.photo_set``)."""

    kind: Literal["example", "upload", "initial", "viewset", "photoset"]
    name: _Name
    type: str | None = Field(default=None, max_length=200, description="An upload's MIME type.")
    index: int | None = Field(default=None, ge=0, lt=1000, description="The photo's place in its view set.")


class ProjectImage(_Model):
    """A project's photo: a project file carries its bytes; the server's projects name the image in
    the server's session store instead (``info.image_id``), which keeps the bytes."""

    name: _Name
    type: str = Field(default="", max_length=200, description="The file's MIME type.")
    data: str | None = Field(default=None, description="base64 of the image file (project files).")
    example: str | None = Field(default=None, max_length=200, description="A shipped example's name.")
    source: ProjectSource | None = None
    info: ImageInfo | None = Field(
        default=None, description="The image as the server stored it (its id in the session store)."
    )


class DisplaySettings(_Model):
    """How the client shows the model and the image (the project file's ``view``)."""

    wireframe: bool = False
    normalColours: bool = False
    texture: bool = False
    maskOverlay: bool = True
    lightArrow: bool = True


class ProjectPhotoSet(_Model):
    """A photo set in a project: the set the server stored and the user's settings."""

    info: PhotoSetInfo
    params: StereoParams


class ProjectViewEntry(_Model):
    """One view in a project: its stored photo, where the photo came from, angle and settings; or a
    stored photo set (``photo_set``; ``image`` then names the set, its ``image_id`` the set's id)."""

    image: ImageInfo
    source: ProjectSource
    angle: float = Field(allow_inf_nan=False)
    params: ReconstructParams
    photo_set: ProjectPhotoSet | None = Field(
        default=None,
        description="The view is this photo set and its photometric stereo (``FuseView.photo_set_id``); "
        "null: a photo.",
    )


class ProjectViews(_Model):
    """The views in a project (several sides of one object, fused) and the fusion's settings."""

    views: list[ProjectViewEntry] = Field(min_length=1, max_length=24)
    refine_poses: bool = Field(
        default=True,
        # "refine", its old name: projects saved before the rename open
        validation_alias=AliasChoices("refine_poses", "refine"),
        description="Correct the poses so that the views agree (``FuseRequest.refine_poses``).",
    )
    settle: bool = True
    resolution: float | None = Field(default=None, ge=0.25, le=64, allow_inf_nan=False)
    showParts: bool = True
    editing: int | None = Field(
        default=None, ge=0, lt=24, description="The view being edited in single-photo mode, if one is."
    )


class ProjectDocument(_Model):
    """A project as the client's project file holds it: one photo (``image`` and ``params``), a
    photo set (``photo_set``) or views (``views``), with the display settings."""

    format: Literal["shadeform-project"]
    version: int = Field(ge=1, le=1, description="1: the only version so far.")
    name: str | None = Field(
        default=None, max_length=200, description="Shown in Open recent; null: what the project is of."
    )
    image: ProjectImage | None = None
    params: ReconstructParams | None = None
    view: DisplaySettings = Field(default_factory=DisplaySettings)
    photo_set: ProjectPhotoSet | None = None
    views: ProjectViews | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> ProjectDocument:
        held = [key for key in ("image", "photo_set", "views") if getattr(self, key) is not None]
        if len(held) != 1:
            raise ValueError(
                "a project holds exactly one of image (with params), photo_set or views; "
                f"this one holds {' and '.join(held) or 'none of them'}"
            )
        if self.image is not None and self.params is None:
            raise ValueError("a project with an image needs its params")
        return self


class ProjectInfo(_Model):
    """A project the server keeps, as Open recent lists it."""

    id: str
    name: str
    image: str = Field(description="What the project is of: the photo's name, the photo set's, the views'.")
    kind: Literal["photo", "photo_set", "views"]
    created: float = Field(description="Seconds since the epoch.")
    updated: float = Field(description="Seconds since the epoch, when it was last saved.")


class ProjectList(_Model):
    """The projects the server keeps, the most recently updated first."""

    projects: list[ProjectInfo]


class Project(ProjectInfo):
    """A project the server keeps, with its document."""

    document: ProjectDocument
