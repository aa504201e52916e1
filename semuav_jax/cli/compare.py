"""``semuav-compare`` (or ``python -m semuav_jax.cli.compare``): a finished train.py run's seeds
against the tuned baselines and both planners (``semuav_jax.experiments.learned``, docs/ddqn.md)."""

from __future__ import annotations

import argparse
import sys

from semuav_jax.experiments.learned import evaluate_run, markdown, validation_table


def main(argv: list[str] | None = None) -> int:
    """``semuav-compare RUN``: (re)write RUN/eval.json and eval.md; ``--validation RUN [RUN ...]``:
    print the seeds' mean PSNR on validation layouts."""
    ap = argparse.ArgumentParser(description="Compare a train.py run's seeds with the tuned baselines and the planner.")
    ap.add_argument("run", nargs="+", help="a finished train.py run folder (several with --validation)")
    ap.add_argument("--episodes", type=int, default=1000, help="test layouts (default: %(default)s)")
    ap.add_argument(
        "--validation-episodes", type=int, default=500, help="layouts that choose v_b* (default: %(default)s)"
    )
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--validation",
        action="store_true",
        help="only the agents, on --validation-episodes validation layouts at 5/20/25/40 kHz "
        "(for choosing settings; writes nothing)",
    )
    ap.add_argument(
        "--references",
        action="store_true",
        help="with --validation: also greedy-dwell and TSP-dwell, tuned on the same validation layouts",
    )
    args = ap.parse_args(argv)
    if min(args.validation_episodes, args.workers) < 1 or args.episodes < 2:
        ap.error("--episodes must be >= 2 (its intervals need two), --validation-episodes and --workers >= 1")
    if args.references and not args.validation:
        ap.error("--references goes with --validation")
    if len(args.run) > 1 and not args.validation:
        ap.error("several run folders need --validation")
    try:
        if args.validation:
            refs = args.references
            print(validation_table(args.run, args.validation_episodes, references=refs, workers=args.workers))
            return 0
        r = evaluate_run(args.run[0], args.episodes, args.validation_episodes, args.workers)
    except (ValueError, KeyError, OSError) as e:
        print(f"learned: error: {e}", file=sys.stderr)
        return 2
    print(markdown(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
