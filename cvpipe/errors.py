"""The exceptions cvpipe raises.

``InputError`` is bad input (a file, a parameter): the CLI exits with status 2.
``EstimationError`` means the algorithm ran but could not produce a result (too few matches, degenerate points):
the CLI exits with status 1. Both derive from the builtin a caller would naturally catch.
"""


class CvpipeError(Exception):
    """Base class of every error cvpipe raises on purpose."""


class InputError(CvpipeError, ValueError):
    """An input file or parameter is missing, unreadable or out of range."""


class EstimationError(CvpipeError, RuntimeError):
    """The algorithm could not produce a result from valid input; the message says what to tune."""
