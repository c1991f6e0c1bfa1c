# Two commands for a fresh machine: `make demo` and `make test`. Both set themselves up.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
JS     := tests/js
JSSTAMP := $(JS)/node_modules/.installed-stamp
# The browser client (TypeScript + three.js in web/), built into the package that serves it.
WEB      := web
WEBDEPS  := $(WEB)/node_modules/.installed-stamp
STATIC   := src/shadeform/app/static
WEBSTAMP := $(STATIC)/.built-stamp
WEBSRC   := $(WEB)/index.html $(WEB)/vite.config.ts $(WEB)/tsconfig.json $(wildcard $(WEB)/src/*.ts $(WEB)/src/*.css)

.PHONY: venv demo test lint format bench clean web app system

venv: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "shadeform needs Python 3.11 or newer"'
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	# compile the numba kernels now, into the cache beside the installed sources, so that the
	# first reconstruction does not wait for the compiler (`shadeform warm`)
	$(VENV)/bin/shadeform warm
	@touch $@

$(JSSTAMP): $(JS)/package.json $(JS)/package-lock.json
	npm ci --prefix $(JS) --no-audit --no-fund --silent
	@touch $@

$(WEBDEPS): $(WEB)/package.json $(WEB)/package-lock.json
	npm ci --prefix $(WEB) --no-audit --no-fund --silent
	@touch $@

# rebuilt only when a source under web/ changed (vite empties static/, the stamp comes back last)
$(WEBSTAMP): $(WEBDEPS) $(WEBSRC)
	npm run --prefix $(WEB) --silent build
	@touch $@

web: $(WEBSTAMP)

# the app on a shipped example: a real photo of a coin (its light estimated from the photo)
app: $(STAMP) $(WEBSTAMP)
	$(VENV)/bin/shadeform app coin

demo: $(STAMP)
	$(VENV)/bin/shadeform demo --out out/demo

# the system packages the tests need (chromium, Open3D's libraries, ivinfo): installed as root or
# through password-less sudo, else make stops here with the one command to run
system:
	@bash .ci/system-packages

# two test workers share the two cores: one BLAS thread each, or OpenBLAS's threads spin against
# each other (the relief light fit's products ran 10-25x slower that way)
test: system lint $(STAMP) $(JSSTAMP) $(WEBSTAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -n 2 --dist loadgroup -q

# ruff: lint and formatting, checked (CI runs this through `make test`); `make format` fixes both.
# import-linter: the layers of docs/architecture.md and no import cycle (.importlinter)
lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks setup.py
	$(VENV)/bin/ruff format --check src tests benchmarks setup.py
	$(VENV)/bin/lint-imports --no-cache

format: $(STAMP)
	$(VENV)/bin/ruff check --fix src tests benchmarks setup.py
	$(VENV)/bin/ruff format src tests benchmarks setup.py

bench: $(STAMP)
	$(PY) benchmarks/bench_pipeline.py
	$(PY) benchmarks/bench_poisson.py > benchmarks/results/poisson.txt && cat benchmarks/results/poisson.txt
	$(PY) benchmarks/bench_eikonal.py
	$(PY) benchmarks/bench_light.py
	$(PY) benchmarks/bench_diligent.py
	$(PY) benchmarks/bench_stereo.py
	$(PY) benchmarks/bench_methods.py
	$(PY) benchmarks/bench_real.py
	$(PY) benchmarks/bench_detail.py
	$(PY) benchmarks/bench_photo.py
	$(PY) benchmarks/bench_relief.py

clean:
	rm -rf $(VENV) $(JS)/node_modules $(WEB)/node_modules $(STATIC) out
