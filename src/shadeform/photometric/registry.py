"""The photometric-stereo methods (:mod:`shadeform.photometric`'s description): one
:class:`StereoMethod` each in :data:`STEREO_METHODS`, added by :func:`register`; a new method is
one module and one ``register(...)`` line below (``shadeform stereo --method`` and the app list
them from here, when asked: a method registered later is listed and taken too).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from shadeform.registry import Option, Registry

__all__ = [
    "METHODS",  # noqa: F822 (given by __getattr__, read from the registry when asked)
    "STEREO_METHODS",
    "StereoMethod",
    "available_methods",
    "available_stereo_methods",
    "register",
]


@dataclass(frozen=True)
class StereoMethod:
    """One photometric-stereo method of the registry.

    Attributes
    ----------
    name : str
        What users pass (``photometric_stereo(method=name)``, ``shadeform stereo --method``).
    fit : str
        ``"module:function"`` naming ``fit(lights (N, 3), readings (N, P), *, min_shading,
        highlight_cos, iterations) -> (g (P, 3), usable (N, P) bool)``: per pixel ``g`` = albedo
        times the unit normal (NaN where it cannot tell) and the readings it counted.
    description : str
        One line in the user's words.
    drops_photos : bool
        Whether photos that contradict the others are left out first.
    slant_scale : str, optional
        ``"module:function"`` naming ``slant_scale(lights (N, 3), readings (N, P), start (P, 3))
        -> float``: the factor on the given lights' ``tan(slant)`` that the method's model
        explains a sample of readings best with (1 where they cannot tell); None: the method
        takes the lights as given.
    options : tuple of Option
        Options of its own (:class:`shadeform.registry.Option`), listed by the app's
        ``/api/options``; no caller passes any yet, and the built-in methods declare none.
    """

    name: str
    fit: str
    description: str
    drops_photos: bool = True
    slant_scale: str | None = None
    options: tuple[Option, ...] = ()


#: The registered methods, the default first.
STEREO_METHODS: Registry[StereoMethod] = Registry("method", StereoMethod)


def register(method: StereoMethod) -> None:
    """Add a method (its module is imported when first used)."""
    STEREO_METHODS.register(method)


def available_stereo_methods() -> dict[str, str]:
    """The registered methods, the default first: name -> one-line description."""
    return STEREO_METHODS.descriptions()


def available_methods() -> dict[str, str]:
    """Deprecated alias of :func:`available_stereo_methods` (``shadeform.available_methods`` lists
    the solvers); removed in the next release."""
    warnings.warn(
        "shadeform.photometric.available_methods is deprecated; use available_stereo_methods "
        "(shadeform.available_methods lists the one-photo solvers)",
        DeprecationWarning,
        stacklevel=2,
    )
    return available_stereo_methods()


def __getattr__(name: str):
    # METHODS follows the registry: read when asked, not copied at import
    if name == "METHODS":
        return STEREO_METHODS.names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


register(
    StereoMethod(
        "bivariate",
        "shadeform.photometric.bivariate:fit",
        "a reflectance model per pixel (falloff and gloss lobes), shadows and outliers weighted out",
        slant_scale="shadeform.photometric.bivariate:slant_scale",
    )
)
register(
    StereoMethod(
        "robust",
        "shadeform.photometric.lambertian:robust",
        "Lambertian, with each pixel's shadows and highlights left out",
    )
)
register(
    StereoMethod(
        "least_squares",
        "shadeform.photometric.lambertian:least_squares",
        "Lambertian, every reading (Woodham 1980)",
        drops_photos=False,
    )
)
