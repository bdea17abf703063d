#!/usr/bin/env bash
# Everything a lent GPU machine is wanted for, in one call of under 10 minutes, the most
# important first (a call that runs out of time still returns what is done):
#   1. the 2-minute fits of issue 4 (`fast`, the device's batch) on the packed datasets;
#   2. the CUDA tests that run without Open3D (pytest -m gpu, grids and event windows);
#   3. operations, read-backs and time per training step, hash grid joined and per level;
#   4. grid encoding speed, joined against per level.
#
# Here:   python benchmarks/gpu_pack.py --out gpu_carry DATASET...   (gpu_carry is ignored by
#         git), then run this with carry ["gpu_carry"] and timeout_s 600:
# There:  bash benchmarks/gpu_session.sh gpu_carry
# Back:   $OUT holds session.log and, per fit, its snapshots and a tar of its small files;
#         python benchmarks/gpu_pack.py --unpack FILES_AT --out RUNS, then
#         python benchmarks/run_suite.py --score-runs RUNS/* --image-views 0
# The GPU machine has no network and no Open3D / pymeshlab / trimesh: the package installs
# without dependencies (or, where that fails, runs from a tree of links laid out as pyproject.toml
# maps the package), and nothing here meshes. DEVICE=cpu MINUTES=0.1 makes a dry run.
set -u
CARRY=${1:-gpu_carry}
MINUTES=${MINUTES:-2}
DEVICE=${DEVICE:-cuda}
OUT=${OUT:-/tmp/gpu-session-out}
RUNS=/tmp/gpu-session-runs
mkdir -p "$OUT"
LOG="$OUT/session.log"
PY=python3
exec >"$LOG" 2>&1

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
$PY -c "import torch, hybridneus.grids; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"

echo "== 1. fits of $MINUTES minutes"
scenes=$(for d in "$CARRY"/*/; do basename "$d" | cut -d- -f1; done)
timeout 400 $PY benchmarks/run_suite.py --assets /nonexistent --cache "$CARRY" \
    --out-runs "$RUNS" --scenes $scenes --minutes "$MINUTES" --curve 2 \
    --presets fast --device "$DEVICE" --threads 2 --fit-only
# At most 8 files come back: per run its snapshots (about 13 MB each) and one small tar.
for run in "$RUNS"/*/; do
  [ -d "$run/snapshots" ] || continue
  name=$(basename "$run")
  tar -cf "$OUT/$name.tar" -C "$run" fit.json config.yaml metrics.csv
  for snap in "$run"/snapshots/*.pt; do
    cp "$snap" "$OUT/$name.$(basename "$snap")"
  done
done
ls -la "$OUT"

echo "== 2. pytest -m gpu"
timeout 60 $PY -m pytest -q -m gpu -p no:cacheprovider tests/test_grids.py \
    tests/test_data_windows.py 2>&1 | tail -5

first=$(ls -d "$CARRY"/*/ | head -1)
echo "== 3. bench_launches on $first"
timeout 75 $PY benchmarks/bench_launches.py --cache "$first" --device "$DEVICE" --steps 30

echo "== 4. bench_grids, joined against per level"
timeout 45 $PY benchmarks/bench_grids.py --device "$DEVICE" --impl ours-joined ours-per-level \
    --log2-t 17 19 --log2-n 15 17 --repeats 5
date -u
