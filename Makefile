# The two commands of the README: `make demo` and `make test`.
# Both create .venv on first use with the system Python (>= 3.11) and install
# piezohyst into it; later runs reuse it until pyproject.toml changes.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= demo-report

.PHONY: demo test lint bench clean docs

$(BIN)/.installed: pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "piezohyst needs Python >= 3.11, found " + sys.version.split()[0]'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-compile -e '.[test]'
	@touch $@

demo: $(BIN)/.installed
	$(BIN)/piezohyst demo --out $(OUT)

lint: $(BIN)/.installed
	$(BIN)/ruff check src tests benchmarks examples docs/conf.py docs/api_pages.py
	$(BIN)/ruff format --check src tests benchmarks examples docs/conf.py docs/api_pages.py
	$(BIN)/mypy
	$(BIN)/lint-imports

# The tests, as CI runs them (.ci/run calls this target):
#  0. the linters, and beside them the numba kernels the tests call compiled into numba's
#     cache, half on each core (tests/kernel_warmup.py): on a fresh clone each worker
#     compiled nearly all of them, the same work once per core;
#  1. every test once, compiled, on two workers (a file's tests on one: its module fixtures
#     are built once), under coverage: numba's compiled kernels are invisible to coverage, so
#     their lines count in step 2 only. The `heavy` tests (long runs that check accuracy, not
#     paths: tests/conftest.py) run untraced: the limits' property test took 25 s untraced and
#     54-59 s traced, and the combined coverage stayed 94 % without them;
#  2. the tests listed in tests/kernel_paths.txt again with the JIT off, under coverage: what
#     sees the kernels' Python lines. The list reaches every kernel line that all the tests
#     of the `kernels` modules reach uncompiled, in a fifth of their time (tests/kernel_paths.py
#     chooses it; Hypothesis tries a quarter of its examples there, tests/conftest.py);
#  3. two gates on the combined data: all of src/ and the kernel modules, each >= 90 %.
KERNEL_MODULES := */piezohyst/_kernels/*.py,*/piezohyst/simulation/_plant.py
# Each worker's BLAS on one thread: the two workers fill the two cores, and BLAS threads on top
# had four threads share two (the compiled run, warm: 142-145 s with them, 125-127 s without)
ONE_THREAD := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Bytecode written even where the environment says not to (PYTHONDONTWRITEBYTECODE=1, as on
# this workplace's machines): the tests start piezohyst and Python processes (the console
# script, the docs' shell blocks), and each compiled the package's sources again (a CLI
# process: 0.48 s with its bytecode, 0.70-0.74 s without). Written under src/, ignored by git.
# So the install compiles none (--no-compile): pip compiled every module of every dependency
# (89 s against 56 s on a 2-core Xeon), the first process to import one now compiles it.
export PYTHONDONTWRITEBYTECODE :=
test: $(BIN)/.installed
	@rm -f .coverage .coverage.*
	$(ONE_THREAD) $(BIN)/python tests/kernel_warmup.py warm & warm=$$!; \
		$(MAKE) --no-print-directory lint || { kill $$warm; exit 1; }; \
		wait $$warm
	$(ONE_THREAD) $(BIN)/python -m pytest -n 2 --dist loadfile -p no:cacheprovider -rs --durations=10 --cov --cov-report=
	$(ONE_THREAD) NUMBA_DISABLE_JIT=1 $(BIN)/python -m pytest -q -n 2 --dist loadfile -p no:cacheprovider -m kernel_paths \
		--cov --cov-append --cov-report= tests
	@printf 'line coverage of src/, both runs combined (gate 90): '
	@$(BIN)/coverage report --fail-under=90 --format=total
	@echo 'line coverage of the numba kernel modules (gate 90):'
	@$(BIN)/coverage report --fail-under=90 --no-skip-covered --include='$(KERNEL_MODULES)'

bench: $(BIN)/.installed
	$(BIN)/python benchmarks/bench_core.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .mypy_cache .ruff_cache .hypothesis .coverage

# The documentation site (docs/_build/html): Sphinx with warnings as errors (a broken
# reference, a docstring numpydoc cannot read, or a gallery example that raises fails it),
# the API reference written from the packages (docs/api_pages.py), the gallery run from
# examples/; then the built pages opened in headless Chromium (tests/site). Its tools are the
# `docs` extra, installed beside the package on first use.
$(BIN)/.docs-installed: $(BIN)/.installed
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[docs]'
	@touch $@

docs: $(BIN)/.docs-installed
	@start=$$(date +%s); 	MPLBACKEND=Agg $(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html && 	echo "site built in $$(( $$(date +%s) - start )) s: $$(find docs/_build/html -name '*.html' | wc -l) pages in docs/_build/html (open index.html)"
	PIEZOHYST_SITE=$(CURDIR)/docs/_build/html $(BIN)/python -m pytest -q -p no:cacheprovider -rs tests/site
