"""The agent with search at the BS against the reactive agent and the references

``semuav-search RUN_FOLDER [--episodes 100] [--every 10] [--targets 4] [--top M] [--no-rules] [--validation]
[--no-references] [--tuning EVAL_JSON] [--json out.json]``: the table of ``semuav_jax.experiments.search`` for a
finished train.py run folder, the dwell knobs from its eval.json (or ``--tuning``'s; docs/ddqn.md,
"The agent with search"), printed as Markdown.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from baselines.report import BANDWIDTHS
from semuav_jax.agents.runs import CONFIG_FILE, read_config
from semuav_jax.agents.search import SEARCH_EVERY, SEARCH_TARGETS, SEARCH_TOP
from semuav_jax.experiments.search import compare_search, markdown
from semuav_jax.io import atomic_write


def cells(folder: str) -> int | None:
    """How many (bandwidth, seed) lines the search of ``folder`` logs, or None when its config does
    not read (compare_search then says why)."""
    try:
        return len(BANDWIDTHS) * read_config(Path(folder) / CONFIG_FILE).seeds
    except (OSError, ValueError, TypeError, KeyError):
        return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="a finished train.py run folder with its eval.json")
    ap.add_argument("--episodes", type=int, default=100, help="test layouts (the first of keys.TEST_SEED)")
    ap.add_argument("--every", type=int, default=SEARCH_EVERY, help="slots between two decisions")
    ap.add_argument("--targets", type=int, default=SEARCH_TARGETS, help="option agents: candidate devices per decision")
    ap.add_argument(
        "--top", type=int, default=SEARCH_TOP, help="option agents: simulate only the agent's M best options by Q"
    )
    ap.add_argument(
        "--no-rules",
        action="store_true",
        help="option agents: simulate the agent's own options only, no constant options or curve rules",
    )
    ap.add_argument("--validation", action="store_true", help="validation layouts (keys.VALIDATION_SEED): for choosing")
    ap.add_argument(
        "--no-references",
        action="store_true",
        help="against the agent alone: no reference flights, no bound (for choosing the knobs with --validation)",
    )
    ap.add_argument("--tuning", help="the eval.json whose dwell knobs to use (default: the folder's own)")
    ap.add_argument("--json", help="write the numbers here (atomically)")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    # the bar's total and the search share BANDWIDTHS: one value, so the count cannot drift from the call
    with tqdm(total=cells(args.folder), desc="search", unit="seed x B", dynamic_ncols=True) as bar:
        try:
            r = compare_search(
                args.folder,
                args.episodes,
                bandwidths=BANDWIDTHS,
                every=args.every,
                targets=args.targets,
                top=args.top,
                rules=not args.no_rules,
                validation=args.validation,
                tuning=args.tuning,
                references=not args.no_references,
                log=lambda line: (bar.write(line), bar.update()),
            )
        except ValueError as e:
            ap.error(str(e))
    print(markdown(r))
    if args.json:
        atomic_write(args.json, json.dumps(r, indent=1).encode())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
