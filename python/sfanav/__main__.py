"""``python -m sfanav``: the ``sfanav`` command."""

import sys

from .app.cli import main

sys.exit(main())
