#!/bin/bash
# benchmarks/throughput.py --gpu-check on one bare GPU node (Python 3.12, torch, timm, OpenCV; no renderer,
# no OpenEXR, trimesh or albumentations, nothing to download): the table of issue 63 in one short run.
#
#   bash benchmarks/gpu_check.sh --prepare [CARRY]   # here, once: the data archive and the wheels
#   OUT=DIR bash benchmarks/gpu_check.sh [CARRY]     # on the node (a CPU without CUDA: a small dry run)
#
# CARRY (default runs/gpu_check, ignored by git) holds what travels with the working tree:
#   data.tar.xz  240 training samples at 640x480 (Mitsuba draft, JPEG images, float16 xyz EXR; the
#                issue's set size), rendered here;
#   wheels/      cp312 wheels of what posenet train imports and the node lacks: openexr, trimesh,
#                networkx, click, tensorboard (+ protobuf, absl-py: its writer needs no more). The node
#                installs the missing ones into a temporary folder (--no-index: nothing is fetched).
# scipy (predict's rotation maths) is not carried (35 MB): without it the predict stage is one line saying so.
#
# Writes $OUT (default /tmp/gpu-check): device.txt, throughput.json (rewritten after every measured line,
# so a killed run keeps what it measured), throughput.log and table.txt (the table). Its stages are
# sized to end within ~6 minutes on one H100/H200; the whole run is stopped at 7.
set -u
if [[ ${1:-} == -h || ${1:-} == --help ]]; then
  sed -n '2,/^set -u/p' "$0" | sed '$d; s/^# \{0,1\}//'
  exit 0
fi
if [[ ${1:-} == --prepare ]]; then
  CARRY=${2:-runs/gpu_check}; PY=${PY:-.venv/bin/python}
  mkdir -p "$CARRY/wheels"
  "${SCGEN:-.venv/bin/scgen}" render --n 240 --out "$CARRY/ds" --backend mitsuba --quality draft --split 1,0,0 \
    --no-depth --quiet || exit 1
  tar -C "$CARRY" --exclude=ds/models_eval --exclude=ds/train/000000/records -cf - ds | xz -6 > "$CARRY/data.tar.xz" || exit 1
  "$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 -d "$CARRY/wheels" \
    openexr trimesh networkx click tensorboard protobuf absl-py || exit 1
  du -sh "$CARRY/data.tar.xz" "$CARRY/wheels"
  exit 0
fi
CARRY=${1:-runs/gpu_check}
OUT=${OUT:-/tmp/gpu-check}; T=$(mktemp -d)
PY=${PY:-python3}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1 NO_ALBUMENTATIONS_UPDATE=1
{ date; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader; nproc
  "$PY" -c "import sys, torch, timm; print(sys.version.split()[0], 'torch', torch.__version__, 'timm', timm.__version__)"
} > "$OUT/device.txt" 2>&1
MISSING=$("$PY" - <<'EOF'
import importlib.util
WHEELS = {"OpenEXR": "openexr", "trimesh": "trimesh", "networkx": "networkx", "click": "click",
          "tensorboard": "tensorboard", "google.protobuf": "protobuf", "absl": "absl-py"}
def present(module):
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # google.protobuf without google
        return False
print(" ".join(w for m, w in WHEELS.items() if not present(m)))
EOF
)
if [[ -n $MISSING ]]; then
  echo "installing from $CARRY/wheels: $MISSING" >> "$OUT/device.txt"
  "$PY" -m pip install -q --no-index --no-deps --find-links "$CARRY/wheels" --target "$T/site" $MISSING \
    >> "$OUT/device.txt" 2>&1 || { cat "$OUT/device.txt"; exit 1; }
fi
export PYTHONPATH="$PWD:$PWD/benchmarks:$T/site${PYTHONPATH:+:$PYTHONPATH}"
xz -dc "$CARRY/data.tar.xz" | tar xf - -C "$T" || exit 1
if "$PY" -c "import torch, sys; sys.exit(not torch.cuda.is_available())"; then
  SIZE=(--gpu-check)
else  # the dry run on a CPU: every stage, on a tiny network (tests/test_posenet_train.py's), one thread
  printf 'preset: smoke\nmodel: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}\noptim: {batch_size: 4}\n' > "$T/tiny.yaml"
  SIZE=(--config "$T/tiny.yaml" --threads 1 --steps 1 --samples 16 --train-steps 8 --skip 2 --predict 4 --workers 1 --batch 4)
  echo "no CUDA device: the CPU dry run (${SIZE[*]})" >> "$OUT/device.txt"
fi
timeout 420 "$PY" benchmarks/throughput.py --data "$T/ds" --json "$OUT/throughput.json" "${SIZE[@]}" \
  > "$OUT/throughput.log" 2>&1
echo "exit $? $(date)" >> "$OUT/device.txt"
"$PY" -c "import json, sys; print('\n'.join(r['line'] for r in json.load(open(sys.argv[1]))['rows']))" \
  "$OUT/throughput.json" > "$OUT/table.txt" 2>/dev/null
cat "$OUT/device.txt" "$OUT/table.txt"
tail -n 5 "$OUT/throughput.log"
rm -rf "$T"
