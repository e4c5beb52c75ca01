"""``python -m topomech``: the command line."""

import sys

from topomech.cli import main

sys.exit(main())
