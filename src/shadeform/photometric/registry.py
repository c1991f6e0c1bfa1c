"""The photometric-stereo methods (:mod:`shadeform.photometric`'s description): one
:class:`StereoMethod` each, added by :func:`register`; a new method is one module and one
``register(...)`` line below (``shadeform stereo --method`` and the app list them from here).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["METHODS", "StereoMethod", "available_methods", "register"]


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
    """

    name: str
    fit: str
    description: str
    drops_photos: bool = True
    slant_scale: str | None = None


_REGISTRY: dict[str, StereoMethod] = {}


def register(method: StereoMethod) -> None:
    """Add a method (its module is imported when first used)."""
    _REGISTRY[method.name] = method


def available_methods() -> dict[str, str]:
    """The registered methods, the default first: name -> one-line description."""
    return {name: method.description for name, method in _REGISTRY.items()}


def _fit_function(name, attribute="fit"):
    import importlib

    module, function = getattr(_REGISTRY[name], attribute).split(":")
    return getattr(importlib.import_module(module), function)


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
#: The registered method names, the default first.
METHODS = tuple(_REGISTRY)
