"""``python -m sahgrasp``: the ``sahgrasp`` command."""

import sys

from sahgrasp.cli import main

sys.exit(main())
