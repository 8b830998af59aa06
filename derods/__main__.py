"""``python -m derods``: the command line (:mod:`derods.apps.cli`)."""

import sys

from .apps.cli import main

if __name__ == "__main__":
    sys.exit(main())
