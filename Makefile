# The README's two commands: `make demo` (set up, score the policies on the line and the 60 m track, reproduce the
# paper, validate the physics) and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

$(BIN)/trackenv: pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e ".[dev]"
	touch $@

.PHONY: setup demo test docs typecheck lint bench validate clean
# setup also builds every compiled entry of the physics kernel (numba's on-disk cache beside the package), so that
# no later call blocks to compile; when they are all built this takes a second
setup: $(BIN)/trackenv
	$(BIN)/trackenv compile

# the line first: the shipped agent against the best tuned rule and the calendar on 32 held-out episodes, paired;
# then the 60 m track (its tuned rules, its shipped agent and the model-predictive planner on the same engine),
# the paper's scenarios and the validation
demo: setup
	$(BIN)/trackenv evaluate --env trackenv/TampingLine-v0 --seeds 0:32 --rules grouped-threshold,uniform-periodic
	$(BIN)/trackenv evaluate --env trackenv/Tamping-v1 --seeds 0:32 --out results/track60_compare
	$(BIN)/trackenv paper
	$(BIN)/trackenv validate

# pytest in one worker process per core, at most 4 (pytest-xdist); the tests that start a local Ray share one
# worker (their xdist_group); a plain `pytest` runs the suite in one process
test: setup
	$(BIN)/ruff check trackenv agents tests experiments
	$(BIN)/mypy  # the library's types, as configured in pyproject.toml ([tool.mypy])
	$(BIN)/python -m pytest -q -n auto --maxprocesses 4 --dist loadgroup

docs: setup  # the documentation site into build/docs; --strict: any warning fails the build
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

typecheck: setup
	$(BIN)/mypy

bench: setup
	$(BIN)/trackenv bench

validate: setup
	$(BIN)/trackenv validate

clean:  # also numba's on-disk cache of the compiled kernel (its index files pile up as the kernel's source changes)
	rm -rf $(VENV) results runs build .pytest_cache .mypy_cache
	find trackenv agents -path '*/__pycache__/*.nb[ic]' -delete
