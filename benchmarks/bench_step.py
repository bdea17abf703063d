"""Where one training step's time goes: encoding, heads, rendering, backward, optimiser.

Runs the real ``Trainer`` on a small simulated scene (cached under --cache) and times the
phases of a step separately (medians over --steps after --warmup), plus a whole step.

    python benchmarks/bench_step.py --quick
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import common
import torch


def _timed(fn, n: int) -> float:
    times = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench/step-device"))
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--rays", type=int, default=256)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--quick", action="store_true", help="fewer steps and rays")
    common.add_arguments(ap, "step")
    args = ap.parse_args()
    common.check_tree(args)
    if args.quick:
        args.steps, args.warmup, args.rays = 4, 1, 128
    if args.threads:
        torch.set_num_threads(args.threads)

    from hybridneus.api import prepare
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.rendering.renderer import render_rays

    if not (args.cache / "scene.json").is_file():
        from hybridneus.simulate import SimulationConfig, simulate_dataset

        simulate_dataset("builtin:device", args.cache,
                         SimulationConfig(n_views=120, width=173, height=130, val_views=0,
                                          test_views=0, revolutions=3))
    cfg = apply_overrides(preset_config(args.preset),
                          [f"train.n_rays={args.rays}", "train.iters=1000", *args.overrides])
    trainer, _ = prepare(args.cache, cfg, device=args.device)
    field = trainer.field
    field.update_step(10**6, 1)  # all levels: the expensive end of training
    trainer.occupancy.update(field.raw_sdf, float(field.inv_s().detach()))
    batch = trainer.windows.sample(args.rays)
    o = torch.cat([batch.origins0, batch.origins1]).to(trainer.device)
    d = torch.cat([batch.dirs0, batch.dirs1]).to(trainer.device)
    n_pts = o.shape[0] * trainer.sampler.n_samples
    pts = (torch.rand(n_pts, 3, device=trainer.device) - 0.5) * 0.5
    dirs = torch.nn.functional.normalize(torch.randn(n_pts, 3, device=trainer.device), dim=-1)

    def sync():
        if trainer.device.type == "cuda":
            torch.cuda.synchronize()

    def placement():
        trainer.sampler(o, d, field.raw_sdf, trainer.generator)
        sync()

    def encoding_fwd_bwd():
        x = ((pts + 1) * 0.5).requires_grad_(True)
        field.encoding(x).sum().backward()
        sync()

    # backward into the parameters only, as the trainer does (the points' gradient is unused)
    params = [p for p in field.parameters() if p.requires_grad]

    def sdf_eikonal():
        s, g, f = field.sdf_gradient_features(pts, create_graph=True)
        (s.sum() + ((g.norm(dim=-1) - 1) ** 2).sum() + f.sum()).backward(inputs=params)
        sync()

    def heads_only():
        s, g, f = field.sdf_gradient_features(pts, create_graph=False)
        f = f.requires_grad_(True)
        field.radiance(pts, dirs, g, f).sum().backward()
        sync()

    def render_fwd_bwd():
        out = render_rays(field, o, d, trainer.sampler, trainer.generator, True)
        loss = out.color.sum() + (out.gradients.norm(dim=-1) - 1).pow(2).mean()
        loss.backward(inputs=params)
        sync()

    def optimiser():
        trainer.optimizer.step()
        sync()

    def full_step():
        # train_step applies the schedules: keep them at their late, all-levels end, on a step
        # without the occupancy refresh (every render.occupancy_every steps; not included).
        trainer.step, trainer.total_steps = 10**6 + 1, 10**6 + 2
        trainer.train_step()
        sync()

    def no_grads():
        trainer.optimizer.zero_grad(set_to_none=True)

    def dense_grads():
        # Adam skips parameters without gradients: give every one a dense gradient, as a real
        # backward pass does.
        for p in field.parameters():
            p.grad = torch.zeros_like(p)

    rows = []
    for name, fn, reset in [
        ("sample placement (no grad)", placement, no_grads),
        ("grid encoding fwd+bwd", encoding_fwd_bwd, no_grads),
        ("SDF + autograd Eikonal fwd+bwd", sdf_eikonal, no_grads),
        ("colour head fwd+bwd", heads_only, no_grads),
        ("render (all of the above) fwd+bwd", render_fwd_bwd, no_grads),
        ("Adam step", optimiser, dense_grads),
        ("full train_step", full_step, no_grads),
    ]:
        reset()
        _timed(fn, args.warmup)
        reset()
        rows.append((name, _timed(fn, args.steps)))
    print(f"device {trainer.device}, threads {torch.get_num_threads()}, preset {args.preset}, "
          f"{args.rays} pixels x 2 poses x {trainer.sampler.n_samples} samples = {n_pts} points")
    print("| phase | median s |")
    print("|---|---|")
    for name, t in rows:
        print(f"| {name} | {t:.3f} |")
    common.append(args.out, {
        "bench": "step", "preset": args.preset, "rays": args.rays, "points": n_pts,
        "overrides": args.overrides, "phases_s": {name: round(t, 5) for name, t in rows},
        **common.stamp(torch.get_num_threads(), str(trainer.device))})


if __name__ == "__main__":
    main()
