"""The exceptions cvpipe raises.

``InputError`` is bad input (a file, a parameter): the CLI exits with status 2.
``EstimationError`` means the algorithm ran but could not produce a result (too few matches, degenerate points):
the CLI exits with status 1. Both derive from the builtin a caller would naturally catch.

Every error may carry the file it is about (``file``, a path string or None); the CLI puts it in the JSON record
``{"error", "file", "exit"}`` that ``--json`` prints on failure.

:func:`check_int` is the one check of an integer parameter at a public boundary.
"""

from __future__ import annotations

from numbers import Integral


class CvpipeError(Exception):
    """Base class of every error cvpipe raises on purpose.

    Parameters
    ----------
    message : str
        One line saying what is wrong and what to change.
    file : str or path-like, optional
        The file the error is about.
    """

    #: the CLI's exit status for this kind of error
    exit_code = 1

    def __init__(self, *args, file=None):
        super().__init__(*args)
        self.file = None if file is None else str(file)


class InputError(CvpipeError, ValueError):
    """An input file or parameter is missing, unreadable or out of range."""

    exit_code = 2


class EstimationError(CvpipeError, RuntimeError):
    """The algorithm could not produce a result from valid input; the message says what to tune."""

    exit_code = 1


class BudgetError(InputError):
    """A buffer the input and parameters ask for exceeds the memory budget; the message names what to change."""


class BudgetWarning(UserWarning):
    """Work was scaled down to stay within the memory budget (the CLI prints it as one ``cvpipe: note:`` line)."""


#: default memory budget of one command, in GB (10^9 bytes); ``CVPIPE_MEMORY_BUDGET_GB`` overrides it
DEFAULT_MEMORY_BUDGET_GB = 4.0


def memory_budget() -> int:
    """The memory budget in bytes: ``$CVPIPE_MEMORY_BUDGET_GB`` (a positive number of GB) or 4 GB.

    Every large buffer (Hough accumulator, stereo cost volumes, keypoint sets, panorama canvases) is checked against
    it before it is allocated; over it, the command refuses with one line naming what to change.
    """
    import math
    import os

    raw = os.environ.get("CVPIPE_MEMORY_BUDGET_GB", "").strip()
    if not raw:
        return int(DEFAULT_MEMORY_BUDGET_GB * 1e9)
    try:
        gb = float(raw)
    except ValueError:
        gb = float("nan")
    if not (math.isfinite(gb) and gb > 0):
        raise InputError(f"CVPIPE_MEMORY_BUDGET_GB must be a positive number of GB, got {raw!r}")
    return int(gb * 1e9)


def check_memory(nbytes: float, what: str, change: str) -> None:
    """Raise :class:`BudgetError` when a buffer of ``nbytes`` would exceed :func:`memory_budget`.

    Parameters
    ----------
    nbytes : float
        Size of the buffer (or buffers) about to be allocated.
    what : str
        What the buffer is, e.g. ``"the Hough accumulator (36000000 angles x 2 distances)"``.
    change : str
        What to change, naming the parameter, e.g. ``"raise `--theta-deg` or `--rho`"``.
    """
    budget = memory_budget()
    if nbytes > budget:
        raise BudgetError(f"{what} needs {nbytes / 1e9:.3g} GB, over the memory budget of {budget / 1e9:.3g} GB; "
                          f"{change} (or raise CVPIPE_MEMORY_BUDGET_GB)")


def check_int(name: str, value: object, minimum: int | None = None, maximum: int | None = None, *,
              note: str | None = None, source: str | None = None) -> int:
    """``value`` as an ``int`` when it is an integer in ``[minimum, maximum]``; else :class:`InputError` naming the
    parameter and the allowed range.

    Parameters
    ----------
    name : str
        The parameter as its caller spells it (``"max_iters"``, ``"compute.workers"``).
    value : object
        A Python or NumPy integer. A bool, a float (even a whole one) or anything else is refused.
    minimum, maximum : int, optional
        Inclusive bounds; None leaves that side open.
    note : str, optional
        What a special value means, added to the range in parentheses (``"0 = one per core"``).
    source : str, optional
        Where the value was read from (a file): the message starts with it and the error carries it as ``file``.

    Returns
    -------
    int
        ``value``.

    Raises
    ------
    InputError
        ``"`name` must be an integer >= minimum, got value"`` (``<= maximum``, ``in [minimum, maximum]``).

    Examples
    --------
    >>> check_int("max_iters", 100, 1)
    100
    >>> check_int("tiles", 0, 1)
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `tiles` must be an integer >= 1, got 0
    >>> check_int("bands", True, 1, 12)
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `bands` must be an integer in [1, 12], got True
    """
    if not isinstance(value, bool) and isinstance(value, Integral) and \
            (minimum is None or value >= minimum) and (maximum is None or value <= maximum):
        return int(value)
    if minimum is not None and maximum is not None:
        allowed = f" in [{minimum}, {maximum}]"
    elif minimum is not None:
        allowed = f" >= {minimum}"
    elif maximum is not None:
        allowed = f" <= {maximum}"
    else:
        allowed = ""
    if note:
        allowed += f" ({note})"
    where = f"{source}: " if source else ""
    raise InputError(f"{where}`{name}` must be an integer{allowed}, got {value!r}", file=source)


def require_extra(module: str, extra: str, needed_for: str):
    """Import ``module`` of an optional dependency, or raise :class:`InputError` naming the extra that installs it.

    ``pip install cvpipe`` brings the library and the commands; the pipeline (dvc), Dask and the bundled samples'
    renderers come with the extras ``cvpipe[pipeline]``, ``cvpipe[dask]`` and ``cvpipe[samples]``.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise InputError(f"{needed_for} needs the Python package {module.split('.')[0]!r}, which the {extra!r} "
                         f"extra installs: pip install 'cvpipe[{extra}]'") from exc
