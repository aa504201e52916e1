"""``python -m semuav_jax.jscc``: the command of ``semuav_jax.cli.jscc``."""

if __name__ == "__main__":
    import sys

    from semuav_jax.cli.jscc import main

    sys.exit(main())
