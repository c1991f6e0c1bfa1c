# Two commands for a fresh machine: `make demo` and `make test`. Both set themselves up.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
JS     := tests/js
JSSTAMP := $(JS)/node_modules/.installed-stamp

.PHONY: venv demo test bench clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "shadeform needs Python 3.11 or newer"'
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	@touch $@

$(JSSTAMP): $(JS)/package.json $(JS)/package-lock.json
	npm ci --prefix $(JS) --no-audit --no-fund --silent
	@touch $@

demo: $(STAMP)
	$(VENV)/bin/shadeform demo --out out/demo

test: $(STAMP) $(JSSTAMP)
	$(PY) -m pytest -n 2 -q

bench: $(STAMP)
	$(PY) benchmarks/bench_pipeline.py
	$(PY) benchmarks/bench_poisson.py > benchmarks/results/poisson.txt && cat benchmarks/results/poisson.txt
	$(PY) benchmarks/bench_eikonal.py
	$(PY) benchmarks/bench_light.py
	$(PY) benchmarks/bench_diligent.py

clean:
	rm -rf $(VENV) $(JS)/node_modules out
