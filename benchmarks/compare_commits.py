"""Two commits' accuracy on the same fits, interleaved on one machine.

Fits every (scene, seed) with the ``fast`` preset at the base commit and at the new one (HEAD
by default), one after the other, alternating which goes first, so that the machine's drift
falls on both alike; started again, it skips the fits already in ``--out``. Each commit runs
from a worktree of its own (its benchmarks/run_suite.py and its package, from a tree of links
laid out as pyproject.toml maps it, so nothing is installed and later commits to this checkout
change nothing mid-run) and only fits; the suite of the commit checked out at the start
scores every fit (from a worktree too, ``scored_at`` in the lines), so a pair differs by the
fitted code alone. Their lines are added to benchmarks/results/suite.jsonl.
``python benchmarks/report.py --compare BASE NEW`` then pairs them. With ``--iters`` (a
schedule that repeats exactly on a CPU) ``--jobs 2`` runs two fits at a time, each on its
``--threads``: the scores are those of fits run alone, their wall times are not.

    python benchmarks/compare_commits.py cf67ae4 --seeds 0 1 2
    python benchmarks/compare_commits.py cf67ae4 --scenes none --generated 6 --generated-seed 2026
    python benchmarks/compare_commits.py b1bba48 --scenes none --generated 6 --generated-seed 2026 \
        --iters 2000 --threads 1
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import common
import run_suite

WORK = Path("/tmp/hybridneus-compare")
#: Held while a line is added to ``--out``, which fits running side by side share.
_SHARED = threading.Lock()


def worktree(commit: str) -> tuple[Path, Path]:
    """(worktree, site folder) of ``commit``: the site holds ``hybridneus`` as links into the
    worktree, with ``grids/`` and ``cli/`` where the package maps them."""
    tree, site = WORK / commit, WORK / f"{commit}-site"
    if not tree.is_dir():
        subprocess.run(["git", "-C", str(common.REPO), "worktree", "add", "--detach", str(tree),
                        commit], check=True)
    package = site / "hybridneus"
    if not package.is_dir():
        package.mkdir(parents=True)
        for item in (tree / "hybridneus").iterdir():
            (package / item.name).symlink_to(item)
        (package / "grids").symlink_to(tree / "grids")
        (package / "cli").symlink_to(tree / "cli")
    return tree, site


def suite_env(tree: Path, site: Path) -> dict[str, str]:
    """The environment that runs a worktree's suite: its site first, so that the worktree's
    package is imported, not the one installed from this checkout."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(tree / "benchmarks")])}


def fitting_worktree(commit: str) -> tuple[Path, Path]:
    """:func:`worktree` of a commit whose suite can fit without scoring (``--fit-only``);
    a one-line exit otherwise, before any fit."""
    tree, site = worktree(commit)
    if "--fit-only" not in (tree / "benchmarks" / "run_suite.py").read_text():
        raise SystemExit(f"error: {commit}: its run_suite.py cannot fit without scoring "
                         "(--fit-only); compare later commits")
    return tree, site


def run_at(args, commit: str, name: str, seed: int) -> None:
    """One fit at ``commit`` with that commit's own suite (``--fit-only``), scored by the
    suite of the commit checked out when the comparison started (``args.ruler``, a worktree
    of its own, so that edits made meanwhile change no score): both commits of a pair are
    measured with the same ruler, whatever each commit's scoring was."""
    tree, site = args.trees[commit]
    suite = tree / "benchmarks" / "run_suite.py"
    # a folder and a file per fit: fits running side by side must not take each other's runs
    # or lines
    runs = args.out_runs / f"{commit}-{name}-s{seed}"
    budget = (["--iters", str(args.iters)] if args.iters else ["--minutes", str(args.minutes)])
    cmd = [sys.executable, str(suite), "--scenes", name, "--presets", "fast", *budget,
           "--seeds", str(seed), "--threads", str(args.threads), "--assets", str(args.assets),
           "--cache", str(args.cache), "--out-runs", str(runs), "--curve", "2",
           "--image-views", "0", "--fit-only"]
    subprocess.run(cmd, env=suite_env(tree, site), cwd=tree, check=False,
                   stdout=subprocess.DEVNULL)
    fitted = sorted((f.parent for f in runs.glob("*/fit.json")), key=lambda d: d.stat().st_mtime)
    if not fitted:
        print(f"[compare] {commit} {name} seed {seed}: the fit failed; skipped",
              file=sys.stderr, flush=True)
        return
    scored = WORK / f"{commit}-{name}-s{seed}-lines.jsonl"
    before = len(common.read_lines(scored))
    ruler, ruler_site = args.ruler
    score = [sys.executable, str(ruler / "benchmarks" / "run_suite.py"), "--score-runs",
             str(fitted[-1]), "--cache", str(args.cache), "--threads", str(args.threads),
             "--assets", str(args.assets), "--out", str(scored)]
    subprocess.run(score, env=suite_env(ruler, ruler_site), cwd=ruler, check=False,
                   stdout=subprocess.DEVNULL)
    for line in common.read_lines(scored)[before:]:
        converted = {**line, "seed": seed, "preset": "fast", "overrides": [],
                     "iters": args.iters, "scored_at": args.ruler_commit,
                     "command": f"python benchmarks/compare_commits.py {args.base} {args.new} "
                     f"(fits with the commit's run_suite.py {' '.join(cmd[2:])})"}
        with _SHARED:
            common.append(args.out, converted)
        print(f"[compare] {commit} {name} seed {seed}: CD {line.get('chamfer')}",
              file=sys.stderr, flush=True)


