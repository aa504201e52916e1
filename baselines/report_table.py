"""The Markdown of the reference table (docs/baselines.md) from :func:`baselines.report.report`'s
numbers: how a row names its setting, the table, the margins of plan-switch, the exact planner and
dwell-switch, and the planners' flights against the bound's relaxation."""

from __future__ import annotations


def setting(s: dict) -> str:
    """How a row names its setting: the speed v_b, the dwell knobs, an agent's expert (its k) or 'plan'."""
    if "knobs" in s:
        v, k, m = s["knobs"]
        return f"v_c {v:g}, k* {k:g}, margin {m:g} s"
    if "switch" in s:
        v, m = s["switch"]
        return f"v_c {v:g}, margin {m:g} s, k* by simulation" + (", exact plan" if s["v_b"] is None else "")
    if "expert_k" in s:
        return f"options 1st along the tour, k {s['expert_k']:g}"
    return "plan" if s["v_b"] is None else f"{s['v_b']:g}"


def reference_line(B: float, name: str, s: dict) -> str:
    """A reference's table row: bandwidth, name, setting, mean PSNR ± CI, coverage, arrival."""
    return (
        f"| {B / 1e3:g} | {name} | {setting(s)} | {s['mean_psnr']:.2f} ± {s['ci95']:.2f} | "
        f"{s['coverage']:.2f} | {100 * s['arrived']:.1f} % |"
    )


def markdown(r: dict) -> str:
    lines = [
        f"{r['episodes']} test layouts (seed {r['test_seed']}); v_b* and dwell knobs from {r['tuning']['episodes']} "
        f"validation layouts (seed {r['validation_seed']}), N = {r['N']}",
        "",
        "| B (kHz) | policy | setting (m/s) | mean PSNR (dB) ± 95 % CI | coverage | arrival | unused time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        for name, s in row["policies"].items():
            lines.append(reference_line(row["B"], name, s) + f" {s['unused_s']:.1f} |")
        lines.append(f"| {row['B'] / 1e3:g} | bound (no policy that arrives exceeds) | | {row['bound']:.2f} | | | |")
    diff = lambda d: f"{d['diff'][0]:+.2f} ± {d['diff'][1]:.2f} (vs {d['vs']})"
    ci = lambda d: f"{d[0]:.2f} ± {d[1]:.2f}"
    lines += [
        "",
        "| B (kHz) | plan-switch − best of planner, greedy-dwell, TSP-dwell (paired 95 % CI) | plan-switch − best "
        "of all others | exact planner − best of planner, greedy-dwell, TSP-dwell | dwell-switch − best of those "
        "and the exact planner | bound − plan-switch | bound − exact planner | bound − dwell-switch "
        "| planner − greedy at v_b* |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        keys = ("plan_switch_minus_target", "plan_switch_minus_best", "exact_minus_best", "switch_minus_best")
        bounds = ("bound_minus_plan_switch", "bound_minus_exact", "bound_minus_switch")
        g = row["planner_minus_tuned_greedy"]
        lines.append(
            f"| {row['B'] / 1e3:g} | "
            + " | ".join([diff(row[k]) for k in keys] + [ci(row[k]) for k in bounds])
            + f" | {g[0]:+.2f} ± {g[1]:.2f} |"
        )
    lines += [
        "",
        "The exact planner and plan-switch against the bound's relaxation (means over the test layouts; "
        "docs/baselines.md):",
        "",
        "| B (kHz) | policy | seconds with data | without data, flown | dead seconds the relaxation allows "
        "(same discs) | unused after arrival | of which with an unserved device in reach "
        "| symbols per second with data / (R0 / β) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        for name, a in row["account"].items():
            lines.append(
                f"| {row['B'] / 1e3:g} | {name} | {a['data_s']:.1f} | {a['dead_s']:.1f} | {a['relaxed_dead_s']:.1f} | "
                f"{a['unused_s']:.1f} | {a['unused_in_reach_s']:.1f} | {a['rate_share']:.2f} |"
            )
    lines += ["", f"Wall time: {r['wall_s']:.0f} s"]
    return "\n".join(lines)
