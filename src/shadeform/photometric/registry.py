"""The photometric-stereo models (:mod:`shadeform.photometric`'s description): one
:class:`StereoModel` each in :data:`STEREO_MODELS`, added by :func:`register`; a new model is
one module and one ``register(...)`` line below (``shadeform stereo --model`` and the app list
them from here, when asked: a model registered later is listed and taken too).

The names this module had before (``StereoMethod``, ``STEREO_METHODS``,
``available_stereo_methods``, ``METHODS``) still work, with a :class:`DeprecationWarning`, for
one release.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from shadeform._deprecated import renamed_attributes
from shadeform.registry import Option, Registry

__all__ = [
    "MODELS",  # noqa: F822 (given by __getattr__, read from the registry when asked)
    "STEREO_MODELS",
    "StereoModel",
    "available_methods",
    "available_stereo_models",
    "register",
]


@dataclass(frozen=True)
class StereoModel:
    """One photometric-stereo model of the registry: what the fit per pixel assumes of the surface.

    Attributes
    ----------
    name : str
        What users pass (``photometric_stereo(model=name)``, ``shadeform stereo --model``).
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
        -> float``: the factor on the given lights' ``tan(slant)`` that the model explains a
        sample of readings best with (1 where they cannot tell); None: the model takes the
        lights as given.
    options : tuple of Option
        Options of its own (:class:`shadeform.registry.Option`), listed by the app's
        ``/api/options``; no caller passes any yet, and the built-in models declare none.
    """

    name: str
    fit: str
    description: str
    drops_photos: bool = True
    slant_scale: str | None = None
    options: tuple[Option, ...] = ()


#: The registered models, the default first.
STEREO_MODELS: Registry[StereoModel] = Registry("model", StereoModel)


def register(model: StereoModel) -> None:
    """Add a model (its module is imported when first used)."""
    STEREO_MODELS.register(model)


def available_stereo_models() -> dict[str, str]:
    """The registered models, the default first: name -> one-line description."""
    return STEREO_MODELS.descriptions()


def available_methods() -> dict[str, str]:
    """Deprecated alias of :func:`available_stereo_models` (``shadeform.available_methods`` lists
    the solvers); removed in the next release."""
    warnings.warn(
        "shadeform.photometric.available_methods is deprecated; use available_stereo_models "
        "(shadeform.available_methods lists the one-photo solvers)",
        DeprecationWarning,
        stacklevel=2,
    )
    return available_stereo_models()


def available_stereo_methods() -> dict[str, str]:
    """Deprecated alias of :func:`available_stereo_models`; removed in the next release."""
    warnings.warn(
        "shadeform.photometric.available_stereo_methods is deprecated; use available_stereo_models",
        DeprecationWarning,
        stacklevel=2,
    )
    return available_stereo_models()


#: The module's old names, for one release: old name -> (new name, its value when asked).
OLD_NAMES = {
    "STEREO_METHODS": ("STEREO_MODELS", lambda: STEREO_MODELS),
    "StereoMethod": ("StereoModel", lambda: StereoModel),
    "METHODS": ("MODELS", lambda: STEREO_MODELS.names()),
}
_renamed = renamed_attributes(__name__, OLD_NAMES)


def __getattr__(name: str):
    # MODELS follows the registry: read when asked, not copied at import
    if name == "MODELS":
        return STEREO_MODELS.names()
    return _renamed(name, stacklevel=3)


register(
    StereoModel(
        "bivariate",
        "shadeform.photometric.bivariate:fit",
        "a reflectance model per pixel (falloff and gloss lobes), shadows and outliers weighted out",
        slant_scale="shadeform.photometric.bivariate:slant_scale",
    )
)
register(
    StereoModel(
        "robust",
        "shadeform.photometric.lambertian:robust",
        "Lambertian, with each pixel's shadows and highlights left out",
    )
)
register(
    StereoModel(
        "least_squares",
        "shadeform.photometric.lambertian:least_squares",
        "Lambertian, every reading (Woodham 1980)",
        drops_photos=False,
    )
)
