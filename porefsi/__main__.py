"""``python -m porefsi``: the command line."""

import sys

from porefsi.cli import main

sys.exit(main())
