"""``python eval.py``: the same program as ``semuav-eval`` (semuav_jax/cli/eval.py)."""

import sys

from semuav_jax.cli.eval import main

if __name__ == "__main__":
    sys.exit(main())
