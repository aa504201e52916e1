"""The Markdown of the reference table (docs/baselines.md) from :func:`baselines.report.report`'s
numbers: how a row names its setting, the table, the exact planner's and dwell-switch's margins
and the exact planner's flights against the bound's relaxation."""

from __future__ import annotations


def setting(s: dict) -> str:
    """How a row names its setting: the speed v_b, the dwell knobs, or 'plan'."""
    if "knobs" in s:
        v, k, m = s["knobs"]
        return f"v_c {v:g}, k* {k:g}, margin {m:g} s"
    if "switch" in s:
        v, m = s["switch"]
        return f"v_c {v:g}, margin {m:g} s, k* by simulation"
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
    lines += [
        "",
        "| B (kHz) | exact planner − best of planner, greedy-dwell, TSP-dwell (paired 95 % CI) | "
        "dwell-switch − best of those and the exact planner | bound − exact planner | bound − dwell-switch "
        "| planner − greedy at v_b* |",
        "|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        e, w, g = row["exact_minus_best"], row["switch_minus_best"], row["planner_minus_tuned_greedy"]
        b, bw = row["bound_minus_exact"], row["bound_minus_switch"]
        lines.append(
            f"| {row['B'] / 1e3:g} | {e['diff'][0]:+.2f} ± {e['diff'][1]:.2f} (vs {e['vs']}) | "
            f"{w['diff'][0]:+.2f} ± {w['diff'][1]:.2f} (vs {w['vs']}) | "
            f"{b[0]:.2f} ± {b[1]:.2f} | {bw[0]:.2f} ± {bw[1]:.2f} | {g[0]:+.2f} ± {g[1]:.2f} |"
        )
    lines += [
        "",
        "Exact planner against the bound's relaxation (means over the test layouts; docs/baselines.md):",
        "",
        "| B (kHz) | seconds with data | without data, flown | dead seconds the relaxation allows (same discs) "
        "| unused after arrival | symbols per second with data / (R0 / β) |",
        "|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        a = row["account"]
        lines.append(
            f"| {row['B'] / 1e3:g} | {a['data_s']:.1f} | {a['dead_s']:.1f} | {a['relaxed_dead_s']:.1f} | "
            f"{a['unused_s']:.1f} | {a['rate_share']:.2f} |"
        )
    lines += ["", f"Wall time: {r['wall_s']:.0f} s"]
    return "\n".join(lines)
