#!/usr/bin/env bash
# Everything a lent GPU machine is wanted for, in one call of under 10 minutes:
#   1. the CUDA tests that run without Open3D (pytest -m gpu, grids and event windows);
#   2. operations, read-backs and time per training step, hash grid joined and per level;
#   3. grid encoding speed, joined against per level;
#   4. the 2-minute fits of issue 4 (`fast`, the device's batch) on the packed datasets.
#
# Here:   python benchmarks/gpu_pack.py --out gpu_carry DATASET...   (gpu_carry excluded in
#         .git/info/exclude), then run this with carry ["gpu_carry"]:
# There:  bash benchmarks/gpu_session.sh gpu_carry
# Back:   $OUT holds session.log and, per fit, its snapshots and a tar of its small files;
#         unpack into a folder and score with
#         python benchmarks/run_suite.py --score-runs RUN... --image-views 0
# The GPU machine has no network and no Open3D / pymeshlab / trimesh: the package installs
# without dependencies, and nothing here meshes.
set -u
CARRY=${1:-gpu_carry}
MINUTES=${MINUTES:-2}
DEVICE=${DEVICE:-cuda}  # DEVICE=cpu MINUTES=0.1: a dry run of this script anywhere
OUT=${OUT:-/tmp/gpu-session-out}
mkdir -p "$OUT"
LOG="$OUT/session.log"
PY=python3
{
  date -u
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
  $PY -m pip install -q --no-deps --no-build-isolation -e . 2>&1 | tail -2
  $PY -c "import torch, hybridneus; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"

  echo "== 1. pytest -m gpu"
  timeout 120 $PY -m pytest -q -m gpu -p no:cacheprovider tests/test_grids.py \
      tests/test_data_windows.py 2>&1 | tail -5

  first=$(ls -d "$CARRY"/*/ | head -1)
  echo "== 2. bench_launches on $first"
  timeout 120 $PY benchmarks/bench_launches.py --cache "$first" --device "$DEVICE" --steps 30

  echo "== 3. bench_grids, joined against per level"
  timeout 90 $PY benchmarks/bench_grids.py --device "$DEVICE" --impl ours-joined ours-per-level \
      --log2-t 17 19 --log2-n 15 17 --repeats 5

  echo "== 4. fits of $MINUTES minutes"
  scenes=$(for d in "$CARRY"/*/; do basename "$d" | cut -d- -f1; done)
  timeout 480 $PY benchmarks/run_suite.py --assets /nonexistent --cache "$CARRY" \
      --out-runs /tmp/gpu-session-runs --scenes $scenes --minutes "$MINUTES" --curve 2 \
      --presets fast --device "$DEVICE" --threads 2 --fit-only
} >"$LOG" 2>&1

# At most 8 files come back: per run its snapshots (about 13 MB each) and one small tar.
for run in /tmp/gpu-session-runs/*/; do
  name=$(basename "$run")
  tar -cf "$OUT/$name.tar" -C "$run" fit.json config.yaml metrics.csv
  for snap in "$run"/snapshots/*.pt; do
    cp "$snap" "$OUT/$name.$(basename "$snap")"
  done
done
ls -la "$OUT"
tail -40 "$LOG"
