"""Write docs/benchmarks.md from the result lines in benchmarks/results/*.jsonl.

Every figure in that page comes from a line here, with its commit, date, machine and the
command that made it; lines from trees with uncommitted changes are left out, and so are the
lines of experiments removed from the config (:func:`common.reruns_today`): the results files
keep the history, the page shows what the software does now. Groups of lines are summarised
(mean and spread over seeds, mean over scenes), the newest commit's of each kind of group;
``--compare BASE NEW`` adds a table of two commits' fits paired by scene, seed, preset and
budget on the same machine; ``--same-as OLD NEW`` lets OLD's preset fits stand beside NEW's
variants where NEW repeats them (checked on every fit both commits made).

    python benchmarks/report.py                                  # writes docs/benchmarks.md
    python benchmarks/report.py --compare cf67ae4 4d2c1e0 --check
    python benchmarks/report.py --readme 4d2c1e0     # and README.md's results table
    python benchmarks/report.py --accuracy 4d2c1e0   # and docs/accuracy.md's table of scenes
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


def _shown(command: str) -> str:
    """A line's command as the docs show it: where the run appended its lines (``--out``)
    is no part of what it measured."""
    return re.sub(r" --out [^ ]+", "", command)


def _command_lines(rows: list[dict]) -> list[str]:
    """A section's closing lines: every command that made its rows, once, in order."""
    commands = dict.fromkeys(f"Command: `{_shown(r['command'])}`" for r in rows)
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
        return ["generated", "generated, kinds with few events"]
    return ["generated"]


def base_preset(preset: str) -> str:
    """The preset a variant's name starts with: ``fast priors.hull.enabled=false`` (a
    ``--set`` override) and ``fast+train.lr=0.02`` (a preset spec) -> ``fast``."""
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
    command = _shown(r["command"].split(" (fits with the commit's ")[0])
    fitted = r.get("fit_command")
    if fitted and fitted != r["command"]:
        return f"`{_shown(fitted)}`, scored by `{command}`"
    return f"`{command}`"


def newest(lines: list[dict], key) -> list[dict]:
    """The lines of the newest commit (by its newest line's date; of equal dates, the later
    line: results files are appended in time) of every ``key(line)``."""
    latest: dict = {}
    for r in lines:
        k = key(r)
        if k not in latest or r["date"] >= latest[k][1]:
            latest[k] = (r["commit"], r["date"])
    return [r for r in lines if latest[key(r)][0] == r["commit"]]


def _group_key(r: dict) -> tuple:
    return (r["preset"], _budget(r), _cpu(r))


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


def _mean_of(rs: list[dict], key: str) -> float | None:
    values = [r[key] for r in rs if r.get(key) is not None]
    return statistics.mean(values) if values else None


