# One-command set-up: every target creates the virtual environment if it is missing and
# installs the package with all extras, so a fresh clone needs nothing but python3 and make.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
CORE_STAMP := $(VENV)/.core-stamp
BENCH_STAMP := $(VENV)/.bench-stamp
BROWSER_STAMP := $(VENV)/.browser-stamp
DEMO_PNG ?= splinecast-demo.png

.PHONY: demo test bench lint clean clean-cache bench-deps compare compare-quick docs fuzz

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,test,docs]'
	touch $(STAMP) $(CORE_STAMP)

# The demo needs only the core dependencies (numpy, numba, pillow, cmap): installing the extras
# (readers, viewer, Dask, zarr, docs) would double the wait before the first picture.
$(CORE_STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet -e .
	touch $(CORE_STAMP)

demo: $(CORE_STAMP)
	@$(VENV)/bin/splinecast render 'demo:marschner-lobb?size=128' --iso 0.5 --size 768x768 \
		--azimuth 30 --elevation 25 --quiet -o $(DEMO_PNG)

test: $(STAMP) $(BENCH_STAMP) $(BROWSER_STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) benchmarks/bench_core.py

# Comparison suite against VTK and scikit-image (the benchmarks/compare package).
# Optional for `make test`: system libraries for offscreen OpenGL (scripts/install_bench.sh) and the
# `bench` extra from PyPI (~10 s of wheels); if either fails the VTK tests skip with the reason.
# The stamp is written only when both succeed, so a failure is retried by the next `make test`
# instead of being remembered (a remembered failure would make those tests skip forever).
$(BENCH_STAMP): pyproject.toml scripts/install_bench.sh scripts/apt_install.sh $(STAMP)
	@ok=1; \
	bash scripts/install_bench.sh || ok=0; \
	$(PY) -m pip install --quiet -e '.[all,test,bench]' || ok=0; \
	if [ $$ok = 1 ]; then touch $(BENCH_STAMP); else \
		echo "optional comparison set-up incomplete: the VTK/scikit-image tests will skip" \
			"with the reason; the next 'make test' tries again"; fi

# Headless Chromium for the viewer's browser tests, optional for `make test`: Debian's
# chromium via apt (scripts/install_browser.sh); if it cannot be installed those tests skip with
# the reason. As for the bench stamp, only success is remembered: a failure is retried next time.
$(BROWSER_STAMP): scripts/install_browser.sh scripts/apt_install.sh $(STAMP)
	@if bash scripts/install_browser.sh; then touch $(BROWSER_STAMP); else \
		echo "chromium not installed: the browser tests will skip with the reason;" \
			"the next 'make test' tries again"; fi

# Strict variant: fails when the system libraries or the extra cannot be installed.
bench-deps: $(STAMP)
	bash scripts/install_bench.sh
	$(PY) -m pip install --quiet -e '.[all,test,bench]'
	touch $(BENCH_STAMP)

compare: bench-deps
	$(PY) -m benchmarks.compare

compare-quick: bench-deps
	$(PY) -m benchmarks.compare --quick

# Documentation site into docs/_build/html (offline; runs every gallery example for its pictures).
# Warnings are errors and every cross-reference must resolve (-W -n); tests/test_docs.py builds
# the same site without running the gallery.
docs: $(STAMP)
	$(PY) -m sphinx -b html -W -n --keep-going -q docs docs/_build/html
	@echo "docs: $(CURDIR)/docs/_build/html/index.html"

# Long fuzzing run: hostile files of every format and render options at their edges,
# each in a forked child under memory, address-space and time caps; new kernels may compile.
# The short run (300 cases) is part of `make test` (tests/fuzz/test_short_run.py).
FUZZ_CASES ?= 20000
fuzz: $(STAMP)
	cd tests && $(abspath $(PY)) -m fuzz.run --cases $(FUZZ_CASES) --compile allow \
		--json ../benchmarks/results/fuzz.json --markdown ../benchmarks/results/fuzz.md

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks

clean:
	rm -rf $(VENV) build src/*.egg-info docs/_build docs/generated docs/gallery docs/sg_execution_times.rst

# Numba's on-disk cache misses changes in functions inlined from other modules: drop it after edits.
clean-cache:
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
