#!/usr/bin/env bash
# Every GPU check, in one call of under 10 minutes, the most important first (a call that runs
# out of time still returns what is done):
#   1. budgeted fits (`fast`, the device's batch) of the packed datasets, snapshots kept;
#   2. the CUDA tests that need no meshing libraries (pytest -m gpu);
#   3. operations, read-backs and time per training step, hash grid joined and per level;
#   4. grid encoding speed, joined against per level.
#
# Here:   python benchmarks/gpu_pack.py --out gpu_carry DATASET...   (a clean tree: it writes
#         the commit into gpu_carry/COMMIT), then run with carry ["gpu_carry"]:
# There:  bash benchmarks/gpu_check.sh gpu_carry          (MINUTES=1 by default)
# Back:   python benchmarks/gpu_pack.py --unpack FILES_AT --out RUNS, which scores the fits
#         and adds every line to benchmarks/results/.
# The GPU machine has no network and no Open3D / pymeshlab / trimesh: the package installs
# without dependencies (or runs from a tree of links laid out as pyproject.toml maps it), and
# nothing there meshes. At most 8 files come back: session.log, gpu.jsonl and per fit a tar of
# its small files and two snapshots (13 MB each). DEVICE=cpu MINUTES=0.1 makes a dry run.
set -u
CARRY=${1:-gpu_carry}
MINUTES=${MINUTES:-1}
DEVICE=${DEVICE:-cuda}
OUT=${OUT:-/tmp/gpu-check-out}
RUNS=/tmp/gpu-check-runs
mkdir -p "$OUT"
exec >"$OUT/session.log" 2>&1
export HYBRIDNEUS_BENCH_COMMIT=$(cat "$CARRY/COMMIT")
PY=python3

date -u
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
$PY -m pip install -q --no-deps --no-build-isolation -e . 2>&1 | tail -2
if ! $PY -c "import hybridneus.grids, hybridneus.cli" 2>/dev/null; then
  # No install (an old setuptools, say): the same package layout from links, as
  # pyproject.toml maps it (grids/ and cli/ are hybridneus.grids and hybridneus.cli).
  site=/tmp/hybridneus-site
  rm -rf "$site" && mkdir -p "$site/hybridneus"
  for f in "$PWD"/hybridneus/*; do ln -s "$f" "$site/hybridneus/"; done
  ln -s "$PWD/grids" "$site/hybridneus/grids"
  ln -s "$PWD/cli" "$site/hybridneus/cli"
  export PYTHONPATH="$site${PYTHONPATH:+:$PYTHONPATH}"
  PY="$PY -P"  # or the repository root, first on the path, would shadow the link tree
  echo "hybridneus from links in $site (pip install -e . failed)"
fi
$PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"
echo "commit $HYBRIDNEUS_BENCH_COMMIT"

echo "== 1. fits of $MINUTES minutes"
# Only dataset folders (test-scenes/ beside them holds the tests' small scenes).
scenes=$(for d in "$CARRY"/*/; do [ -f "$d/scene.json" ] && basename "$d" | sed -E 's/-[0-9]+v-[0-9]+x[0-9]+-t[0-9]+$//'; done)
timeout 400 $PY benchmarks/run_suite.py --assets /nonexistent --cache "$CARRY" \
    --out-runs "$RUNS" --scenes $scenes --minutes "$MINUTES" --curve 2 \
    --presets fast --device "$DEVICE" --threads 2 --fit-only
for run in "$RUNS"/*/; do
  [ -d "$run/snapshots" ] || continue
  name=$(basename "$run")
  tar -cf "$OUT/$name.tar" -C "$run" fit.json config.yaml scene.yaml metrics.csv
  for snap in "$run"/snapshots/*.pt; do
    cp "$snap" "$OUT/$name.$(basename "$snap")"
  done
done
ls -la "$OUT"

echo "== 2. pytest -m gpu"
HYBRIDNEUS_TEST_SCENES=$PWD/$CARRY/test-scenes timeout 90 $PY -m pytest -q -m gpu -p no:cacheprovider tests/test_grids.py \
    tests/test_data_windows.py tests/test_training.py 2>&1 | tail -5

first=$(dirname "$(ls "$CARRY"/*/scene.json | head -1)")
echo "== 3. bench_launches on $first"
timeout 75 $PY benchmarks/bench_launches.py --cache "$first" --device "$DEVICE" --steps 30 \
    --out "$OUT/gpu.jsonl"

echo "== 4. bench_grids, joined against per level"
timeout 45 $PY benchmarks/bench_grids.py --device "$DEVICE" --impl ours-joined ours-per-level \
    --log2-t 17 19 --log2-n 15 17 --repeats 5 --out "$OUT/gpu.jsonl"
date -u
