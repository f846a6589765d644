"""The ``slipstep`` command line: ``main`` (run, compare, cases, check, ...) and the commands it
plugs in (``frf``, ``sweep``, ``post``/``report``); the console script is ``slipstep.cli.main:app``."""
