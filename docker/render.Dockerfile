# A CPU rendering node: scgen[render,ray] (Blender Cycles + Mitsuba 3, Ray), Python 3.11 on Debian 12.
# The same install path as tests/test_packaging.py: the wheel built from the source, installed with its
# part's extra. Build from the repository root:
#   docker build -f docker/render.Dockerfile -t scgen-render .
#   docker run --rm -v "$PWD/data:/data" scgen-render render --n 100 --out /data/sc
FROM python:3.11-slim-bookworm

# bpy's shared libraries (X11 and GL are loaded even when rendering headless) and Debian's libLLVM 19,
# Mitsuba's fast LLVM variant (without it Mitsuba renders on scalar_rgb, slower; `scgen doctor` says)
RUN apt-get update && apt-get install -y --no-install-recommends \
        libx11-6 libxext6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libgl1 libllvm19 \
    && rm -rf /var/lib/apt/lists/*

COPY . /src
RUN pip wheel --no-cache-dir --no-deps /src -w /tmp/dist \
    && pip install --no-cache-dir "$(ls /tmp/dist/scgen-*.whl)[render,ray]" \
    && rm -rf /tmp/dist /src

WORKDIR /data
ENTRYPOINT ["scgen"]
CMD ["doctor"]
