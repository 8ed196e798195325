"""The ``lfproc`` command line: a thin layer over the library (installed as ``lfproc.cli``).

Each sub-command lives in its own module here, with ``register(subparsers)`` adding its
parser and a ``run(args) -> int`` function that parses nothing further, calls library
functions and prints. :mod:`lfproc.cli.main` lists the sub-commands.
"""
