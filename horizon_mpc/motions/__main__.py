"""``python -m horizon_mpc.motions <leap|turn|walk> [...]``: see :mod:`horizon_mpc.motions.cli`."""

import sys

from horizon_mpc.motions.cli import main

if __name__ == "__main__":
    sys.exit(main())
