"""``python -m gcsd``: the same as the ``gcsd`` command."""

import sys

from gcsd.daemon.cli import main

if __name__ == "__main__":
    sys.exit(main())
