#!/usr/bin/env bash
# The GPU checks, for any machine with a CUDA GPU and this repository installed
# (pip install -e ".[test]" with a CUDA build of torch):
#   1. the CUDA tests (pytest -m gpu);
#   2. a budgeted fit of each DATASET (`fast`, the device's batch, MINUTES minutes), scored
#      against its ground truth where the meshing libraries are installed, else kept for
#      `python benchmarks/run_suite.py --score-runs RUN... --cache CACHE` on a machine that has
#      them;
#   3. operations, read-backs and time per training step (bench_launches.py);
#   4. grid encoding speed, the levels gathered per level against joined (bench_grids.py).
# Every result line names the GPU. They go to benchmarks/results/ (OUT=FOLDER: there instead),
# and the log to $LOG (default: gpu_check.log in OUT, or in the current folder).
#
#   bash benchmarks/gpu_check.sh                   # the bunny, simulated from ../shared/assets
#   bash benchmarks/gpu_check.sh DATASET...        # datasets the suite simulated (its cache
#                                                  # folders, NAME-999v-346x260-t8)
#   MINUTES=2 bash benchmarks/gpu_check.sh DATASET
#   DEVICE=cpu MINUTES=0.1 bash benchmarks/gpu_check.sh DATASET   # a dry run without a GPU
#
# On a machine without network or without Open3D, give datasets copied with
# benchmarks/pack_datasets.py (and HYBRIDNEUS_TEST_SCENES=<copy>/test-scenes for the tests).
# Each step has a time limit, the most important first, so the whole takes under 10 minutes.
set -u
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-1}
DEVICE=${DEVICE:-cuda}
RUNS=${RUNS:-/tmp/gpu-check-runs}
CACHE=${CACHE:-/tmp/hybridneus-bench}
if [ -n "${OUT:-}" ]; then
  mkdir -p "$OUT"
  suite_out=(--out "$OUT/suite.jsonl"); launches_out=(--out "$OUT/launches.jsonl")
  grids_out=(--out "$OUT/grids.jsonl")
else
  suite_out=(); launches_out=(); grids_out=()
fi
LOG=${LOG:-${OUT:-.}/gpu_check.log}
exec > >(tee "$LOG") 2>&1
PY=${PYTHON:-python3}

date -u
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
$PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"

if [ $# -eq 0 ]; then
  # the suite's cached copy of the bunny (simulated on first use: needs Open3D)
  $PY -c "
import argparse, sys
sys.path.insert(0, 'benchmarks')
import run_suite
args = argparse.Namespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                          cache=__import__('pathlib').Path('$CACHE'), assets=run_suite.DEFAULT_ASSETS)
run_suite.dataset_for('bunny', run_suite.find_assets(args.assets), args)" || exit 2
  set -- "$CACHE/bunny-999v-346x260-t8"
fi

echo "== 1. pytest -m gpu"
timeout 120 $PY -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tail -5

echo "== 2. fits of $MINUTES minutes on $DEVICE"
score=()
$PY -c "import open3d, pymeshlab, trimesh" 2>/dev/null || score=(--fit-only)
for dataset in "$@"; do
  name=$(basename "$dataset" | sed -E 's/-[0-9]+v-[0-9]+x[0-9]+-t[0-9]+$//')
  timeout 300 $PY benchmarks/run_suite.py --cache "$(dirname "$dataset")" --out-runs "$RUNS" \
      --scenes "$name" --minutes "$MINUTES" --curve 2 --presets fast --device "$DEVICE" \
      --threads 2 "${score[@]}" "${suite_out[@]}"
done
[ ${#score[@]} -eq 0 ] || echo "runs in $RUNS: score them where Open3D is installed"

echo "== 3. bench_launches on $1"
timeout 75 $PY benchmarks/bench_launches.py --cache "$1" --device "$DEVICE" --steps 30 \
    "${launches_out[@]}"

echo "== 4. bench_grids, joined against per level"
timeout 45 $PY benchmarks/bench_grids.py --device "$DEVICE" --impl ours-joined ours-per-level \
    --log2-t 17 19 --log2-n 15 17 --repeats 5 "${grids_out[@]}"
date -u
