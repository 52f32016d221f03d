"""``python -m gyrostar`` is the ``gyrostar`` command."""

from .cli.console import console

console()
