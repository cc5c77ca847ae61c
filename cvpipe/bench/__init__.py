"""Benchmarks on the real data sets (``cvpipe bench <task> --data DIR``).

Each module has the same interface as the subcommand modules in ``cvpipe.commands``. Benchmarks print ratios
against the baseline measured in the same process; they never assert on time.
"""