def suite_section(lines: list[dict]) -> list[str]:
    """Accuracy: per (preset, budget, machine) and scene the newest commit's fits, the mean
    CD over their seeds by both protocols where its lines have both; variants (a preset with
    overrides) are in :func:`variant_section`, beside their preset."""
    plain = [r for r in lines if base_preset(r["preset"]) == r["preset"]]
    latest = newest(plain, lambda r: (*_group_key(r), r["scene"]))
    out = ["## Accuracy", "",
           "Chamfer distance (lower is better) of `hybridneus mesh`'s mesh against the "
           "simulator's ground truth, by the unit-cube protocol and, in the lines that have it, "
           "by EventNeuS's published one (`hybridneus eval --protocol`, docs/evaluation.md); "
           "per scene the newest commit's fits, the mean over their seeds and their range, and "
           "each protocol's floor (the ground truth against a second sampling of itself: no "
           "mesh scores below it). `gen-<kind>-<seed>` are generated objects "
           "(`hybridneus.simulate.generated`). Means over scenes where one commit made every "
           "row.", ""]
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in latest:
        groups[_group_key(r)].append(r)
    for (preset, budget, cpu), rows in sorted(groups.items(),
                                              key=lambda kv: max(r["date"] for r in kv[1])):
        by_scene: dict[str, list[dict]] = defaultdict(list)
        for r in rows:
            by_scene[r["scene"]].append(r)
        hows = list(dict.fromkeys(_how(r) for r in rows))  # each command once, in order
        both = any(r.get("chamfer_eventneus") is not None for r in rows)
        extra = " floor | CD eventneus | floor eventneus |" if both else ""
        out += [f"### `{preset}`, {budget}, {cpu}", "",
                "| scene | commit | date | seeds | CD mean | CD range | F@1% |" + extra
                + " steps | longest wall s | first step s |",
                "|---|---|---|---|---|---|---|" + "---|" * (3 if both else 0) + "---|---|---|"]
        means: dict[str, list[list[float | None]]] = defaultdict(list)
        for scene in sorted(by_scene, key=lambda sc: (sc.startswith("gen-"), sc)):
            rs = by_scene[scene]
            cds = [r["chamfer"] for r in rs if r.get("chamfer") is not None]
            failed = len(rs) - len(cds)
            mean = statistics.mean(cds) if cds else None
            ev = [_mean_of(rs, k) for k in ("floor", "chamfer_eventneus", "floor_eventneus")]
            if mean is not None:
                for group in _groups(scene):
                    means[group].append([mean, *ev])
            note = f" ({failed} without a surface)" if failed else ""
            firsts = [r["first_step_s"] for r in rs if r.get("first_step_s") is not None]
            cells = "".join(f" {_f(v)} |" for v in ev) if both else ""
            out.append(f"| {scene} | {rs[0]['commit']} | {max(r['date'] for r in rs)[:10]} | "
                       f"{len(rs)}{note} | {_f(mean)} | {_spread(cds)} | "
                       f"{_f(_mean_of(rs, 'fscore'), 3)} |{cells} "
                       f"{round(statistics.mean(r['steps'] for r in rs))} | "
                       f"{max(r.get('fit_wall_s', 0) for r in rs):.0f} | "
                       f"{_f(max(firsts) if firsts else None, 1)} |")
        if len({r["commit"] for r in rows}) == 1:
            for name, values in means.items():
                cols = [None if any(v[i] is None for v in values)
                        else statistics.mean(v[i] for v in values) for i in range(4)]
                cells = "".join(f" **{_f(v)}** |" for v in cols[1:]) if both else ""
                out.append(f"| **mean, {name}** | | | | **{_f(cols[0])}** | | |{cells} | | |")
        out += _command_lines([{"command": h.strip("`")} for h in hows])
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
    scored = [r for r in lines if all(k in r for k in keys) and r.get("chamfer") is not None
              and base_preset(r["preset"]) == r["preset"]]
    runs = list(_runs(newest(scored, _group_key)))
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
    # a variant that sets a key removed from the config is no switch a user has, and its
    # preset's fits of that commit may have run with the removed part at another value
    lines = [r for r in lines if not common.removed_settings(r)]
    repeats: dict[str, tuple[str, int]] = {}
    for old, new in same_as:
        lines, n = stand_in(lines, old, new)
        repeats[new] = (old, n)
    paired = _with_base(lines)
    if not paired:
        return []
    # of each experiment (a preset's variants on one budget and machine), the newest commit
    variants_of: dict[tuple, set[str]] = defaultdict(set)
    for *k, p in paired:
        variants_of[(*k, base_preset(p))].add(p)
    latest: dict[tuple, tuple[str, str]] = {}
    for (commit, budget, cpu, base), names in variants_of.items():
        date = max(r["date"] for r in lines if _run_key(r) == (commit, budget, cpu))
        kind = (budget, cpu, base, frozenset(names))
        if kind not in latest or date >= latest[kind][1]:
            latest[kind] = (commit, date)
    keep = {(commit, budget, cpu) for (budget, cpu, _, _), (commit, _) in latest.items()}
    paired = {k for k in paired if tuple(k[:3]) in keep}
    out = ["## Variants against their preset", "",
           "A variant is a preset with config overrides, fitted in the same suite run as the "
           "preset itself (same commit, budget and machine; the suite interleaves them). Per "
           "scene: the preset's mean CD over its seeds and their range, and each variant's "
           "change on the seeds both have; `!` marks a change beyond the preset's seed range "
           "(`+`: worse, `-`: better), `empty` a fit that left no surface. The keep rule for a "
           "prior: on by default only if switching it off makes the mean worse and no scene "
           "better beyond the range. The newest commit of each set of variants.", ""]
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


