"""``python -m gyrostar`` is the ``gyrostar`` command."""

import sys

from .cli.main import main

sys.exit(main())
