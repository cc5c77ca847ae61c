"""The Examples sections of the panorama package and of the shared pieces it uses run as doctests."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ["cvpipe.linalg", "cvpipe.matching", "cvpipe.panorama", "cvpipe.panorama.features",
           "cvpipe.panorama.register", "cvpipe.panorama.seams", "cvpipe.panorama.warp", "cvpipe.panorama.blend",
           "cvpipe.panorama.crop", "cvpipe.panorama.match"]


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name} has no Examples section"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"
