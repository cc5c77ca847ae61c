"""The machinery of :mod:`cvpipe.params`: the :class:`Section` base model, :class:`Bound`, the one-line messages
and the reading of ``params.yaml`` (the sections themselves are declared in :mod:`cvpipe.params`).

Two rules hold for every field of every section, so that no value reaches OpenCV or a compiled kernel that they
cannot take: a float is finite (NaN and the infinities are refused unless the field says ``Field(allow_inf_nan=
True)``), and an integer fits a C ``int`` (:data:`INT_MIN` .. :data:`INT_MAX`) on each side where its field
declares no limit of its own. :func:`check_field` applies one field's declarations alone: the command-line flags
that set a field go through it (:func:`cvpipe.commands.add_param_options`).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import operator
import os
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar

import annotated_types
import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, create_model, field_validator, model_validator
from pydantic_core import PydanticCustomError

from ..errors import InputError

T = TypeVar("T")

_OPS = {">=": operator.ge, ">": operator.gt, "<=": operator.le}

#: the range of an integer parameter on a side where its field declares no limit: a C ``int``, what OpenCV and the
#: compiled kernels take (a field that is passed on as a wider integer declares its own limit)
INT_MIN, INT_MAX = -(2**31), 2**31 - 1


@dataclasses.dataclass(frozen=True)
class Bound:
    """A limit given by another field of the same section: ``p2: Annotated[int, Bound(">", "p1")]``.

    ``op`` is ``">="``, ``">"`` (a lower limit) or ``"<="`` (an upper limit); the field's own ``Field`` limits still
    apply, and the message shows both.
    """

    op: Literal[">=", ">", "<="]
    other: str


class Section(BaseModel):
    """Base of every ``params.yaml`` section: frozen, unknown keys refused, strict types, :class:`Bound` checked,
    floats finite and integers within a C ``int`` (see the module docstring)."""

    # defer_build: a section's validator is built on its first use, so a command pays only for the sections it uses
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, defer_build=True, allow_inf_nan=False)

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise InputError(_message(type(self), exc, "", data)) from exc

    # pydantic calls an overridden __init__ from model_validate too (whose errors from_mapping words with the
    # section's name); this mark, the one BaseModel.__init__ carries, keeps validation on pydantic's own path
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    @field_validator("*", mode="before")
    @classmethod
    def _exact_choice(cls, value: Any, info: Any) -> Any:
        """A choice matches by type too: pydantic's ``Literal[3, 5, 7]`` takes ``3.0`` even in strict mode."""
        choices = _choices(cls.model_fields[info.field_name].annotation)
        if choices and value is not None and not any(type(value) is type(c) and value == c for c in choices):
            raise PydanticCustomError("literal_error", "not one of the choices", {"expected": str(choices)})
        return value

    @field_validator("*", mode="after")
    @classmethod
    def _c_int(cls, value: Any, info: Any) -> Any:
        """An integer within :data:`INT_MIN` .. :data:`INT_MAX` on the sides its field leaves open."""
        if type(value) is int:
            lo, hi = _int_limits(cls.model_fields[info.field_name])
            if not lo <= value <= hi:
                raise PydanticCustomError("int_range", "not a C int")
        return value

    @model_validator(mode="after")
    def _check_bounds(self):
        for name, info in type(self).model_fields.items():
            for b in info.metadata:
                if isinstance(b, Bound):
                    value, limit = getattr(self, name), getattr(self, b.other)
                    if not _OPS[b.op](value, limit):
                        raise PydanticCustomError("bound", "`{field}` must be {op} `{other}` ({limit}), got {value}",
                                                  {"field": name, "op": b.op, "other": b.other, "limit": limit,
                                                   "value": value})
        return self

    def replace(self: T, **changes: Any) -> T:
        """A validated copy with ``changes`` (``dataclasses.replace`` for a section).

        Examples
        --------
        >>> from cvpipe.params import MatchParams
        >>> MatchParams().replace(ratio=0.7).ratio
        0.7
        >>> MatchParams().replace(ratio=0.0)
        Traceback (most recent call last):
        ...
        cvpipe.errors.InputError: `ratio` must be in (0.0, 1.0], got 0.0
        """
        return type(self)(**{**dict(self), **changes})


def replace(obj: T, /, **changes: Any) -> T:
    """``dataclasses.replace`` that also takes a :class:`Section` (validated, unlike ``model_copy(update=...)``)."""
    if isinstance(obj, Section):
        return obj.replace(**changes)
    return dataclasses.replace(obj, **changes)


