# A CUDA training node: scgen[train] (posenet: torch, timm, the dataset's readers; no bpy, no Mitsuba)
# on PyTorch's CUDA image, whose torch is kept (the train extra asks torch >= 2.4). The same install
# path as tests/test_packaging.py's training install. Build from the repository root:
#   docker build -f docker/train.Dockerfile -t posenet-train .
#   docker run --rm --gpus all -v "$PWD/data:/data" posenet-train train --data /data/sc --out /data/run
FROM pytorch/pytorch:2.7.1-cuda12.6-cudnn9-runtime

COPY . /src
RUN pip wheel --no-cache-dir --no-deps /src -w /tmp/dist \
    && pip install --no-cache-dir "$(ls /tmp/dist/scgen-*.whl)[train]" \
    && rm -rf /tmp/dist /src

WORKDIR /data
ENTRYPOINT ["posenet"]
CMD ["--help"]
