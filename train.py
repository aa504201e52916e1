"""``python train.py``: the same program as ``semuav-train`` (semuav_jax/cli/train.py)."""

import sys

from semuav_jax.cli.train import main

if __name__ == "__main__":
    sys.exit(main())
