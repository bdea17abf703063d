"""Write docs/benchmarks.md from the result lines in benchmarks/results/*.jsonl.

Every figure in that page comes from a line here, with its commit, date, machine and the
command that made it; lines from trees with uncommitted changes are left out. Groups of lines
are summarised (mean and spread over seeds, mean over scenes); ``--compare BASE NEW`` adds a
table of two commits' fits paired by scene, seed, preset and budget on the same machine;
``--same-as OLD NEW`` lets OLD's preset fits stand beside NEW's variants where NEW repeats them
(checked on every fit both commits made).

    python benchmarks/report.py                                  # writes docs/benchmarks.md
    python benchmarks/report.py --compare cf67ae4 4d2c1e0 --check
    python benchmarks/report.py --readme 4d2c1e0     # and README.md's results table
"""

from __future__ import annotations

import argparse
import re
import statistics
from collections import defaultdict
from pathlib import Path

import common

from hybridneus.simulate.generated import SCARCE_KINDS

DOC = common.REPO / "docs" / "benchmarks.md"


def _cpu(line: dict) -> str:
    m = line.get("machine", {})
    if m.get("gpu"):
        return m["gpu"]
    threads = line.get("threads")
    # 0 or None: the library's own default, all cores
    return f"{m.get('cpu', '?')}, {threads or m.get('cores', 'all')} threads"


def _budget(line: dict) -> str:
    """The budget, and the meshed volume where it is the crop's box: lines meshed over the
    whole cube (older ones) and over the crop score the same fit differently, so no table
    pairs or averages the two."""
    budget = common.budget_label(line)
    return f"{budget}, meshed over the crop" if common.meshed_over_crop(line) else budget


def _command_lines(rows: list[dict]) -> list[str]:
    """A section's closing lines: every command that made its rows, once, in order."""
    commands = dict.fromkeys(f"Command: `{r['command']}`" for r in rows)
    return ["", "  \n".join(commands), ""]


def _f(v, digits: int = 4) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _spread(values: list[float]) -> str:
    if len(values) < 2:
        return "-"
    return f"{min(values):.4f}-{max(values):.4f}"


def _kind(scene: str) -> str:
    return scene.split("-")[1] if scene.startswith("gen-") else scene


def _groups(scene: str) -> list[str]:
    """The mean rows a scene counts in."""
    if not scene.startswith("gen-"):
        return ["assets"]
    if _kind(scene) in SCARCE_KINDS:
        return ["generated", f"generated, {'/'.join(SCARCE_KINDS)}"]
    return ["generated"]


def base_preset(preset: str) -> str:
    """The preset a variant's name starts with: ``fast priors.hull.enabled=false`` (a
    ``--set`` override) and ``fast+train.view_balance=1`` (a preset spec) -> ``fast``."""
    return re.split(r"[ +]", preset, maxsplit=1)[0]


def _run_key(r: dict) -> tuple:
    return (r["commit"], _budget(r), _cpu(r))


def _with_base(lines: list[dict]) -> set[tuple]:
    """(commit, budget, machine, variant) of the variants whose preset has fits in the same
    (commit, budget, machine)."""
    presets = {(*_run_key(r), r["preset"]) for r in lines}
    return {(*k, p) for *k, p in presets
            if base_preset(p) != p and (*k, base_preset(p)) in presets}


def _how(r: dict) -> str:
    """How a suite line was made, in a form shared by every line of the same run.

    compare_commits.py stamps each fit with the run_suite call it made for that one scene
    and seed; the comparison's own command is what reruns them all."""
    command = r["command"].split(" (fits with the commit's ")[0]
    fitted = r.get("fit_command")
    if fitted and fitted != r["command"]:
        return f"`{fitted}`, scored by `{command}`"
    return f"`{command}`"


