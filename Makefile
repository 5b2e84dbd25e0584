# The two set-up commands of the README: `make demo` and `make test`.
PY ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint assets clean

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

test: install
	$(BIN)/ruff check .
	@echo "the suite: ~600 tests, 15-25 min on 2 cores (real renders and training runs); a dot per test"
	$(BIN)/pytest -q

lint: install
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

assets: install
	$(BIN)/python -m scgen.assets.build_spacecraft

clean:
	rm -rf $(VENV) demo_out .pytest_cache
