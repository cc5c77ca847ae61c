"""The Examples sections of the logo package and of the shared geometry and metrics helpers run as doctests."""

import doctest
import importlib

import pytest

# by module name: `cvpipe.logo.verify` the attribute is the re-exported function, not the module
MODULES = ["cvpipe.geometry", "cvpipe.metrics", "cvpipe.logo.detect", "cvpipe.logo.verify", "cvpipe.logo.report"]


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0  # the module has examples, and they ran
    assert result.failed == 0
