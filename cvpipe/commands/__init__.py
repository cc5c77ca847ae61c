"""One module per `cvpipe` subcommand.

Each module defines ``HELP`` (one line), ``EXAMPLE`` (one command line), ``add_arguments(parser)`` and
``run(args) -> int``. ``cvpipe.cli`` lists them in ``COMMANDS``; a module that is absent is simply not offered.
"""
