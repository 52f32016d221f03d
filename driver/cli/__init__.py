"""The ``gyrostar`` command line (see :mod:`gyrostar.cli.main`)."""
