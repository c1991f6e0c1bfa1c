"""Old names kept for one release: keyword arguments (:func:`renamed_keywords`) and module
attributes (:func:`renamed_attributes`) that were renamed."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

__all__ = ["renamed_attributes", "renamed_keywords"]

F = TypeVar("F", bound=Callable[..., Any])


def renamed_keywords(**renames: str) -> Callable[[F], F]:
    """Accept each old keyword (``old="new"``) for its new name, with a ``DeprecationWarning``.

    The decorated function's signature shows only the new names; giving both an old name and
    its new one is a ``TypeError``, as any keyword given twice is.

    Examples
    --------
    >>> @renamed_keywords(method="solver")
    ... def solve(*, solver="auto"):
    ...     return solver
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     solve(method="eikonal")
    'eikonal'
    """

    def decorate(function: F) -> F:
        @functools.wraps(function)
        def wrapper(*args, **kwargs):
            for old, new in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{function.__name__}() got both {old}= and {new}=; give only {new}=")
                    warnings.warn(
                        f"{function.__name__}({old}=...) is now {function.__name__}({new}=...); "
                        f"the old name goes in the next release",
                        DeprecationWarning,
                        stacklevel=2,
                    )
                    kwargs[new] = kwargs.pop(old)
            return function(*args, **kwargs)

        return wrapper  # type: ignore[return-value]

    return decorate


def renamed_attributes(
    module: str, renames: Mapping[str, tuple[str, Callable[[], Any]]]
) -> Callable[[str], Any]:
    """A module ``__getattr__`` for old attribute names: ``renames`` maps each old name to its new
    name and a function giving its value (read when asked, so a registry's listing stays current),
    and each access warns (``DeprecationWarning``, pointing at the code that asked). Other names
    raise ``AttributeError``. A module with attributes of its own to serve calls the result last
    from its own ``__getattr__``, with ``stacklevel=3`` (one frame more to the asker).

    Examples
    --------
    >>> __getattr__ = renamed_attributes("shadeform.x", {"OLD": ("NEW", lambda: 3)})
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     __getattr__("OLD")
    3
    """

    def __getattr__(name: str, stacklevel: int = 2):
        if name not in renames:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        new, value = renames[name]
        warnings.warn(
            f"{module}.{name} is now {new}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=stacklevel,
        )
        return value()

    return __getattr__
