# mitpiv: `make demo` runs the default experiment; `make test` runs the test suite.
# Both do all set-up first (virtualenv, dependencies, LLVM for Dr.Jit).
PY := .venv/bin/python
OUT ?= out/tomo4

.PHONY: setup demo test lint bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) -m mitpiv.cli run scenes/tomo4/experiment.toml --out $(OUT)

test: setup
	$(PY) -m pytest -q

lint: setup
	.venv/bin/ruff check mitpiv tests bench scenes

bench: setup
	$(PY) bench/bench_speed.py --quick
	$(PY) bench/bench_cameras.py
	$(PY) bench/bench_mie.py
	$(PY) bench/bench_optics.py
	$(PY) bench/bench_lightfield.py
	$(PY) bench/bench_reconstruct.py
	$(PY) bench/bench_analysis.py
	$(PY) bench/bench_holography.py

clean:
	rm -rf out .pytest_cache
