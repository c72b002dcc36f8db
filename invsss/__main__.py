"""``python -m invsss``: the same as the ``invsss`` command."""

import sys

from .cli import main

sys.exit(main())
