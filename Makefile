# The two commands of the README: `make run` (whole pipeline at paper scale) and `make test`.
# Both set everything up first (scripts/setup.sh is idempotent).
PY := .venv/bin/python
RUN ?= runs/paper
CONFIG ?= configs/paper.toml

.PHONY: setup run test sim-bench sweep-bench study solvers solver-matrix clean

setup:
	bash scripts/setup.sh

run: setup
	$(PY) -m quadfdi.cli run --config $(CONFIG) --out $(RUN)

test: setup
	$(PY) -m pytest -q

sim-bench: setup
	$(PY) -m quadfdi.cli sim bench --config $(CONFIG)

sweep-bench: setup
	$(PY) -m quadfdi.cli sweep bench

study: setup
	$(PY) -m quadfdi.cli train study --run $(RUN) --readme README.md

solvers: setup
	$(PY) -m quadfdi.cli solvers study --run $(RUN) --set solvers.sample=128

solver-matrix: setup
	$(PY) -m quadfdi.cli solvers matrix --run $(RUN)

clean:
	rm -rf runs/test-* .pytest_cache
