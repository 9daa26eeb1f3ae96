"""``python -m jellysim``: the command line."""

import sys

from jellysim.cli.main import main

sys.exit(main())
