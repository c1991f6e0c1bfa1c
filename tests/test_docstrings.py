"""The examples in the library's docstrings run and give what they show."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import shadeform

MODULES = sorted(
    info.name
    for info in pkgutil.walk_packages(shadeform.__path__, "shadeform.")
    # the app needs the optional server packages; its examples are the API tests
    if not info.name.startswith("shadeform.app")
)


@pytest.mark.parametrize("name", MODULES)
def test_examples(name):
    module = importlib.import_module(name)
    failed, _ = doctest.testmod(
        module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False
    )
    assert failed == 0
