"""``python -m sdmpi``: the same as the ``sdmpi`` command."""

import sys

from .cli import main

sys.exit(main())
