# The two set-up commands of the README: `make demo` and `make test`.
PY ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint assets figures clean

$(STAMP): pyproject.toml
	@command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ] && ! dpkg -s libllvm19 >/dev/null 2>&1 \
	  && (apt-get update -qq && apt-get install -y -qq libllvm19 >/dev/null) || true
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e ".[all,dev,ray]"
	touch $(STAMP)

install: $(STAMP)

demo: install
	$(BIN)/scgen doctor --out demo_out
	$(BIN)/scgen render --n 8 --out demo_out --seed 0
	$(BIN)/scgen stats demo_out

# pytest-xdist processes for the suite: whole modules each (their module fixtures stay in one process), in
# collection order (tests/conftest.py puts the longest first). OpenMP threads wait passively: torch's spin
# at the end of every parallel region, which on 2 cores takes the other process's core (two processes
# without it: user + sys 4,875 s against 2,972 s serially, and slower than one process)
WORKERS ?= 2
# the second kernel set: torch's ATen vector code, oneDNN and NumPy's OpenBLAS held to older
# instruction sets, so that a float bound tuned to this CPU's kernels fails here first (docs/install.md)
KERNELS2 ?= ATEN_CPU_CAPABILITY=default ONEDNN_MAX_CPU_ISA=SSE41 OPENBLAS_CORETYPE=Prescott

test: install
	$(BIN)/ruff check .
	@echo "the suite: ~800 tests on $(WORKERS) processes, 12-28 min on 2 cores (11.6-28.4 min on 2026-11-29: the machine sets it; real renders and training runs); a dot per test"
	env OMP_WAIT_POLICY=PASSIVE $(BIN)/pytest -q -n $(WORKERS) --dist loadfile --no-loadscope-reorder
	@echo "the numeric tests (-m numeric) again under the second kernel set: $(KERNELS2)"
	env $(KERNELS2) $(BIN)/pytest -q -m numeric

lint: install
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

# every picture in docs/ that the generator draws, from today's code (about 15 min on 2 cores); the
# learning curves and the predict sheet are training results, remade by the benchmarks that docs/index.md names
figures: install
	rm -rf .figures && mkdir .figures
	$(BIN)/scgen preview --out .figures/preview --n 16 --quiet
	cp .figures/preview/preview.png docs/preview.png
	$(BIN)/scgen preview --out .figures/fleet --n 8 --backend mitsuba --config examples/fleet.toml --seed 11 --quiet
	cp .figures/fleet/preview.png docs/fleet_scene.png
	$(BIN)/python benchmarks/figures/camera_figure.py
	$(BIN)/python benchmarks/figures/sky_figure.py
	$(BIN)/scgen preview --sequence 1 --config examples/approach.toml --out .figures/sequence --backend mitsuba --quiet
	$(BIN)/python -c "import cv2; cv2.imwrite('docs/sequence_strip.jpg', \
	  cv2.imread('.figures/sequence/sequence_1.png'), [cv2.IMWRITE_JPEG_QUALITY, 88])"
	$(BIN)/python benchmarks/figures/camera_before_after.py --before b970dd6
	rm -rf .figures

assets: install
	$(BIN)/python -m scgen.assets.build

clean:
	rm -rf $(VENV) demo_out .pytest_cache .figures
