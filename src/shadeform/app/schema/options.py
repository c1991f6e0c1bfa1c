"""The schema of what the server offers (``/api/options``): solvers, integrators, formats,
examples, the upload limits and every panel's default parameters."""

from __future__ import annotations

from typing import Literal

from pydantic import ConfigDict, Field

from shadeform.app.schema.common import _Model
from shadeform.app.schema.printing import ReliefParams
from shadeform.app.schema.reconstruct import ImageInfo, ReconstructParams
from shadeform.app.schema.stereo import StereoParams


class OptionInfo(_Model):
    """One option of a solver's (or another registry entry's) own (:class:`shadeform.registry.Option`)."""

    name: str
    type: Literal["bool", "int", "float", "str"]
    default: bool | int | float | str
    help: str = Field(description="One line in the user's words.")


def _options_optional(schema: dict) -> None:
    # sent only when an entry has options: the built-in ones have none
    schema["required"] = [name for name in schema.get("required", ()) if name != "options"]


class MethodInfo(_Model):
    """A solver or integrator the library offers (its registry: :func:`shadeform.solvers.available_solvers`,
    :func:`shadeform.integration.available_integrators`)."""

    model_config = ConfigDict(json_schema_extra=_options_optional)

    name: str
    description: str = Field(description="One line in the user's words.")
    options: list[OptionInfo] = Field(
        default_factory=list,
        exclude_if=lambda options: not options,
        description="Its own options (``--option NAME=VALUE`` on the command line); absent when it has none.",
    )


class FormatInfo(_Model):
    """A mesh format the export endpoint writes (:func:`shadeform.available_formats`)."""

    suffix: str
    description: str


class ExampleInfo(_Model):
    """A shipped example (:data:`shadeform.examples.EXAMPLES`)."""

    name: str
    title: str


class Limits(_Model):
    """What an upload may be."""

    max_upload_bytes: int
    max_pixels: int
    large_pixels: int = Field(
        description="Images with more pixels get their quick look on a downsampled copy and their full "
        "solve in the background (``/api/solves``: progress, cancel).",
    )
    fit_factor: int = Field(
        description="A photo over ``max_pixels`` but at most this many times it may be opened downsampled "
        "to fit (``POST /api/images?fit=true``).",
    )


class Options(_Model):
    """What the library offers, the upload limits and the default parameters."""

    solvers: list[MethodInfo] = Field(description='"auto" first, then every registered solver.')
    integrators: list[MethodInfo]
    channels: list[str]
    filters: list[str]
    formats: list[FormatInfo]
    examples: list[ExampleInfo]
    stereo_models: list[MethodInfo] = Field(
        description="Photometric stereo's models (``StereoParams.model``), the default first."
    )
    photo_set_examples: list[ExampleInfo]
    stereo_defaults: StereoParams
    relief_defaults: ReliefParams = Field(default_factory=lambda: ReliefParams())
    view_set_examples: list[ExampleInfo] = Field(
        description="Shipped view sets: one object photographed from several sides, to fuse."
    )
    limits: Limits
    defaults: ReconstructParams
    initial_image: ImageInfo | None = Field(
        default=None,
        description="The image the server was started with (``shadeform app IMAGE``), else null.",
    )
