"""Deprecated: photo sets moved to :mod:`shadeform.photoset` (a set's lights may be read from a
shiny sphere in its photos, a step after loading). The old names stay importable from here,
with a DeprecationWarning, for one release."""

from __future__ import annotations


def __getattr__(name: str):
    import warnings

    from shadeform import photoset

    if name.startswith("__") or not hasattr(photoset, name):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(
        f"shadeform.io.photoset.{name} moved to shadeform.photoset.{name}; the old name goes in the next release",
        DeprecationWarning,
        stacklevel=2,
    )
    return getattr(photoset, name)
