# The two commands of the README. Both set everything up first (idempotent).
VENV ?= .venv
PY := $(VENV)/bin/python
JOBS ?= 2

.PHONY: demo test lint format bench setup docs reproduce

demo:
	@scripts/setup.sh
	$(VENV)/bin/vlocbench run experiments/demo.yaml --workers $(JOBS)

test:
	@scripts/setup.sh test
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/ruff format --check src tests benchmarks
	$(PY) -m mypy
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet
	$(PY) -m pytest -n $(JOBS) -q

lint:
	@scripts/setup.sh test
	$(VENV)/bin/ruff check src tests benchmarks

format:
	@scripts/setup.sh test
	$(VENV)/bin/ruff format src tests benchmarks
	$(VENV)/bin/ruff check --fix src tests benchmarks

# The paper's three experiments at its scale, each in its resumable store (out/paper/...), then
# each report. Many hours: see docs/reproduction.md; `make reproduce JOBS=16` on a larger machine.
reproduce:
	@scripts/setup.sh
	for e in illumination viewpoint weather; do \
		$(VENV)/bin/vlocbench run experiments/paper/$$e.yaml --workers $(JOBS) || exit $$?; \
	done

bench:
	@scripts/setup.sh
	for b in benchmarks/bench_*.py; do $(PY) $$b; done

docs:
	@scripts/setup.sh test
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs serve
