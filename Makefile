# The two commands of the README: `make run` (whole pipeline at paper scale) and `make test`.
# Both set everything up first (scripts/setup.sh is idempotent).
PY := .venv/bin/python
RUN ?= runs/paper
CONFIG ?= configs/paper.toml
REAL_OUT ?= runs/real-flights

.PHONY: setup run test fuzz real-flights crazypad sim-bench sweep-bench study solvers solver-matrix clean

setup:
	bash scripts/setup.sh

run: setup
	$(PY) -m quadfdi.cli run --config $(CONFIG) --out $(RUN)

# Two pytest workers, one per core, each taking whole files (module fixtures are built once): the
# suite is half subprocesses (C++ builds, QEMU, ONNX Runtime, CLI runs) and half single-threaded
# Python, so one worker per core halves its wall time.
test: setup
	$(PY) -m pytest -q -n 2 --dist loadfile

# The long libFuzzer pass over the C++ readers (firmware_ref/fuzz/run.sh): FUZZ_SECONDS per harness,
# two at a time; corpora, logs and findings in firmware_ref/build-fuzz/run. `make test` runs the same
# harnesses for 10 s each (tests/test_fuzz.py).
FUZZ_SECONDS ?= 600
fuzz: setup
	bash firmware_ref/fuzz/run.sh $(FUZZ_SECONDS)

# README's real-flight tables: the fixed and masked profiles' realistic-suite models (the masked one
# under every mask pattern), parity, then `quadfdi detect` on every shared real quad log and every
# CrazyPAD log (`quadfdi real-flights`, quadfdi/real_flights.py).
real-flights: setup
	$(PY) -m quadfdi.cli real-flights $(REAL_OUT)

# The CrazyPAD protocol scored by the masked run `make real-flights` trains (quadfdi/crazypad.py), written
# into that run's folder so that its report.md carries the table.
CRAZYPAD_RUN ?= $(REAL_OUT)/mask
crazypad: setup
	$(PY) -m quadfdi.cli crazypad $(CRAZYPAD_RUN)/crazypad --run $(CRAZYPAD_RUN) --workers 2

sim-bench: setup
	$(PY) -m quadfdi.cli sim bench --config $(CONFIG)

sweep-bench: setup
	$(PY) -m quadfdi.cli sweep bench

# The seed study, then its headline tables into README.md's results block (quadfdi/readme_study.py).
study: setup
	$(PY) -m quadfdi.cli train study --run $(RUN)
	$(PY) -m quadfdi.cli readme --run $(RUN) --block results

solvers: setup
	$(PY) -m quadfdi.cli solvers study --run $(RUN) --set solvers.sample=128

solver-matrix: setup
	$(PY) -m quadfdi.cli solvers matrix --run $(RUN)

clean:
	rm -rf runs/test-* .pytest_cache
