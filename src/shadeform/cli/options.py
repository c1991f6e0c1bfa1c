"""The options the commands share, declared once: their types (help, metavar, limits), and the
options of one photo's solve that ``reconstruct``, ``relief`` and ``maps`` all take
(:class:`PhotoOptions`, added to a command by :func:`takes_photo_options`)."""

from __future__ import annotations

import functools
import inspect
import typing
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Annotated

import typer

from shadeform.cli._shell import parse_reference, refuse_options, resolve_light
from shadeform.integration import available_integrators
from shadeform.solvers import available_solvers

# options shared by the commands that build meshes
SlantOption = Annotated[
    float | None, typer.Option(metavar="DEGREES", help="Light slant: angle from the viewing direction.")
]
TiltOption = Annotated[
    float | None, typer.Option(metavar="DEGREES", help="Light tilt: from +x toward +y (up); needs --slant.")
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the summary.")]
StepOption = Annotated[int, typer.Option(min=1, help="Mesh granularity: pixels per vertex.")]
# --method: the option's name before the rename, kept for one release
SolverOption = Annotated[
    str,
    typer.Option(
        "--solver",
        "--method",
        help=f"Solver: {', '.join(available_solvers())} (`shadeform solvers` says what each does).",
    ),
]
IntegratorOption = Annotated[
    str | None,
    typer.Option(
        help=f"Depth from normals: {', '.join(available_integrators())} (default: the solver's own)."
    ),
]
RefineOption = Annotated[
    int,
    typer.Option(
        min=0, max=100, help="Integrability refinement iterations (0: the 2002 field; at most 100)."
    ),
]
LinearOption = Annotated[
    bool | None,
    typer.Option(
        "--linear/--srgb",
        help="How the photo file holds its values: --srgb decodes sRGB (JPEG, phone photos) to linear "
        "light, --linear keeps them. Default: 8-bit files are sRGB, 16-bit and float ones linear, and so "
        "is a photo in a folder with light_intensities.txt (a calibrated photo set).",
        show_default=False,
    ),
]
ChannelOption = Annotated[
    str,
    typer.Option(
        help="Image channel: auto (luma, or the least clipped colour channel where one clips on "
        "clearly fewer pixels), luma, r, g, b or max."
    ),
]
FilterOption = Annotated[
    str | None,
    typer.Option(
        "--filter",
        metavar="KIND:SIZE",
        help="Smoothing: gaussian:SIGMA, mean:R, median:R, minimum:R or none.",
    ),
]

#: The loader's one pixel limit, :data:`shadeform.io.images.MAX_PIXELS`, written out here so that
#: the command starts without importing the image decoders (tests/test_cli_max_pixels.py checks
#: that the two agree).
MAX_PIXELS = 8192 * 8192
# every command that reads photos or masks takes it; `app` defaults to the server's own limit
MaxPixelsOption = Annotated[
    int | None,
    typer.Option(
        "--max-pixels",
        min=1,
        metavar="PIXELS",
        help="Refuse a photo or mask whose header declares more pixels than this, before decoding "
        "it (a damaged file or a decompression bomb); raise it for larger photos you trust.",
    ),
]

# the options of one photo's reconstruction that every command making something of it shares
LightOption = Annotated[
    str | None,
    typer.Option(
        metavar="X,Y,Z",
        help='Direction toward the light in the camera frame, or "estimate" to estimate it from the image; 0,0,1 if not given.',
    ),
]
ConcaveOption = Annotated[
    Path | None,
    typer.Option(help="JSON file of concave regions (docs/conventions.md).", show_default=False),
]
ReferenceOption = Annotated[
    list[str] | None,
    typer.Option(
        "--reference",
        metavar="ROW,COL",
        help="Reference pixel ROW,COL (or ROW,COL,NX,NY,NZ with its normal); repeat for several.",
        show_default=False,
    ),
]
MaskFileOption = Annotated[
    Path | None,
    typer.Option(help="Mask image: non-zero pixels are the object; found automatically if not given."),
]

NormalsFileOption = Annotated[Path | None, typer.Option(help="Also write the normal map (16-bit .png).")]
# the listings' --json (batch, evaluate, formats)
TableJsonOption = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the table.")]


@dataclass(frozen=True)
class PhotoOptions:
    """The options of one photo's solve as the user typed them: how the photo is read (``channel``,
    ``linear``, ``max_pixels``, the ``mask`` file) and solved (the rest). Each field's type is the
    command-line option it comes from, so this class is their one declaration."""

    filter: FilterOption = None
    light: LightOption = None
    slant: SlantOption = None
    tilt: TiltOption = None
    channel: ChannelOption = "auto"
    linear: LinearOption = None
    concave: ConcaveOption = None
    reference: ReferenceOption = None
    mask: MaskFileOption = None
    solver: SolverOption = "auto"
    integrator: IntegratorOption = None
    refine: RefineOption = 3
    max_pixels: MaxPixelsOption = MAX_PIXELS

    def refuse_for_set(self) -> None:
        """Refuse the options that only one photo's solve takes, as the user typed them: a photo
        set's lights are in its files and its shape has no convexity to choose."""
        given = {
            "--light": self.light is not None,
            "--slant": self.slant is not None,
            "--tilt": self.tilt is not None,
            "--concave": self.concave is not None,
            "--reference": bool(self.reference),
            "--solver": self.solver != "auto",
            "--filter": self.filter is not None,
            "--refine": self.refine != 3,
        }
        refuse_options(
            given,
            "for one photo: a photo set's lights come from its light file and its shape needs no "
            "hints; leave them out",
        )

    def arguments(self, *, solver_options: dict | None = None) -> dict:
        """The keyword arguments of :func:`shadeform.cli.photos.reconstruct_photo` (and so of
        :func:`shadeform.reconstruct`), checked before any work: the light as ``--light`` or
        ``--slant``/``--tilt``, the references, the regions file, a named solver's own options."""
        from shadeform.regions import parse_regions

        references = [parse_reference(text) for text in self.reference or ()]
        if solver_options and self.solver != "auto":  # checked before the photo is read
            from shadeform.solvers import SOLVERS

            SOLVERS.settle(self.solver, solver_options)
        given = asdict(self)
        del given["slant"], given["tilt"], given["reference"]
        return {
            **given,
            "light": resolve_light(self.light, self.slant, self.tilt),
            "references": references or None,
            "concave": parse_regions(self.concave) if self.concave is not None else None,
            "solver_options": solver_options,
        }


#: Every option of one photo's solve at its default: the default of a command's
#: :class:`PhotoOptions` parameter (the command line always gives all of them).
PHOTO_DEFAULTS = PhotoOptions()


def takes_photo_options(command):
    """Give a command the options of one photo's solve: its parameter typed :class:`PhotoOptions`
    stands, in its signature and so in its ``--help``, for each of those options, and receives them
    as one :class:`PhotoOptions`."""
    signature = inspect.signature(command, eval_str=True)
    types = typing.get_type_hints(PhotoOptions, include_extras=True)
    (slot,) = (p for p in signature.parameters.values() if p.annotation is PhotoOptions)
    shared = [
        inspect.Parameter(field.name, slot.kind, default=field.default, annotation=types[field.name])
        for field in fields(PhotoOptions)
    ]
    parameters = []
    for parameter in signature.parameters.values():
        parameters += shared if parameter is slot else [parameter]

    @functools.wraps(command)
    def run(**given):
        options = PhotoOptions(**{field.name: given.pop(field.name) for field in fields(PhotoOptions)})
        return command(**given, **{slot.name: options})

    run.__signature__ = signature.replace(parameters=parameters)
    run.__annotations__ = {p.name: p.annotation for p in parameters} | {"return": signature.return_annotation}
    return run
