"""Which part of the field moved when it emptied: the grid or the SDF head.

A fit's field can empty within a few steps early in training (the collapse guard then
restores it; docs/accuracy.md, "Why a field empties"). This runs the opening of a ``fast``
fit of an ``--iters`` schedule (as ``bench_early.py`` does) and keeps the field's state at two
steps, ``--at A B``: A while the field still holds matter, B after it emptied. It then samples
points in the field's crop box and evaluates the SDF with the parameters of A, of B, and of A
with only one part taken from B: the grid encoding (everything but ``sdf_net``) or the SDF
head (``sdf_net``). One line per run: the share of points inside (SDF < 0) each way, and the
mean change of the SDF on the points inside at A. A fixed schedule on a CPU repeats exactly,
so the steps of one seed can be found with ``bench_early.py`` and looked at here.

    python benchmarks/bench_collapse.py /tmp/hybridneus-bench/xylophone-999v-346x260-t8 \\
        --seed 1 --iters 2000 --at 160 167
"""

from __future__ import annotations

import argparse
from pathlib import Path

import common
from bench_early import opening_config, run_opening

#: Points sampled in the crop box.
N_POINTS = 200_000


def crop_points(crop: tuple[float, float, float], n: int, seed: int = 0):
    """``n`` points uniform in the box around the crop cylinder ``(r, y_min, y_max)``."""
    import torch

    r, y0, y1 = crop
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 3, generator=g)
    lo = torch.tensor([-r, y0, -r])
    hi = torch.tensor([r, y1, r])
    return lo + u * (hi - lo)


def mixed(field, grid_state: dict, head_state: dict, points) -> object:
    """The SDF at ``points`` with the SDF head of ``head_state`` and the rest of ``grid_state``."""
    import torch

    field.load_state_dict(head_state)
    head = {k: v.clone() for k, v in field.sdf_net.state_dict().items()}
    field.load_state_dict(grid_state)
    field.sdf_net.load_state_dict(head)
    with torch.no_grad():
        return field.sdf_and_features(points)[0].reshape(-1)


def attribute(dataset: Path, seed: int, iters: int, at: tuple[int, int], threads: int,
              overrides: list[str]) -> dict:
    """Fit to step ``at[1]``, keep the states at both steps, and mix them (see above)."""
    import copy

    cfg = opening_config(seed, iters, threads, overrides)
    states: dict[int, dict] = {}
    held: dict = {}

    def record(trainer, logs) -> None:
        held["trainer"] = trainer
        if trainer.step in at:
            states[trainer.step] = copy.deepcopy(trainer.field.state_dict())

    run_opening(dataset, cfg, at[1], record)
    field = held["trainer"].field
    a, b = states[at[0]], states[at[1]]
    points = crop_points(tuple(float(v) for v in field.crop), N_POINTS)
    base = mixed(field, a, a, points)
    inside = base < 0
    out = {"inside_at_a": round(float(inside.float().mean()), 4)}
    for name, grid, head in (("both", b, b), ("grid", b, a), ("head", a, b)):
        sdf = mixed(field, grid, head, points)
        shift = (sdf - base)[inside].mean() if bool(inside.any()) else sdf.new_tensor(0.0)
        out[f"inside_{name}_from_b"] = round(float((sdf < 0).float().mean()), 4)
        out[f"shift_{name}_from_b"] = round(float(shift), 4)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--iters", type=int, default=2000, help="the schedule's length")
    ap.add_argument("--at", type=int, nargs=2, required=True, metavar=("A", "B"),
                    help="a step that still holds matter and a later one that has emptied")
    ap.add_argument("--set", dest="overrides", action="append", default=[],
                    metavar="KEY=VALUE", help="config override")
    ap.add_argument("--threads", type=int, default=1)
    common.add_arguments(ap, "collapse")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    if not 0 < args.at[0] < args.at[1]:
        raise SystemExit(f"error: --at {args.at[0]} {args.at[1]}: need 0 < A < B")
    found = attribute(args.dataset, args.seed, args.iters, tuple(args.at), args.threads,
                      args.overrides)
    print(", ".join(f"{k} {v}" for k, v in found.items()))
    common.append(args.out, {
        "bench": "collapse", "dataset": args.dataset.name, "seed": args.seed,
        "iters": args.iters, "at": list(args.at), "overrides": args.overrides, **found,
        **common.stamp(args.threads)})


if __name__ == "__main__":
    main()
