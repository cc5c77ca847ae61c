"""cvpipe.params: unknown or mistyped keys are rejected by name; params.yaml agrees with the dataclass defaults."""

import dataclasses
from dataclasses import dataclass
from typing import Literal, Optional

import pytest

from cvpipe import params
from cvpipe.errors import InputError
from cvpipe.params import FeaturesParams, MatchParams, from_mapping, load_section, read_params_file


@dataclass(frozen=True)
class Demo:
    n: int = 3
    x: float = 0.5
    flag: bool = False
    name: str = "a"
    mode: Literal["fast", "slow"] = "fast"
    pair: tuple[int, int] = (1, 2)
    opt: Optional[float] = None


def test_defaults_and_conversion():
    d = from_mapping(Demo, {"x": 2, "pair": [3, 4], "opt": 1}, "demo")
    assert d == Demo(x=2.0, pair=(3, 4), opt=1.0)
    assert isinstance(d.x, float)
    assert from_mapping(Demo, None, "demo") == Demo()


@pytest.mark.parametrize("mapping, message", [
    ({"nn": 1}, r"unknown key `demo\.nn`.*expected one of: flag, mode, n, name, opt, pair, x"),
    ({"n": 1.5}, r"`demo\.n` must be an integer, got 1\.5"),
    ({"n": True}, r"`demo\.n` must be an integer"),
    ({"x": "big"}, r"`demo\.x` must be a number"),
    ({"flag": 1}, r"`demo\.flag` must be true or false"),
    ({"name": 3}, r"`demo\.name` must be a string"),
    ({"mode": "medium"}, r"`demo\.mode` must be one of \['fast', 'slow'\]"),
    ({"pair": [1]}, r"`demo\.pair` must be a list of 2 values"),
    ({"pair": 5}, r"`demo\.pair` must be a list"),
    ({"pair": [1, "b"]}, r"`demo\.pair\[1\]` must be an integer"),
    ({"opt": "x"}, r"`demo\.opt` must be a number"),
])
def test_rejections_name_the_key(mapping, message):
    with pytest.raises(InputError, match=message):
        from_mapping(Demo, mapping, "demo")


def test_section_not_a_mapping():
    with pytest.raises(InputError, match="section `demo` must be a mapping, got list"):
        from_mapping(Demo, [1, 2], "demo")


def test_range_checks_name_the_parameter():
    with pytest.raises(InputError, match=r"`ratio` must be in \(0\.0, 1\.0\], got 1\.5"):
        from_mapping(MatchParams, {"ratio": 1.5}, "homography.match")
    with pytest.raises(InputError, match=r"`max_features` must be in \[1, 1000000\], got 0"):
        from_mapping(FeaturesParams, {"max_features": 0}, "homography.features")


def test_file_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_params_file(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(InputError, match="not valid YAML"):
        read_params_file(bad)
    top = tmp_path / "list.yaml"
    top.write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="expected a mapping of sections"):
        read_params_file(top)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert read_params_file(empty) == {}
    with pytest.raises(InputError, match="section `homography.match` is missing"):
        load_section(MatchParams, "homography.match", empty)


def test_unsafe_yaml_is_not_executed(tmp_path):
    evil = tmp_path / "evil.yaml"
    evil.write_text("x: !!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(InputError, match="not valid YAML"):
        read_params_file(evil)


def test_params_yaml_agrees_with_dataclass_defaults(repo_root):
    """Defaults are declared once (the dataclasses); params.yaml must say the same for every registered section."""
    data = read_params_file(repo_root / "params.yaml")
    for section, cls in params.SECTIONS.items():
        node = data
        for part in section.split("."):
            assert part in node, f"params.yaml lacks section {section}"
            node = node[part]
        loaded = from_mapping(cls, node, section)
        assert loaded == cls(), f"params.yaml section {section} differs from {cls.__name__} defaults"
        assert set(node) == {f.name for f in dataclasses.fields(cls)}, f"{section}: keys differ from {cls.__name__}"
