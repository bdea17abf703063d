"""Training curves of suite fits side by side, for the docs: losses, sharpness and opacity.

Like ``pictures.py``, a figure is made from suite result lines, never from loose runs: each
``COMMIT:PRESET`` picks the newest clean line of the scene and seed at that commit (as the
lines spell it), whose run folder holds the ``metrics.csv`` drawn (with
``hybridneus.training.previews.write_curve``), captioned with the line's commit, preset,
budget, steps, restores and Chamfer.

    python benchmarks/curves.py gen-blob-784857333 --seed 1 8257a30:fast 50fe3df:fast \\
        --out docs/images/gen-blob-784857333-sharpness.png
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path

import common
import cv2
import numpy as np
import pictures


def pick(lines: list[dict], scene: str, seed: int, spec: str) -> dict:
    """The newest clean line of ``scene`` and ``seed`` for ``COMMIT:PRESET``
    (:func:`pictures.pick_lines`).

    Raises:
        SystemExit: the spec is malformed or no line matches.
    """
    commit, sep, preset = spec.partition(":")
    if not sep or not commit or not preset:
        raise SystemExit(f"curves: {spec!r}: expected COMMIT:PRESET")
    return pictures.pick_lines(lines, scene, [preset], commit, seed)[0]


def history(run: Path) -> list[dict[str, float]]:
    """The rows of a run's ``metrics.csv`` as floats (empty cells left out)."""
    path = run / "metrics.csv"
    if not path.is_file():
        raise SystemExit(f"curves: {path}: missing (make figures on the machine that ran it)")
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in row.items() if v not in ("", None)}
                for row in csv.DictReader(fh)]


def caption(line: dict) -> str:
    return (f"{line['preset']} | {line['commit']} | {pictures.budget_text(line)} | "
            f"{line['steps']} of "
            f"{line['total_steps']} steps | {line.get('restores', 0)} restores | "
            f"Chamfer {line['chamfer']:.4f}")


def figure(lines: list[dict]) -> np.ndarray:
    """One curve image per line, side by side, each under its caption."""
    from hybridneus.training.previews import write_curve

    tiles = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, line in enumerate(lines):
            path = Path(tmp) / f"{n}.png"
            write_curve(history(Path(line["run"])), path)
            img = cv2.imread(str(path))
            band = np.full((24, img.shape[1], 3), 235, np.uint8)
            cv2.putText(band, caption(line), (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.33,
                        (0, 0, 0), 1, cv2.LINE_AA)
            tiles.append(np.vstack([band, img]))
    return np.hstack(tiles)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="a suite scene name, e.g. gen-blob-784857333")
    ap.add_argument("specs", nargs="+", help="COMMIT:PRESET, one curve each")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, default=common.RESULTS / "suite.jsonl")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    lines = [pick(common.read_lines(args.results), args.scene, args.seed, s)
             for s in args.specs]
    img = figure(lines)
    from hybridneus.fileio import atomic_path

    with atomic_path(args.out, suffix=".png") as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise SystemExit(f"curves: {args.out}: could not write the PNG")
    print(f"curves: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