def section_or_default(params: Any, cls: type[T], section: str) -> T:
    """``params`` when it is a ``cls`` (the ``section`` of ``params.yaml``), ``cls()`` when it is None: the type check
    of every entry point that takes a section.

    Raises
    ------
    InputError
        ``params`` is neither None nor a ``cls``; the one-line message names ``params``.

    Examples
    --------
    >>> from cvpipe.params import MatchParams
    >>> section_or_default(None, MatchParams, "homography.match").ratio
    0.8
    >>> section_or_default({"ratio": 0.7}, MatchParams, "homography.match")
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `params` must be a MatchParams (the homography.match section), got dict
    """
    if params is None:
        return cls()
    if not isinstance(params, cls):
        raise InputError(f"`params` must be a {cls.__name__} (the {section} section), got {type(params).__name__}")
    return params


def _int_limits(info: Any) -> tuple[int | float, int | float]:
    """The (lo, hi) that the C ``int`` rule sets for an integer field: :data:`INT_MIN` / :data:`INT_MAX` on a side
    the field leaves open, none (an infinity) on a side where it declares its own limit, which pydantic checks."""
    lo: int | float = INT_MIN
    hi: int | float = INT_MAX
    for m in info.metadata:
        if isinstance(m, (annotated_types.Gt, annotated_types.Ge)):
            lo = -float("inf")
        elif isinstance(m, (annotated_types.Lt, annotated_types.Le)):
            hi = float("inf")
    return lo, hi


def _range(info: Any, bound: Bound | None = None, limit: Any = None) -> str:
    """``"[0, 1.0]"``, ``"(0.0, inf)"``, ``"[1, 2147483647]"``... from a field's ``Field`` limits (an integer's open
    side is the C ``int``'s, a float's is infinite and excluded), ``bound`` (set to ``limit``) replacing the side it
    sets."""
    lo, hi = ("[-2147483648", "2147483647]") if info.annotation is int else ("(-inf", "inf)")
    for m in info.metadata:
        if isinstance(m, annotated_types.Gt):
            lo = f"({m.gt!r}"
        elif isinstance(m, annotated_types.Ge):
            lo = f"[{m.ge!r}"
        elif isinstance(m, annotated_types.Lt):
            hi = f"{m.lt!r})"
        elif isinstance(m, annotated_types.Le):
            hi = f"{m.le!r}]"
    if bound is not None and bound.op == "<=":
        hi = f"{limit!r}]"
    elif bound is not None:
        lo = f"{'[' if bound.op == '>=' else '('}{limit!r}"
    return f"{lo}, {hi}"


def _choices(tp: Any) -> list | None:
    """The values of a ``Literal`` annotation (inside ``Optional``), else None."""
    if typing.get_origin(tp) is Literal:
        return list(typing.get_args(tp))
    for arg in typing.get_args(tp):
        if (found := _choices(arg)) is not None:
            return found
    return None


_TYPE_WORDS = {
    "int_type": "an integer", "int_from_float": "an integer", "float_type": "a number", "bool_type": "true or false",
    "string_type": "a string", "tuple_type": "a list", "list_type": "a list", "finite_number": "a finite number",
}
#: the error kinds of a value outside a field's range
_RANGE_KINDS = ("bound", "greater_than", "greater_than_equal", "less_than", "less_than_equal", "int_range")


def _message(cls: type[BaseModel], exc: ValidationError, section: str, data: Any) -> str:
    """One line for the first error of ``exc``, naming the dotted key (``section.field``) and what it accepts.

    ``data`` is what was validated: a limit set by another field (:class:`Bound`) is read from it."""
    err = exc.errors(include_url=False)[0]
    kind, value, ctx = err["type"], err.get("input"), err.get("ctx") or {}
    key, model, owner, info, tuple_key, node, parent = section, cls, cls, None, section, data, None
    if kind == "bound":
        loc = (*err["loc"], ctx["field"])
    else:
        loc = err["loc"]
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
        elif isinstance(model, type) and issubclass(model, BaseModel) and part in model.model_fields:
            info = model.model_fields[part]
            key = tuple_key = f"{key}.{part}" if key else part
            owner, parent, model = model, node, info.annotation
            node = dict(node).get(part) if isinstance(node, (dict, BaseModel)) else None
        elif kind == "extra_forbidden" and part == loc[-1]:  # the unknown key itself
            key = f"{key}.{part}" if key else part
    if kind == "extra_forbidden":
        return f"unknown key `{key}` in params; expected one of: {', '.join(sorted(model.model_fields))}"
    if kind in _RANGE_KINDS:
        bound = next((b for b in info.metadata if isinstance(b, Bound)), None)
        if bound is None:
            return f"`{key}` must be in {_range(info)}, got {value!r}"
        prefix = tuple_key.rpartition(".")[0]
        given = dict(parent) if isinstance(parent, (dict, BaseModel)) else {}
        limit = ctx["limit"] if kind == "bound" else given.get(bound.other, owner.model_fields[bound.other].default)
        value = ctx["value"] if kind == "bound" else value
        side = "upper" if bound.op == "<=" else "lower"
        return (f"`{tuple_key}` must be in {_range(info, bound, limit)}, got {value!r} (the {side} limit is "
                f"`{prefix + '.' if prefix else ''}{bound.other}`)")
    if kind == "literal_error":
        return f"`{key}` must be one of {_choices(info.annotation)}, got {value!r}"
    if kind in ("missing", "too_short", "too_long") and info is not None:
        n = len(typing.get_args(info.annotation))
        return f"`{tuple_key}` must be a list of {n} values, got {list(value) if isinstance(value, tuple) else value!r}"
    if kind in _TYPE_WORDS:
        return f"`{key}` must be {_TYPE_WORDS[kind]}, got {value!r}"
    if kind == "model_type" and info is not None:
        return f"`{key}` must be a {ctx.get('class_name', 'section')}, got {type(value).__name__}"
    if kind == "must":  # a field's own check (:func:`must`) says what it accepts
        return f"`{key}` {err['msg']}, got {list(value) if isinstance(value, tuple) else value!r}"
    return f"`{key}`: {err['msg']}, got {value!r}"


