"""Bad input to a benchmark as jellysim's own commands treat it: one line, exit status 2.

A benchmark that reads scenes and ``--set KEY=VALUE`` runs its ``main`` through :func:`run_main`:
an unknown key, a bad value, an unknown preset or a checkpoint of another scene (jellysim's
``InputError``) then ends it with the message on stderr and exit status 2, not a traceback.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

from jellysim.errors import InputError


def run_main(main: Callable[[], object]) -> None:
    """Call ``main``; a jellysim ``InputError`` from it ends the process in one line, exit 2."""
    try:
        main()
    except InputError as error:
        print(f"{Path(sys.argv[0]).name}: error: {error}", file=sys.stderr)
        sys.exit(2)
