# mitpiv: `make demo` renders the default scene; `make test` runs the test suite.
# Both do all set-up first (virtualenv, dependencies, LLVM for Dr.Jit).
PY := .venv/bin/python
OUT ?= out/tomo4

.PHONY: setup demo test lint bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) scenes/tomo4/make_particles.py
	$(PY) -m mitpiv.cli render scenes/tomo4/scene.xml --out $(OUT) --frames 0 1

test: setup
	$(PY) -m pytest -q

lint: setup
	.venv/bin/ruff check mitpiv tests bench scenes

bench: setup
	$(PY) bench/bench_cameras.py
	$(PY) bench/bench_mie.py
	$(PY) bench/bench_optics.py
	$(PY) bench/bench_lightfield.py
	$(PY) bench/bench_reconstruct.py
	$(PY) bench/bench_analysis.py
	$(PY) bench/bench_holography.py

clean:
	rm -rf out .pytest_cache
