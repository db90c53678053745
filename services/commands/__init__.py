"""One module per `navlearn` sub-command.

Each module defines ``register(subparsers)`` which adds its sub-command(s) and
sets ``func`` on the parser to a callable taking the parsed ``argparse.Namespace``
and returning an exit code. Heavy imports (torch, zenoh, matplotlib) belong
inside that callable so that ``navlearn --help`` stays fast.
"""
