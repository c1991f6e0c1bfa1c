"""Old names kept for one release: keyword arguments renamed by :func:`renamed_keywords`."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["renamed_keywords"]

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
