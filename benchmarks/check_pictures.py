"""docs/recordings.md's ``--check`` pictures: a recording against a plain background, and the
same one with a cluttered background firing behind the object.

The generated device is simulated as the suite simulates it (cached in ``--cache``), re-timed
as a hand-held capture of 30 seconds with a 200 Hz TUM track
(:mod:`hybridneus.simulate.recording`), and converted with ``hybridneus convert --check
--point 0,0,0`` (the object's centre). The cluttered copy adds the events of a textured
background sliding past the camera, a pixel a view, everywhere in the image; its conversion
prints the clutter warning. One event frame of each goes to ``docs/images/``.

    python benchmarks/check_pictures.py
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import common
import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="generated:device:161576974")
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--out", type=Path, default=common.REPO / "docs" / "images")
    args = ap.parse_args()

    import run_suite
    from scipy.ndimage import gaussian_filter

    from hybridneus.data import load_dataset
    from hybridneus.simulate import EventModel, EventSimulator
    from hybridneus.simulate.recording import as_recording, handheld_times

    ns = SimpleNamespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                         cache=args.cache, assets=args.assets)
    folder = run_suite.dataset_for(args.scene, run_suite.find_assets(args.assets), ns)
    sp = load_dataset(folder, splits="train")["train"]
    rec = as_recording(sp.events, sp.c2w, handheld_times(sp.n_views, 30.0, 0, 0.5), t0=100.0)
    # the cluttered copy: a smooth texture sliding past, its events in every view interval
    rng = np.random.default_rng(0)
    h, w = sp.height, sp.width
    wall = 0.5 + 3 * gaussian_filter(rng.normal(0, 0.1, (h, w + sp.n_views, 3)), (1.5, 1.5, 0))
    frames = [np.clip(wall[:, k:k + w], 0.05, 1) for k in range(sp.n_views)]
    sim = EventSimulator(frames[0], EventModel(threshold=0.2))
    chunks = [sim.step(f) for f in frames[1:]]
    back_t = np.interp(np.concatenate([c.t for c in chunks]), np.arange(sp.n_views),
                       rec.view_t)
    work = args.cache / "check-pictures"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    np.savetxt(work / "mocap.txt", rec.tum_rows(), fmt="%.9f")
    common.write_calibration(sp, work / "calib.json")
    cases = {"plain": (rec.t, rec.x, rec.y, rec.p)}
    merged = [np.concatenate([a, b]) for a, b in zip(
        cases["plain"], (back_t, *(np.concatenate([getattr(c, k) for c in chunks])
                                   for k in ("x", "y", "p"))), strict=True)]
    order = np.argsort(merged[0], kind="stable")
    cases["cluttered"] = tuple(m[order] for m in merged)
    for name, (t, x, y, p) in cases.items():
        np.savez(work / f"{name}.npz", t=np.round(t * 1e6).astype(np.int64), x=x, y=y, p=p)
        proc = subprocess.run(
            [sys.executable, "-m", "hybridneus.cli.app", "convert", str(work / f"{name}.npz"),
             str(work / name), "--poses", str(work / "mocap.txt"), "--calib",
             str(work / "calib.json"), "--time-unit", "us", "--sensor", "RGGB", "--check",
             "--point", "0,0,0", "-q"], capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"[check] {name}: convert failed: {proc.stderr.strip()}")
        print(f"[check] {name}: {proc.stderr.strip() or 'no warning'}", file=sys.stderr)
        picture = sorted((work / name / "check").glob("events_*.png"))[1]
        target = args.out / f"check-{name}.png"
        shutil.copyfile(picture, target)
        print(f"[check] wrote {target} (from {picture.name})", file=sys.stderr)


if __name__ == "__main__":
    main()
