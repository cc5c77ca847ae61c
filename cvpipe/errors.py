"""The exceptions cvpipe raises.

``InputError`` is bad input (a file, a parameter): the CLI exits with status 2.
``EstimationError`` means the algorithm ran but could not produce a result (too few matches, degenerate points):
the CLI exits with status 1. Both derive from the builtin a caller would naturally catch.

Every error may carry the file it is about (``file``, a path string or None); the CLI puts it in the JSON record
``{"error", "file", "exit"}`` that ``--json`` prints on failure.
"""

from __future__ import annotations


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