def must(accepts: str) -> PydanticCustomError:
    """The error a field's own check raises (an ``AfterValidator`` in its annotation); ``accepts`` completes "`key`
    must ...", and the message adds the value (a tuple as a list, as params.yaml writes it): ``must("be two odd
    sizes ...")`` -> "`stereo.sgm.census_size` must be two odd sizes ..., got [4, 5]"."""
    return PydanticCustomError("must", "must " + accepts.replace("{", "{{").replace("}", "}}"))


@functools.cache
def _one_field(cls: type[Section], name: str) -> type[Section]:
    """A section of the field ``name`` of ``cls`` alone, with its type, limits and own checks but no :class:`Bound`
    (the limit another field sets)."""
    field = copy.copy(cls.model_fields[name])
    # the FieldInfo itself, not an Annotated type: typing caches those by equality, and Ge(0) would show Ge(0.0)
    field.metadata = [m for m in field.metadata if not isinstance(m, Bound)]
    return create_model(f"{cls.__name__}_{name}", __base__=Section, **{name: (field.annotation, field)})


def check_field(cls: type[Section], name: str, value: Any) -> Any:
    """``value`` checked by the declarations of field ``name`` of the section ``cls`` alone: its type, its range and
    choices, its own checks and the two rules of every field (finite floats, C ``int`` integers); a limit that
    another field sets (:class:`Bound`) is checked when the section is built.

    Raises
    ------
    InputError
        One line naming ``name`` and what it accepts.

    Examples
    --------
    >>> from cvpipe.params import HoughLinesParams
    >>> check_field(HoughLinesParams, "threshold", 120)
    120
    >>> check_field(HoughLinesParams, "threshold", 2**32)
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `threshold` must be in [1, 2147483647], got 4294967296
    """
    return getattr(_one_field(cls, name)(**{name: value}), name)


def from_mapping(cls: type[T], mapping: Any, section: str) -> T:
    """Build the section model ``cls`` from a mapping, refusing unknown keys, wrong types and values out of range.

    Parameters
    ----------
    cls : Section subclass
        The model of the section.
    mapping : dict or None
        The section's keys; missing keys take the model defaults. YAML lists become tuples for tuple fields.
    section : str
        The dotted section name, used in messages (``"logo.match"``).

    Returns
    -------
    Section
        The validated, frozen parameters.

    Raises
    ------
    InputError
        One line naming the dotted key (``logo.match.ratio``) and its range or choices.

    Examples
    --------
    >>> from cvpipe.params import MatchParams, StereoSgmParams
    >>> from_mapping(MatchParams, {"ratio": 0.7}, "homography.match").ratio
    0.7
    >>> from_mapping(StereoSgmParams, {"paths": 6}, "stereo.sgm")
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `stereo.sgm.paths` must be one of [4, 8], got 6
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, dict):
        raise InputError(f"params section `{section}` must be a mapping, got {type(mapping).__name__}")
    fields = cls.model_fields
    data = {k: tuple(v) if isinstance(v, list) and k in fields and typing.get_origin(fields[k].annotation) is tuple
            else v for k, v in mapping.items()}
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        raise InputError(_message(cls, exc, section, data)) from exc


def read_params_file(path: str | os.PathLike = "params.yaml") -> dict:
    """The whole ``params.yaml`` as a dict (``yaml.safe_load``)."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise InputError(f"{p}: not valid YAML ({exc})") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{p}: expected a mapping of sections at the top level, got {type(data).__name__}")
    return data


def load_section(cls: type[T], section: str, path: str | os.PathLike = "params.yaml") -> T:
    """Load the dotted ``section`` (``"logo.match"``) of ``params.yaml`` into ``cls``."""
    node: Any = read_params_file(path)
    for part in section.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"{path}: section `{section}` is missing")
        node = node[part]
    return from_mapping(cls, node, section)