def done(args) -> set[tuple[str, str, int]]:
    """(commit, scene, seed) of this comparison's fits already in ``--out``: a comparison
    started again goes on where it stopped."""
    return {(x["commit"], x["scene"], x["seed"]) for x in common.read_lines(args.out)
            if x.get("bench") == "suite" and (x.get("iters") == args.iters if args.iters
                                              else x.get("minutes") == args.minutes)
            and common.meshed_over_crop(x)  # the older lines were scored with another ruler
            and "compare_commits.py" in str(x.get("command", ""))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("base", help="the commit to compare with")
    ap.add_argument("new", nargs="?", default="HEAD", help="the commit compared (default HEAD)")
    ap.add_argument("--assets", type=Path, default=run_suite.DEFAULT_ASSETS)
    ap.add_argument("--scenes", nargs="+", help="asset names (default: every asset; 'none')")
    ap.add_argument("--generated", type=int, default=0, metavar="N")
    ap.add_argument("--generated-seed", type=int, default=0)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    budget = ap.add_mutually_exclusive_group()
    budget.add_argument("--minutes", type=float, default=15.0, help="fit budget (default 15)")
    budget.add_argument("--iters", type=int, help="a fixed schedule of this many steps instead "
                        "of a budget: it repeats exactly on a CPU, so pairs differ by the commits "
                        "alone and may run beside other work")
    ap.add_argument("--threads", type=int, default=2, help="torch threads per fit")
    ap.add_argument("--jobs", type=int, default=1, help="fits run at a time (more than 1 only "
                    "with --iters: a budgeted fit's length depends on the machine's pace)")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--out-runs", type=Path, default=WORK / "runs")
    common.add_arguments(ap, "suite")
    args = ap.parse_args()
    if args.jobs < 1 or (args.jobs > 1 and not args.iters):
        ap.error("--jobs must be 1, or more with --iters")
    args.base, args.new = (common.short_commit(c) for c in (args.base, args.new))
    common.check_tree(args)  # the ruler is this checkout's commit: its code must be that
    args.ruler_commit = common.git_state()[0]
    args.ruler = worktree(args.ruler_commit)
    # made (and checked) here, before the fits run side by side
    args.trees = {commit: fitting_worktree(commit) for commit in (args.base, args.new)}
    assets = run_suite.find_assets(args.assets)
    sources = list(assets) if args.scenes is None else [s for s in args.scenes if s != "none"]
    if args.generated:
        from hybridneus.simulate.generated import generated_set

        sources += [f"generated:{k}:{s}" for k, s in generated_set(args.generated,
                                                                   args.generated_seed)]
    sim = argparse.Namespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                             cache=args.cache, assets=args.assets)
    names = [run_suite.scene_name(s) for s in sources]
    for source in sources:  # every dataset first, with today's simulator
        run_suite.dataset_for(source, assets, sim)
    args.out_runs.mkdir(parents=True, exist_ok=True)
    have = done(args)
    fits, k = [], 0
    for seed in args.seeds:  # seed-major: a comparison cut short still covers every scene
        for name in names:
            for commit in ([args.base, args.new] if k % 2 == 0 else [args.new, args.base]):
                if (commit, name, seed) in have:
                    print(f"[compare] {commit} {name} seed {seed}: in {args.out} already",
                          file=sys.stderr, flush=True)
                    continue
                fits.append((commit, name, seed))
            k += 1
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:  # in order, jobs at a time
        list(pool.map(lambda fit: run_at(args, *fit), fits))
    print(json.dumps({"pairs": k, "base": args.base, "new": args.new}))


if __name__ == "__main__":
    main()
