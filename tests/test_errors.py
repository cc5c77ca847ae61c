"""cvpipe.errors: the integer check every public boundary uses."""

import doctest
import re

import numpy as np
import pytest

import cvpipe.errors
from cvpipe.errors import InputError, check_int


class TestCheckInt:
    @pytest.mark.parametrize("value", [3, np.int64(3), np.uint8(3), np.int32(3)])
    def test_returns_a_python_int(self, value):
        got = check_int("n", value, 1, 5)
        assert got == 3 and type(got) is int

    @pytest.mark.parametrize("value", [True, np.bool_(True), 3.0, np.float64(3), "3", None, [3]])
    def test_refuses_what_is_not_an_integer(self, value):
        with pytest.raises(InputError, match="^`n` must be an integer >= 1, got " + re.escape(repr(value)) + "$"):
            check_int("n", value, 1)

    def test_names_the_bounds_it_has(self):
        with pytest.raises(InputError, match=r"^`n` must be an integer, got 2\.5$"):
            check_int("n", 2.5)
        with pytest.raises(InputError, match=r"^`n` must be an integer >= 8, got 7$"):
            check_int("n", 7, 8)
        with pytest.raises(InputError, match=r"^`n` must be an integer <= 4, got 5$"):
            check_int("n", 5, maximum=4)
        with pytest.raises(InputError, match=r"^`n` must be an integer in \[1, 12\], got 13$"):
            check_int("n", 13, 1, 12)
        assert check_int("n", -7) == -7 and check_int("n", 12, 1, 12) == 12 and check_int("n", 1, 1, 12) == 1

    def test_note_and_source(self):
        with pytest.raises(InputError, match=r"^`compute.workers` must be an integer >= 0 \(0 = one per core\), "
                                             r"got -1$"):
            check_int("compute.workers", -1, 0, note="0 = one per core")
        with pytest.raises(InputError, match=r"^pair/truth\.json: `max_disp` must be an integer >= 1, got 0$") as e:
            check_int("max_disp", 0, 1, source="pair/truth.json")
        assert e.value.file == "pair/truth.json"

    def test_examples_run(self):
        result = doctest.testmod(cvpipe.errors, optionflags=doctest.NORMALIZE_WHITESPACE)
        assert result.attempted > 0 and result.failed == 0


def test_a_missing_optional_dependency_names_the_extra_that_installs_it(monkeypatch):
    import sys

    from cvpipe.errors import InputError, require_extra

    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the dask extra were not installed
    with pytest.raises(InputError, match=r"a Dask scheduler needs the Python package 'distributed', which the 'dask' "
                                         r"extra installs: pip install 'cvpipe\[dask\]'"):
        require_extra("distributed", "dask", "a Dask scheduler")
    assert require_extra("json", "dask", "x") is sys.modules["json"]