def _runs(lines: list[dict]):
    """``lines`` grouped by (commit, preset, budget, machine), oldest first: yields each key,
    its lines, and its lines by scene as (scene, lines) pairs, assets before generated
    objects."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in lines:
        groups[(r["commit"], r["preset"], _budget(r), _cpu(r))].append(r)
    for key, rows in sorted(groups.items(), key=lambda kv: (kv[1][0]["date"], kv[0])):
        by_scene: dict[str, list[dict]] = defaultdict(list)
        for r in rows:
            by_scene[r["scene"]].append(r)
        yield key, rows, [(scene, by_scene[scene]) for scene in
                          sorted(by_scene, key=lambda s: (s.startswith("gen-"), s))]


def suite_section(lines: list[dict]) -> list[str]:
    """Accuracy: per (commit, preset, budget, machine) the mean CD per scene over seeds;
    variants with their preset beside them are in :func:`variant_section` instead."""
    paired = _with_base(lines)
    alone = [r for r in lines if (*_run_key(r), r["preset"]) not in paired]
    out = ["## Accuracy", "",
           "Chamfer distance (the paper's protocol, lower is better) of `hybridneus mesh`'s "
           "mesh against the simulator's ground truth; per scene the mean over seeds and "
           "their range. `gen-<kind>-<seed>` are generated objects "
           "(`hybridneus.simulate.generated`); their means are per kind.", ""]
    for (commit, preset, budget, cpu), rows, scenes in _runs(alone):
        dates = sorted(r["date"][:10] for r in rows)
        hows = list(dict.fromkeys(_how(r) for r in rows))  # each command once, in order
        how = ("command: " if len(hows) == 1 else "commands: ") + "; ".join(hows)
        out += [f"### `{preset}`, {budget}, commit {commit}, {cpu}", "",
                f"{len(rows)} fits, {dates[0]} to {dates[-1]}; {how}", "",
                "| scene | seeds | CD mean | CD range | F@1% | steps | longest wall s "
                "| first step s |",
                "|---|---|---|---|---|---|---|---|"]
        means: dict[str, list[float]] = defaultdict(list)
        for scene, rs in scenes:
            cds = [r["chamfer"] for r in rs if r.get("chamfer") is not None]
            failed = len(rs) - len(cds)
            mean = statistics.mean(cds) if cds else None
            if mean is not None:
                for group in _groups(scene):
                    means[group].append(mean)
            fs = [r["fscore"] for r in rs if r.get("fscore") is not None]
            note = f" ({failed} without a surface)" if failed else ""
            firsts = [r["first_step_s"] for r in rs if r.get("first_step_s") is not None]
            out.append(f"| {scene} | {len(rs)}{note} | {_f(mean)} | {_spread(cds)} | "
                       f"{_f(statistics.mean(fs) if fs else None, 3)} | "
                       f"{round(statistics.mean(r['steps'] for r in rs))} | "
                       f"{max(r.get('fit_wall_s', 0) for r in rs):.0f} | "
                       f"{_f(max(firsts) if firsts else None, 1)} |")
        for name, values in means.items():
            out.append(f"| **mean, {name}** | | **{statistics.mean(values):.4f}** | | | | | |")
        out.append("")
    return out


def _fit_key(r: dict) -> tuple:
    return (r["scene"], r["seed"], r["preset"], _budget(r), _cpu(r))


def compare_section(lines: list[dict], base: str, new: str) -> list[str]:
    """Two commits' fits paired by scene, seed, preset, budget and machine."""
    a = {_fit_key(r): r for r in lines if r["commit"] == base}
    b = {_fit_key(r): r for r in lines if r["commit"] == new}
    pairs = sorted(set(a) & set(b))
    if not pairs:
        return [f"No fits of both {base} and {new} to pair.", ""]
    out = [f"## {new} against {base}", "",
           "The same fits on the same machine, run interleaved; per scene the mean over seeds "
           "and the range.", "",
           "| scene | preset | budget | seeds | CD " + base + " | range | CD " + new
           + " | range | change | worse beyond the spread |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple, list[tuple]] = defaultdict(list)
    for k in pairs:
        groups[(k[0], k[2], k[3])].append((a[k].get("chamfer"), b[k].get("chamfer")))
    totals: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for (scene, preset, budget), values in sorted(groups.items()):
        xs = [x for x, y in values if x is not None and y is not None]
        ys = [y for x, y in values if x is not None and y is not None]
        if not xs:
            continue
        mx, my = statistics.mean(xs), statistics.mean(ys)
        for group in _groups(scene):  # a budget's means of its own: rulers differ
            totals[(group, budget)].append((mx, my))
        # worse by more than either commit's seed spread (a single seed has none to go by)
        spread = max(max(xs) - min(xs), max(ys) - min(ys))
        beyond = "-" if len(xs) < 2 else ("yes" if my - mx > spread else "no")
        out.append(f"| {scene} | {preset} | {budget} | {len(xs)} | {mx:.4f} | {_spread(xs)} | "
                   f"{my:.4f} | {_spread(ys)} | {100 * (my / mx - 1):+.1f}% | {beyond} |")
    budgets = {budget for _, budget in totals}
    for (name, budget), values in sorted(totals.items(), key=lambda kv: kv[0][1]):
        mx = statistics.mean(x for x, _ in values)
        my = statistics.mean(y for _, y in values)
        label = f"{name}, {budget}" if len(budgets) > 1 else name
        out.append(f"| **mean, {label}** | | | | **{mx:.4f}** | | **{my:.4f}** | | "
                   f"{100 * (my / mx - 1):+.1f}% | |")
    return [*out, ""]


CLEANUP_STEPS = (("chamfer_ungrouped", "components judged alone"),
                 ("chamfer_unfilled", "unseen space kept"),
                 ("chamfer_cavities", "cavities kept"))


def cleanup_section(lines: list[dict]) -> list[str]:
    """Each mesh clean-up step on the same fields: the default mesh's CD beside the CD with
    one step switched off, per (commit, preset, budget, machine) whose lines score them all.

    The field is the same, so a difference is the step's alone, with no seed noise in it."""
    keys = [k for k, _ in CLEANUP_STEPS]
    runs = list(_runs([r for r in lines
                       if all(k in r for k in keys) and r.get("chamfer") is not None]))
    if not runs:
        return []
    out = ["## Mesh clean-up on the same fields", "",
           "Every suite fit is meshed with the default clean-up and again with one step "
           "switched off (docs/meshing.md); per scene the mean CD over its seeds. A step "
           "helps where its column is higher than the default's.", ""]
    for (commit, preset, budget, cpu), _, scenes in runs:
        out += [f"### `{preset}`, {budget}, commit {commit}, {cpu}", "",
                "| scene | seeds | CD default | "
                + " | ".join(name for _, name in CLEANUP_STEPS) + " |",
                "|---|---|---|" + "---|" * len(CLEANUP_STEPS)]
        means: dict[str, list[list[float]]] = defaultdict(list)
        for scene, rs in scenes:
            row = [statistics.mean(r["chamfer"] for r in rs)]
            for k in keys:
                vs = [r[k] for r in rs if r[k] is not None]
                row.append(statistics.mean(vs) if len(vs) == len(rs) else None)
            for group in _groups(scene):
                means[group].append(row)
            out.append(f"| {scene} | {len(rs)} | " + " | ".join(_f(v) for v in row) + " |")
        for name, rows_ in means.items():
            cols = [None if any(r[i] is None for r in rows_)
                    else statistics.mean(r[i] for r in rows_) for i in range(len(keys) + 1)]
            out.append(f"| **mean, {name}** | | " + " | ".join(f"**{_f(v)}**" for v in cols)
                       + " |")
        out.append("")
    return out


def _cd(r: dict) -> float | None:
    return r.get("chamfer")


def stand_in(lines: list[dict], old: str, new: str) -> tuple[list[dict], int]:
    """``lines`` with ``old``'s fits of plain presets (no overrides) copied to ``new`` for
    the scenes and seeds ``new`` has not fitted, and the number of fits both commits made.

    For a commit whose changes leave the presets' path alone (docs, tooling, a new switch
    that is off): its variants can then be set beside the preset's fits made before it. It
    is a claim the lines must bear out, so every fit both commits made has to score the same
    Chamfer to the last digit, and at least one must exist."""
    at: dict[str, dict[tuple, list[dict]]] = {old: defaultdict(list), new: defaultdict(list)}
    for r in lines:
        if r["commit"] in at:
            at[r["commit"]][_fit_key(r)].append(r)
    both = sorted(set(at[old]) & set(at[new]))
    if not both:
        raise SystemExit(f"--same-as {old} {new}: no fit made at both commits to show that "
                         f"{new} repeats {old}")
    for k in both:
        scores = {c: {r.get("chamfer") for r in at[c][k]} for c in (old, new)}
        if len(scores[old] | scores[new]) > 1:
            a, b = (", ".join(sorted(map(str, scores[c]))) for c in (old, new))
            raise SystemExit(f"--same-as {old} {new}: {k[0]} seed {k[1]} `{k[2]}` scored {a} "
                             f"at {old} and {b} at {new}; the commits do not fit alike")
    copies = [{**rs[-1], "commit": new, "stands_in_from": old} for k, rs in at[old].items()
              if k not in at[new] and base_preset(k[2]) == k[2]]
    return [*lines, *copies], len(both)


def variant_section(lines: list[dict],
                    same_as: list[tuple[str, str]] | tuple = ()) -> list[str]:
    """Variants (a preset with overrides) against their preset's fits of the same commit,
    budget and machine, scene by scene on the seeds both have.

    ``same_as``: (old, new) commit pairs for :func:`stand_in`; the preset's fits of ``old``
    stand in for those ``new`` lacks, and the table says so."""
    repeats: dict[str, tuple[str, int]] = {}
    for old, new in same_as:
        lines, n = stand_in(lines, old, new)
        repeats[new] = (old, n)
    paired = _with_base(lines)
    if not paired:
        return []
    out = ["## Variants against their preset", "",
           "A variant is a preset with config overrides, fitted in the same suite run as the "
           "preset itself (same commit, budget and machine; the suite interleaves them). Per "
           "scene: the preset's mean CD over its seeds and their range, and each variant's "
           "change on the seeds both have; `!` marks a change beyond the preset's seed range "
           "(`+`: worse, `-`: better), `empty` a fit that left no surface. The keep rule for a "
           "prior: on by default only if switching it off makes the mean worse and no scene "
           "better beyond the range.", ""]
    runs = sorted({(k[:3], base_preset(k[3])) for k in paired}, key=lambda kv: kv[0])
    for (commit, budget, cpu), base in runs:
        variants = sorted(p for *k, p in paired if tuple(k) == (commit, budget, cpu)
                          and base_preset(p) == base)
        rows = [r for r in lines if _run_key(r) == (commit, budget, cpu)]
        fits: dict[tuple[str, str], dict[int, dict]] = defaultdict(dict)
        for r in rows:
            fits[(r["preset"], r["scene"])][r["seed"]] = r
        names = [v[len(base):].strip(" +") for v in variants]
        hows = list(dict.fromkeys(_how(r) for r in rows))  # the table holds every one's fits
        note = []
        if commit in repeats and any(r.get("stands_in_from") for r in rows):
            old, n = repeats[commit]
            note = [f"`{base}` fits of {old} stand in where {commit} has none (its changes "
                    "leave the presets' path alone: every fit made at both commits, "
                    f"{n} of them, scores the same Chamfer to the last digit).", ""]
        out += [f"### `{base}` and its variants, {budget}, commit {commit}, {cpu}", "",
                *note, ("Command: " if len(hows) == 1 else "Commands: ") + "; ".join(hows), "",
                f"| scene | seeds | CD `{base}` | range | "
                + " | ".join(f"`{n}`" for n in names) + " |",
                "|---|---|---|---|" + "---|" * len(names)]
        scenes = sorted({s for p, s in fits if p == base}, key=lambda s: (s.startswith("gen-"),
                                                                          s))
        changes: dict[str, list[tuple[float, float]]] = defaultdict(list)
        empties: dict[str, int] = defaultdict(int)
        for scene in scenes:
            own = {seed: _cd(r) for seed, r in fits[(base, scene)].items()}
            done = [v for v in own.values() if v is not None]
            spread = max(done) - min(done) if len(done) > 1 else None
            cells = []
            for v in variants:
                theirs = {seed: _cd(r) for seed, r in fits.get((v, scene), {}).items()}
                seeds = sorted(set(own) & set(theirs))
                if not seeds:
                    cells.append("-")
                    continue
                if any(own[s] is None or theirs[s] is None for s in seeds):
                    lost = sum(theirs[s] is None for s in seeds)
                    empties[v] += lost
                    cells.append("empty" if lost else "-")
                    continue
                a = statistics.mean(own[s] for s in seeds)
                b = statistics.mean(theirs[s] for s in seeds)
                changes[v].append((a, b))
                flag = ("" if spread is None or abs(b - a) <= spread
                        else (" ! +" if b > a else " ! -"))
                cells.append(f"{b:.4f} ({100 * (b / a - 1):+.0f}%{flag})")
            out.append(f"| {scene} | {len(own)} | {_f(statistics.mean(done) if done else None)}"
                       f" | {_spread(done)} | " + " | ".join(cells) + " |")
        means = []
        for v in variants:
            pairs = changes.get(v, [])
            if not pairs:
                means.append("-")
                continue
            a = statistics.mean(x for x, _ in pairs)
            b = statistics.mean(y for _, y in pairs)
            lost = f"; {_count(empties[v], 'empty fit')} besides" if empties[v] else ""
            means.append(f"**{b:.4f}** against {a:.4f} ({100 * (b / a - 1):+.1f}%, "
                         f"{_count(len(pairs), 'scene')}{lost})")
        out += ["| **mean, same scenes and seeds** | | | | " + " | ".join(means) + " |", ""]
    return out


README = common.REPO / "README.md"
README_START = "<!-- results: python benchmarks/report.py --readme "
README_END = "<!-- end of results -->"


def readme_block(lines: list[dict], commit: str) -> list[str]:
    """The README's results table: every suite group of one commit, one row each."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in lines:
        if r["commit"] == commit:
            groups[(r["preset"], _budget(r), _cpu(r))].append(r)
    out = ["| preset | budget | machine | assets: mean CD | generated: mean CD | steps |",
           "|---|---|---|---|---|---|"]
    for (preset, budget, cpu), rows in sorted(groups.items()):
        cells = []
        for generated in (False, True):
            rs = [r for r in rows if r["scene"].startswith("gen-") == generated
                  and r.get("chamfer") is not None]
            if not rs:
                cells.append("-")
                continue
            by_scene: dict[str, list[float]] = defaultdict(list)
            for r in rs:
                by_scene[r["scene"]].append(r["chamfer"])
            # the mean of the scenes' means, as the comparison's rows: a scene fitted with
            # more seeds does not weigh more
            lo, hi = min(map(len, by_scene.values())), max(map(len, by_scene.values()))
            seeds = _count(lo, "seed") if lo == hi else f"{lo}-{hi} seeds"
            cells.append(f"{statistics.mean(map(statistics.mean, by_scene.values())):.4f} "
                         f"({_count(len(by_scene), 'object' if generated else 'asset')}, "
                         f"{seeds})")
        steps = [r["steps"] for r in rows]
        out.append(f"| `{preset}` | {budget} | {cpu} | {cells[0]} | {cells[1]} | "
                   f"{min(steps)}-{max(steps)} |")
    return out


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' if n != 1 else ''}"


def readme_text(readme: str, lines: list[dict]) -> str:
    """``readme`` with its results block regenerated for the commit its marker names."""
    start = readme.index(README_START)
    commit = readme[start + len(README_START):].split(" ", 1)[0]
    head_end = readme.index("\n", start) + 1
    end = readme.index(README_END)
    return readme[:head_end] + "\n".join(readme_block(lines, commit)) + "\n" + readme[end:]


def recordings_section(rows: list[dict]) -> list[str]:
    """bench_roundtrip.py: a converted recording and a mono sensor against the original."""
    if not rows:
        return []
    out = ["## Recordings: converted against the original layout, mono against colour", "",
           "One simulated scene written as an HDF5 recording with a metric 200 Hz TUM track "
           "and a clock offset, converted by `hybridneus convert` and fitted with the same "
           "preset, seed and steps as the original layout; and the same scene from a "
           "monochrome sensor. Chamfer in the original scene's frame. Targets: converted / "
           "original at most 1.10, mono / colour at most 1.3.", "",
           "| scene | preset | steps | seed | events | CD original | CD converted | ratio | "
           "CD mono | ratio | commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['scene']} | {r['preset']} | {r['iters']} | {r['seed']} | "
                   f"{r['n_events']:,} | {_f(r['chamfer_original'])} | "
                   f"{_f(r['chamfer_converted'])} | {r['converted_ratio']:.3f} | "
                   f"{_f(r['chamfer_mono'])} | {r['mono_ratio']:.3f} | {r['commit']} | "
                   f"{_cpu(r)} | {r['date'][:10]} |")
    return out + _command_lines(rows)


def poses_section(rows: list[dict]) -> list[str]:
    """bench_poses.py: pose refinement on a capture with known pose errors."""
    if not rows:
        return []
    out = ["## Pose refinement: a capture with known pose errors", "",
           "The scene simulated with errors in its written training poses (RMS rotation, RMS "
           "camera-centre shift as a share of the camera distance, a clock offset in views; "
           "events from the true poses) and fitted with the same preset, seed and steps: on "
           "the true poses (exact), on the erroneous ones as given, on those with "
           "`refine.poses=true` and the line's settings (refined; a line that sets "
           "`refine.poses=false` refines by its other settings alone, such as "
           "`refine.pose_smoothing`) and, in the lines that have it, on the true poses "
           "with the same refinement (what it costs where nothing needs it). Pose errors "
           "against the "
           "truth: mean (max) rotation in degrees and camera-centre shift in % of the "
           "distance; errors drawn every N views and interpolated between say `drift N`, errors "
           "drawn from another seed than 0 `noise seed S`, and "
           "the refined fits' extra settings are listed. Step-time ratios are whole-fit means "
           "(corrections learn in the second half); lines run beside other work "
           "(`--shared-machine`) leave them out (-). Targets: refined / exact Chamfer at most "
           "1.2; on exact poses, refinement at most 1.05 of the Chamfer and 1.15 of the step "
           "time.", "",
           "| scene | views | errors (deg, share, views) | refinement | steps | CD exact | "
           "CD given | CD refined | given / exact | refined / exact | exact refined / exact | "
           "given poses | refined poses | step time refined / given | step time on exact | "
           "commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n = r["pose_noise"]
        drift = f", drift {n['smooth_views']:g}" if n.get("smooth_views") else ""
        if n.get("seed"):  # other errors of the same size
            drift += f", noise seed {n['seed']}"
        sets = " ".join(f"`{s}`" for s in r.get("refine_sets") or []) or "per view"
        if r.get("pose_window") is not None:
            sets += f" (chose {r['pose_window']} views)"
        pose = [f"{p['rot_deg_mean']:.2f} ({p['rot_deg_max']:.2f}) deg, "
                f"{p['centre_pct_mean']:.2f} ({p['centre_pct_max']:.2f}) %"
                for p in (r["poses_given"], r["poses_refined"])]
        on_exact = r.get("exact_refined_ratio")
        step_given, step_exact = r.get("step_time_ratio"), r.get("exact_step_time_ratio")
        out.append(f"| {r['scene']} | {r['views']} {r['size']} | {n['rotation_deg']:g}, "
                   f"{n['translation']:g}, {n['clock_offset_views']:g}{drift} | {sets} | "
                   f"{r['iters']} | "
                   f"{_f(r['chamfer_exact'])} | {_f(r['chamfer_given'])} | "
                   f"{_f(r['chamfer_refined'])} | {r['given_ratio']:.3f} | "
                   f"{r['refined_ratio']:.3f} | "
                   f"{'-' if on_exact is None else f'{on_exact:.3f}'} | {pose[0]} | "
                   f"{pose[1]} | {'-' if step_given is None else f'{step_given:.2f}'} | "
                   f"{'-' if step_exact is None else f'{step_exact:.2f}'} | {r['commit']} | "
                   f"{_cpu(r)} | {r['date'][:10]} |")
    return out + _command_lines(rows)


def track_section(rows: list[dict]) -> list[str]:
    """bench_track.py: the pose errors a smoothing window leaves on a jittery track."""
    if not rows:
        return []
    out = ["## Track smoothing: pose errors left by each window", "",
           "The simulator's camera paths with per-view errors in their written poses (RMS "
           "rotation and camera-centre shift, a clock offset), smoothed as "
           "`refine.pose_smoothing` does it: window 0 is the track as given, -1 the window "
           "chosen from each track (the windows chosen are listed, one per noise seed). "
           "Errors against the true poses, mean (max) over the views, averaged over the "
           "noise seeds: rotation in degrees, camera centre in % of the camera distance. No "
           "fit.", "",
           "| path | views | errors (deg, share) | seeds | order | window | chosen | rotation "
           "| centre | commit | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        chosen = ", ".join(str(w) for w in r["chosen"]) if r["window"] < 0 else "-"
        out.append(f"| {r['path']} | {r['views']} | {r['rotation_deg']:g}, "
                   f"{r['translation']:g} | {len(r['noise_seeds'])} | {r['order']} | "
                   f"{r['window']} | {chosen} | {r['rot_deg_mean']:.3f} "
                   f"({r['rot_deg_max']:.2f}) | {r['centre_pct_mean']:.3f} "
                   f"({r['centre_pct_max']:.2f}) | {r['commit']} | {r['date'][:10]} |")
    return out + _command_lines(rows)


def threshold_section(rows: list[dict]) -> list[str]:
    """bench_threshold.py: an unstated threshold taken from the frames."""
    if not rows:
        return []
    out = ["## Contrast threshold: unstated, taken from the frames", "",
           "The scene simulated with unequal ON / OFF thresholds, and a copy whose `scene.json` "
           "states neither C nor the polarity offset, fitted with the same preset, seed and "
           "steps: told the truth; unstated, so that the fit takes both from the frames "
           "(`estimate.threshold`); told a C off by the given share (the offset from the "
           "events' balance). Lines without fits (`--no-fit`) measure the estimate alone. "
           "Targets: estimated C within 5% of the truth, Chamfer within 1.1x of the fit told "
           "the truth.", "",
           "| scene | views | true ON / OFF | estimated ON / OFF (C error) | steps | CD told | "
           "estimated / told | wrong C / told | commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t, e, ratios = r["true"], r["estimated"], r["ratios"]
        wrong = ", ".join(f"{'+' if k == 'high' else '-'}{100 * r['wrong']:.0f}%: {ratios[k]:.3f}"
                          for k in ("high", "low") if k in ratios)
        est = "-" if "estimated" not in ratios else f"{ratios['estimated']:.3f}"
        told = _f(r["fits"]["told"]["chamfer"]) if "told" in r["fits"] else "-"
        out.append(f"| {r['scene']} | {r['views']} {r['size']} | {t['on']:g} / {t['off']:g} | "
                   f"{e['on']:.4f} / {e['off']:.4f} ({100 * r['threshold_error']:+.1f}%) | "
                   f"{r['iters'] if r['fits'] else '-'} | {told} | {est} | "
                   f"{wrong or '-'} | {r['commit']} | {_cpu(r)} | {r['date'][:10]} |")
    return out + _command_lines(rows)


def reliability_section(rows: list[dict]) -> list[str]:
    """reliability.py: bad inputs and faults tried as commands (its latest clean line)."""
    if not rows:
        return []
    r = rows[-1]
    return ["## Reliability: bad inputs and faults", "",
            "Every case of `benchmarks/reliability_cases.py` run as the command a person would "
            "type; the full table, with the message each case shows, is "
            "[docs/reliability.md](reliability.md). Target: 0 tracebacks, 0 silent accepts, "
            "0 leftovers over at least 150 cases.", "",
            "| cases | ok | tracebacks | silent accepts | unclear | leftovers | wrong | seconds "
            "| commit | machine | date |", "|---|---|---|---|---|---|---|---|---|---|---|",
            f"| {r['cases']} | {r['ok']} | {r['traceback']} | {r['silent']} | {r['unclear']} | "
            f"{r['leftover']} | {r['wrong']} | {r['seconds']:.0f} | {r['commit']} | {_cpu(r)} | "
            f"{r['date'][:10]} |", "", f"Command: `{r['command']}`", ""]


def speed_section(results: dict[str, list[dict]]) -> list[str]:
    """The latest clean line of each speed benchmark's measurements."""
    out = ["## Speed", "", "The latest line of each measurement; timings are medians, and "
           "machines differ by 2x between days, so compare only the figures of one table.", ""]
    rows = results.get("startup", [])
    if rows:
        out += ["### From `hybridneus fit` to the first step", "",
                "| budget | dataset | events | seconds | commit | machine | date |",
                "|---|---|---|---|---|---|---|"]
        latest = {(r["mode"], r["dataset"]): r for r in rows}
        for r in latest.values():
            mode = "`--iters`" if r["mode"] == "iters" else "`--minutes` (probe included)"
            out.append(f"| {mode} | {r['dataset']} | {r['events']:,} | {r['first_step_s']:.2f} "
                       f"| {r['commit']} | {_cpu(r)} | {r['date'][:10]} |")
        out += ["", f"Command: `{rows[-1]['command']}`", ""]
    for bench, title in (("repeat", "Repeatability"), ("step", "One training step"),
                         ("trained_step", "A trained field's step"),
                         ("early", "The first steps of a fit"),
                         ("collapse", "Which part of the field moved when it emptied"),
                         ("carving", "What a fit's opening holds of the solid"),
                         ("floor", "Chamfer floors: ideal meshes that lack an unseen part, and the "
                          "ground truth meshed"),
                         ("rare_fill", "Meshing that also fills space few views see"),
                         ("probe", "Budget probe: the mean step it predicts, repeated"),
                         ("launches", "Operations per step"),
                         ("grids", "Grid encoding"), ("mesh", "Mesh extraction"),
                         ("data", "Data"), ("simulate", "Simulation"),
                         ("convert", "Converting a recording (`hybridneus convert`)")):
        by_machine: dict[str, list[dict]] = defaultdict(list)
        for r in results.get(bench, []):
            by_machine[_cpu(r)].append(r)
        for cpu, rows in by_machine.items():
            # the latest run on each machine: the lines of its command and commit (of the
            # carving and convert, whose runs each take one dataset, every command of that
            # commit)
            last = rows[-1]
            if bench == "floor":  # a floor per dataset and mesh, the newest, whichever run
                rows = list({(r["dataset"], r["mesh"]): r for r in rows}.values())
            elif bench == "early":  # the newest of each opening and variant, whichever run
                rows = list({(r["dataset"], r["variant"], r["steps"], r["iters"]): r
                             for r in rows}.values())
            elif bench == "collapse":  # the newest of each fit and pair of steps
                rows = list({(r["dataset"], r["seed"], r["iters"], tuple(r["at"]),
                              tuple(r["overrides"])): r for r in rows}.values())
            else:
                rows = [r for r in rows if r["commit"] == last["commit"]
                        and (bench in ("carving", "convert")
                             or r["command"] == last["command"])]
            commands = dict.fromkeys(f"Command: `{r['command']}`" for r in rows)
            commits = ", ".join(dict.fromkeys(r["commit"] for r in rows))
            out += [f"### {title}: {cpu}, commit {commits}, {last['date'][:10]}", "",
                    *_table(rows), "", "  \n".join(commands), ""]
    return out


_STAMP = ("bench", "commit", "dirty", "date", "machine", "command", "threads")


def _flat(line: dict) -> dict:
    """A line's own fields, nested dicts one column per key (``mpoints_per_s ours-joined``)."""
    out = {}
    for k, v in line.items():
        if k in _STAMP:
            continue
        if isinstance(v, dict):
            out.update({f"{k} {kk}": vv for kk, vv in v.items()})
        else:
            out[k] = v
    return out


def _cell(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return ", ".join(_cell(x) for x in v)
    return "-" if v is None else str(v)


def _table(rows: list[dict]) -> list[str]:
    flat = [_flat(r) for r in rows]
    cols = list(dict.fromkeys(k for f in flat for k in f))
    return [f"| {' | '.join(c.replace('_', ' ') for c in cols)} |",
            f"|{'---|' * len(cols)}",
            *(f"| {' | '.join(_cell(f.get(c)) for c in cols)} |" for f in flat)]


def build(compare: list[tuple[str, str]], same_as: list[tuple[str, str]] | tuple = ()) -> str:
    results: dict[str, list[dict]] = {}
    for path in sorted(common.RESULTS.glob("*.jsonl")):
        clean = [r for r in common.read_lines(path) if not r.get("dirty")]
        if clean:
            results[path.stem] = clean
    suite = results.get("suite", [])
    args = " ".join([*(f"--compare {b} {n}" for b, n in compare),
                     *(f"--same-as {o} {n}" for o, n in same_as)])
    out = ["# Benchmarks", "",
           f"Generated by `python benchmarks/report.py{' ' + args if args else ''}` from the "
           "result lines in `benchmarks/results/` (do not edit by hand: rerun the command). "
           "Each benchmark under `benchmarks/` says in its docstring how to run it; lines "
           "carry their commit, machine, threads, date and command.", ""]
    for base, new in compare:
        out += compare_section(suite, base, new)
    out += variant_section(suite, same_as)
    out += suite_section(suite)
    out += cleanup_section(suite)
    out += recordings_section(results.get("recordings", []))
    out += poses_section(results.get("poses", []))
    out += track_section(results.get("track", []))
    out += threshold_section(results.get("threshold", []))
    out += reliability_section(results.get("reliability", []))
    out += speed_section(results)
    return "\n".join(out).rstrip() + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", nargs=2, action="append", default=[], metavar=("BASE", "NEW"))
    ap.add_argument("--same-as", nargs=2, action="append", default=[], metavar=("OLD", "NEW"),
                    help="NEW repeats OLD's preset fits: in the variant tables OLD's fits of a "
                         "preset stand in for those NEW lacks (checked on the fits both made)")
    ap.add_argument("--out", type=Path, default=DOC)
    ap.add_argument("--check", action="store_true",
                    help="exit 1 if the page differs from what the lines give")
    ap.add_argument("--readme", metavar="COMMIT",
                    help="also write README.md's results table from COMMIT's suite lines")
    args = ap.parse_args()
    if args.readme:
        current = README.read_text()
        start = current.index(README_START) + len(README_START)
        end = current.index(" ", start)
        suite = [r for r in common.read_lines(common.RESULTS / "suite.jsonl")
                 if not r.get("dirty")]
        readme = readme_text(current[:start] + args.readme + current[end:], suite)
        if args.check and readme != current:
            raise SystemExit(f"{README}: results out of date; rerun the report")
        if not args.check:
            README.write_text(readme)
            print(f"wrote {README}'s results for {args.readme}")
    text = build([tuple(c) for c in args.compare], [tuple(c) for c in args.same_as])
    if args.check:
        same = args.out.is_file() and args.out.read_text() == text
        raise SystemExit(0 if same else f"{args.out}: out of date; rerun the report")
    args.out.write_text(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