def readme_block(lines: list[dict], commits: list[str]) -> list[str]:
    """The README's results table: every suite group of the commits' lines, one row each."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in lines:
        if r["commit"] in commits:
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
    return _block_text(readme, README_START, lines, readme_block)


ACCURACY = common.REPO / "docs" / "accuracy.md"
ACCURACY_START = "<!-- scenes: python benchmarks/report.py --accuracy "


def accuracy_block(lines: list[dict], commits: list[str]) -> list[str]:
    """docs/accuracy.md's table: per scene (assets, then generated objects) and budget, the
    commits' plain ``fast`` fits averaged over their seeds, by both protocols."""
    rows = [r for r in lines if r["commit"] in commits and r["preset"] == "fast"
            and r.get("chamfer") is not None]
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        groups[(r["scene"].startswith("gen-"), r["scene"], _budget(r), _cpu(r))].append(r)
    out = ["| scene | budget | machine | seeds | Chamfer | accuracy | completeness | F@1% "
           "| Chamfer, eventneus protocol | steps | commit |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for (_, scene, budget, cpu), rs in sorted(groups.items()):
        cells = [_f(_mean_of(rs, k)) for k in ("chamfer", "accuracy", "completeness")]
        made = ", ".join(sorted({r["commit"] for r in rs}))
        out.append(f"| {scene} | {budget} | {cpu} | {len(rs)} | {' | '.join(cells)} | "
                   f"{_f(_mean_of(rs, 'fscore'), 3)} | {_f(_mean_of(rs, 'chamfer_eventneus'))} "
                   f"| {round(statistics.mean(r['steps'] for r in rs))} | {made} |")
    return out


def _block_text(text: str, marker: str, lines: list[dict], block) -> str:
    """``text`` with the generated block after ``marker`` (which names its commits) made anew,
    up to :data:`README_END`."""
    start = text.index(marker)
    commits = text[start + len(marker):].split(" -->", 1)[0].split()
    head_end = text.index("\n", start) + 1
    end = text.index(README_END, head_end)
    return text[:head_end] + "\n".join(block(lines, commits)) + "\n" + text[end:]


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
    """bench_poses.py: fits on a capture with known pose errors, its track as given and
    smoothed (the lines that smoothed; per-view corrections were removed in 0.3)."""
    rows = [r for r in rows
            if any(s.startswith("refine.pose_smoothing=") for s in r.get("refine_sets") or [])]
    if not rows:
        return []
    out = ["## Poses with known errors: the track as given and smoothed", "",
           "The scene simulated with errors in its written training poses (RMS rotation, RMS "
           "camera-centre shift as a share of the camera distance, a clock offset in views; "
           "events from the true poses) and fitted with the same preset, seed and steps: on "
           "the true poses (exact), on the erroneous ones as given, on those smoothed with the "
           "line's settings (`refine.pose_smoothing`; -1 chooses the window from the track, "
           "and the window chosen is listed) and, in the lines that have it, on the true poses "
           "smoothed the same way (what smoothing costs where nothing needs it). Pose errors "
           "against the truth: mean (max) rotation in degrees and camera-centre shift in % of "
           "the distance; errors drawn from another seed than 0 say `noise seed S`. Step-time "
           "ratios are whole-fit means; lines run beside other work (`--shared-machine`) leave "
           "them out (-). Targets: smoothed / exact Chamfer at most 1.2; on exact poses, "
           "smoothing at most 1.05 of the Chamfer and 1.15 of the step time.", "",
           "| scene | views | errors (deg, share, views) | smoothing | steps | CD exact | "
           "CD given | CD smoothed | given / exact | smoothed / exact | exact smoothed / exact | "
           "given poses | smoothed poses | step time smoothed / given | step time on exact | "
           "commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n = r["pose_noise"]
        drift = f", drift {n['smooth_views']:g}" if n.get("smooth_views") else ""
        if n.get("seed"):  # other errors of the same size
            drift += f", noise seed {n['seed']}"
        sets = " ".join(f"`{s}`" for s in r["refine_sets"] if s != "refine.poses=false")
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


def budget_section(rows: list[dict]) -> list[str]:
    """bench_budget.py: a --minutes fit on a machine busy for a while, the newest run's
    lines."""
    if not rows:
        return []
    last = rows[-1]
    rows = [r for r in rows if r["commit"] == last["commit"] and r["command"] == last["command"]]
    out = ["## A budget on a machine busy for a while", "",
           "`hybridneus fit --minutes M` with processes spinning every core beside it for its "
           "first minutes (busy), and alone (quiet): the steps it ran (of the final schedule), "
           "how often it re-planned its length and the slowest and fastest pace its re-plans "
           "measured (multiples of the probe's step time), and the share of the budget the "
           "whole command used. Target: at least 95% of the budget, never more than it.", "",
           "| dataset | budget | busy | steps | re-plans | paces | wall s | used | commit | "
           "machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        busy = f"{r['busy_minutes']:g} min, {r['hogs']} processes" if r["busy_minutes"] else "-"
        if r.get("refused"):
            ran = "refused: loading left no time"
        else:
            ran = f"{r['steps']} of {r['planned']}" if r["stopped_early"] else str(r["steps"])
        paces = "-" if not r.get("paces") else "x to ".join(f"{p:.2f}" for p in r["paces"]) + "x"
        out.append(f"| {r['dataset']} | {r['minutes']:g} min | {busy} | {ran} | {r['replans']} "
                   f"| {paces} | {r['wall_s']:.0f} | {100 * r['used']:.1f}% | {r['commit']} | "
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


def clock_section(rows: list[dict]) -> list[str]:
    """bench_clock.py: the clock offset found from the data, against the truth."""
    if not rows:
        return []
    out = ["## Clock offset: found from the data", "",
           "Scenes simulated as the suite simulates them, re-timed as hand-held captures "
           "(the camera's log-speed smooth random noise over 0.1 to 3 s with the given "
           "standard deviation; 0: a constant speed), a 200 Hz pose track on a clock ahead "
           "by a known offset, and the offset estimated as `convert --clock-offset auto` does "
           "(`hybridneus.recordings.clock`). The simulator interpolates the brightness "
           "linearly between views, so the views simulated along the path (999, or 3996: "
           "four times as many) set how finely the events follow the camera's motion. Per "
           "group of seeds, at the latest commit measured: how many it answered, the "
           "error of those (median and largest, ms), their median standard error, how many "
           "came within 2 ms, and the refusals. Targets: within 2 ms on hand-held tracks; "
           "refused at a constant speed. No fit.", "",
           "| scene | views | seconds | speed variation | seeds | answered | error median "
           "(max), ms | standard error, ms | within 2 ms | refused | commit | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        key = (r["scene"], r.get("views", 999), r["duration_s"], r["variation"])
        if key in groups and groups[key][0]["commit"] != r["commit"]:
            groups[key] = []  # a later commit's lines replace an earlier one's
        groups.setdefault(key, []).append(r)
    shown = []
    for (scene, views, duration, variation), rs in sorted(groups.items(),
                                                           key=lambda kv: kv[0][1]):
        commit = rs[0]["commit"]
        shown += rs
        answered = [r for r in rs if "error_ms" in r]
        errors = [abs(r["error_ms"]) for r in answered]
        err = f"{statistics.median(errors):.2f} ({max(errors):.2f})" if errors else "-"
        sigma = (f"{statistics.median(r['sigma_ms'] for r in answered):.2f}" if answered
                 else "-")
        reasons = sorted({r["refused"].split(" (")[0].split(";")[0] for r in rs
                          if "refused" in r})
        refused = (f"{len(rs) - len(answered)}: {'; '.join(reasons)}"
                   if len(answered) < len(rs) else "0")
        out.append(f"| {scene} | {views} | {duration:g} | {variation:g} | {len(rs)} | "
                   f"{len(answered)} | "
                   f"{err} | {sigma} | {sum(e <= 2.0 for e in errors)} | {refused} | "
                   f"{commit} | {rs[-1]['date'][:10]} |")
    return out + _command_lines(shown)


def frames_section(rows: list[dict]) -> list[str]:
    """bench_frames.py: the threshold taken from the frames a conversion kept."""
    if not rows:
        return []
    out = ["## Camera frames: the threshold from the frames a conversion kept", "",
           "Scenes simulated as a DAVIS346 at indoor light (`--noise davis346`: its ON / OFF "
           "thresholds, mismatch, background activity, hot pixels, refractory period, "
           "timestamp jitter), re-timed as a hand-held capture, with frames at the given rate "
           "and exposure, written with the events into one AEDAT4 file as DV writes it, "
           "converted with `hybridneus convert --views frames`; the frames stored with 8 or 16 "
           "bits of linear light. Two estimates: the conversion's, on the frames' stored values "
           "(the C that `scene.json` states; lines from 52ff8b5), and `estimate.threshold`'s on "
           "the kept `rgb/` files (8-bit sRGB). Target: C within 10% of the truth. No fit.", "",
           "| scene | seconds | frames (fps, exposure, bits) | true ON / OFF | at conversion: "
           "ON / OFF (C error) | from rgb/: ON / OFF | C error | explained | commit | date |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t = r["true"]
        if "estimated" in r:
            e = r["estimated"]
            est = f"{e['on']:.4f} / {e['off']:.4f}"
            err, expl = f"{100 * r['threshold_error']:+.1f}%", f"{r['explained']:.2f}"
        else:
            est, err, expl = f"none: {r['refused']}", "-", "-"
        conv = "-"
        if "converted" in r:
            c = r["converted"]
            conv = (f"{c['on']:.4f} / {c['off']:.4f} "
                    f"({100 * r['converted_error']:+.1f}%)")
        out.append(f"| {r['scene']} | {r['duration_s']:g} | {r['frames']} ({r['fps']:g}, "
                   f"{1e3 * r['exposure_s']:g} ms, {r.get('bits', 8)}) | {t['on']:.4f} / "
                   f"{t['off']:.4f} | {conv} | {est} | {err} | {expl} | {r['commit']} | "
                   f"{r['date'][:10]} |")
    return out + _command_lines(rows)


def _fit_cell(r: dict, label: str) -> str:
    """A capture line's Chamfer of one fit, or that it failed."""
    return "failed" if f"failed_{label}" in r else _f(r.get(f"chamfer_{label}"))


def batch_section(rows: list[dict]) -> list[str]:
    """bench_batch.py: N small fits as a shell loop and through ``hybridneus batch``."""
    rows = [r for r in rows if not r.get("dirty")]
    if not rows:
        return []
    out = ["## Batch throughput", "",
           "The same small fits (one dataset, a seed each, fixed steps, no mesh) run alone on "
           "the machine four ways: `hybridneus fit` in a shell loop with every core, and "
           "`hybridneus batch` with `--workers 1` and `--workers 2` (one thread a fit) and with "
           "`--executor ray` (one CPU a task). Wall time in all and against the loop; for the "
           "batch, the engine's overhead per job: its wall time less the jobs' own (their "
           "mean times the jobs over those at once), over the jobs.", "",
           "| way | jobs | steps | dataset | wall, s | vs loop | job mean, s | overhead per "
           "job, s | commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    killed = [r for r in rows if r["way"] == "killed"]
    rows = [r for r in rows if r["way"] != "killed"]
    for r in rows:
        m = r.get("machine", {})
        out.append(f"| {r['way']} | {r['jobs']} | {r['iters']} | {r['dataset']} | "
                   f"{r['wall_s']:.0f} | {r.get('ratio_to_loop', 1.0):.2f} | "
                   f"{r.get('job_mean_s', '-')} | {r.get('overhead_per_job_s', '-')} | "
                   f"{r['commit']} | {m.get('cpu', '-')}, {m.get('cores', '-')} cores | "
                   f"{r['date'][:10]} |")
    for r in killed:
        out += ["", f"Killed mid-way (`local-2`, SIGKILL to the batch's process group after "
                f"{r['done_before_kill']} of {r['jobs']} jobs were done) and run again: "
                f"{'every job done' if r['all_done'] else 'NOT every job done'}, "
                f"{'one fit run each' if r['one_run_each'] else 'some jobs with two runs'}, "
                f"{r['resumed']} resumed from a checkpoint, {r['rerun_from_start']} started "
                f"over ({r['wall_s']:.0f} s in all; {r['commit']}, {r['date'][:10]})."]
    return out + _command_lines(rows + killed)


def report_section(rows: list[dict]) -> list[str]:
    """bench_report.py: the run report of a real fit, its size and write time."""
    if not rows:
        return []
    out = ["## Run report", "",
           "A shared asset simulated as the suite simulates it, fitted for the given minutes, "
           "meshed at 300 with colour and scored; then `hybridneus report` timed as a command "
           "(Python's start and imports included) and `write_report` in a warm process "
           "(medians of 3), and the page opened in headless Chromium by the browser tests' own "
           "code (`benchmarks/browser.py`): script errors and requests for anything but the "
           "file itself, whether the curves and the 3D view drew (the pixel spread of the "
           "view; a blank canvas is 0).", "",
           "| scene | fit | steps | CD | mesh faces (shown) | size, MB | write, s: command / "
           "warm | browser errors | 3D view spread | commit | machine | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m, b = r.get("machine", {}), r["browser"]
        out.append(f"| {r['scene']} | {r['minutes']:g} min | {r['steps']} | "
                   f"{_f(r['chamfer'])} | {r['mesh_faces']:,} ({r['shown_faces']:,}) | "
                   f"{r['size_mb']:.1f} | {r['write_s_command']:.1f} / {r['write_s']:.2f} | "
                   f"{len(b['errors']) + len(b['site_errors'])} | {b['canvas_std']:g} | "
                   f"{r['commit']} | {m.get('cpu', '-')}, {m.get('cores', '-')} cores | "
                   f"{r['date'][:10]} |")
    out += ["", "The newest line's report, top of the page and its event windows, and the "
            "documentation site's front page, as the browser test saw them:", "",
            "![The top of the report](images/report.png)", "",
            "![Event windows beside renders](images/report-views.png)", "",
            "![The site's front page](images/site.png)"]
    return out + _command_lines(rows)


def _threshold_cell(r: dict) -> str:
    """A capture line's C as converted: from the frames, or the guess where none were."""
    found = r.get("threshold", {}).get("from_frames")
    return f"{found['threshold']:.4f} (frames)" if found else "0.25 (guess)"


def capture_section(rows: list[dict]) -> list[str]:
    """bench_capture.py: a noisy recording with a messy track, converted and fitted."""
    if not rows:
        return []
    out = ["## A real-capture stand-in: noise, a messy track and an unstated clock", "",
           "The scene simulated as a DAVIS346 at indoor light, re-timed as a hand-held capture "
           "of the given length and speed spread, its events in an AEDAT4 file, its track a "
           "200 Hz motion-capture CSV in a metric frame with occluded rows, repeated stamps and "
           "a 40 ms dropout, on a clock ahead by the given offset; converted with nothing "
           "stated but `--sensor RGGB --clock-offset auto`, and fitted beside the noise-free "
           "scene with the same preset, seed and steps. From 52ff8b5 the AEDAT4 file also "
           "holds the camera's APS frames (20 a second, 5 ms, 8 bits of linear light), from "
           "which the conversion takes C; before, it held none and C was the 0.25 guess (the "
           "truth: 0.168). Target: the converted fit within 1.25x of the clean one.", "",
           "| scene | seconds, spread | seed | steps | clock error (sigma), ms | hot pixels | "
           "track rows dropped | C converted | CD clean | CD converted | ratio | "
           "CD noisy, direct | CD converted, told offset and C | commit | date |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    clean = {(r["scene"], r["seed"], r["iters"]): r["chamfer_clean"] for r in rows
             if r.get("chamfer_clean") is not None}
    earlier = False
    for r in rows:
        if "refused" in r:
            out.append(f"| {r['scene']} | {r['duration_s']:g}, {r['variation']:g} | "
                       f"{r['seed']} | - | refused: {r['refused']} | - | - | - | - | - | - | "
                       f"- | - | {r['commit']} | {r['date'][:10]} |")
            continue
        t = r["track"]
        scene = r["scene"] + "".join(f" (converted fits: {v})" for v in r.get("sets", []))
        ratio = _f(r.get("ratio"), 2)
        known = clean.get((r["scene"], r["seed"], r["iters"]))
        if r.get("ratio") is None and r.get("chamfer_converted") and known:
            ratio, earlier = f"{r['chamfer_converted'] / known:.2f}*", True
        out.append(f"| {scene} | {r['duration_s']:g}, {r['variation']:g} | {r['seed']} | "
                   f"{r['iters']} | {r['clock_error_ms']:+.1f} ({r['clock_sigma_ms']:.1f}) | "
                   f"{r['hot_pixels']} | {t['occluded']} + {t['repeated']} | "
                   f"{_threshold_cell(r)} | "
                   f"{_f(r.get('chamfer_clean'))} | {_f(r.get('chamfer_converted'))} | "
                   f"{ratio} | {_fit_cell(r, 'noisy')} | "
                   f"{_fit_cell(r, 'told')} | {r['commit']} | {r['date'][:10]} |")
    if earlier:
        out += ["", "\\* against the clean fit of the newest line with one, of the same scene, "
                "seed and steps (the line itself fitted the converted recording only)."]
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


def busy_tests_section(rows: list[dict]) -> list[str]:
    """bench_busy_tests.py: the default test run beside processes spinning every core."""
    if not rows:
        return []
    r = rows[-1]
    return ["## The tests on a busy machine", "",
            "`python -m pytest -q` (the README's test command) while processes spin every core "
            "beside it. Target: every test passes, as on a quiet machine; no test depends on "
            "the machine's speed.", "",
            "| spinning processes | passed | failed | errors | wall s | commit | machine | date |",
            "|---|---|---|---|---|---|---|---|",
            f"| {r['hogs']} | {r['passed']} | {r['failed']} | {r['errors']} | "
            f"{r['wall_s']:.0f} | {r['commit']} | {_cpu(r)} | {r['date'][:10]} |", "",
            f"Command: `{_shown(r['command'])}`", ""]


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
            f"{r['date'][:10]} |", "", f"Command: `{_shown(r['command'])}`", ""]


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
        out += ["", f"Command: `{_shown(rows[-1]['command'])}`", ""]
    for bench, title in (("repeat", "Repeatability"), ("step", "One training step"),
                         ("launches", "Operations per step"),
                         ("grids", "Grid encoding"), ("mesh", "Mesh extraction"),
                         ("data", "Data"), ("simulate", "Simulation"),
                         ("convert", "Converting a recording (`hybridneus convert`)")):
        by_machine: dict[str, list[dict]] = defaultdict(list)
        for r in results.get(bench, []):
            by_machine[_cpu(r)].append(r)
        for cpu, rows in by_machine.items():
            # the latest run on each machine: the lines of its command and commit (of the
            # convert, whose runs each take one dataset, every command of that commit)
            last = rows[-1]
            rows = [r for r in rows if r["commit"] == last["commit"]
                    and (bench == "convert" or r["command"] == last["command"])]
            commands = dict.fromkeys(f"Command: `{_shown(r['command'])}`" for r in rows)
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
    suite = [r for r in results.get("suite", []) if common.reruns_today(r)]
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
    out += poses_section([r for r in results.get("poses", []) if common.reruns_today(r)])
    out += track_section(results.get("track", []))
    out += threshold_section(results.get("threshold", []))
    out += clock_section(results.get("clock", []))
    out += frames_section(results.get("frames", []))
    out += capture_section(results.get("capture", []))
    out += batch_section(results.get("batch", []))
    out += report_section(results.get("report", []))
    out += budget_section(results.get("budget", []))
    out += busy_tests_section(results.get("busy_tests", []))
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
    ap.add_argument("--readme", metavar="COMMIT", nargs="+",
                    help="also write README.md's results table from the commits' suite lines")
    ap.add_argument("--accuracy", metavar="COMMIT", nargs="+",
                    help="also write docs/accuracy.md's table of scenes from the commits' lines")
    args = ap.parse_args()
    suite = [r for r in common.read_lines(common.RESULTS / "suite.jsonl") if not r.get("dirty")]
    for commits, path, marker, block in ((args.readme, README, README_START, readme_block),
                                         (args.accuracy, ACCURACY, ACCURACY_START,
                                          accuracy_block)):
        if not commits:
            continue
        current = path.read_text()
        start = current.index(marker) + len(marker)
        end = current.index(" -->", start)
        text = _block_text(current[:start] + " ".join(commits) + current[end:], marker, suite,
                           block)
        if args.check and text != current:
            raise SystemExit(f"{path}: results out of date; rerun the report")
        if not args.check:
            path.write_text(text)
            print(f"wrote {path}'s results for {' '.join(commits)}")
    text = build([tuple(c) for c in args.compare], [tuple(c) for c in args.same_as])
    if args.check:
        same = args.out.is_file() and args.out.read_text() == text
        raise SystemExit(0 if same else f"{args.out}: out of date; rerun the report")
    args.out.write_text(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
