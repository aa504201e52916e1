"""The command-line programs (``semuav-train``, ``semuav-eval``; the root ``train.py`` and
``eval.py`` are shims for them): the top floor, free to import every other part of the package."""
