"""``python -m topomech``: the command line. A Ctrl-C while the package is still being
imported exits 130 quietly too (the command line answers one during a command itself)."""

import sys

try:
    from topomech.cli import main
except KeyboardInterrupt:
    sys.exit(130)

sys.exit(main())
