# The two set-up commands of the README: `make demo` and `make test`.
# Both create .venv on first use, install the package with the extras the test
# suite needs ([test], [sweep]: Dask, [plot]: matplotlib, [docs]: Sphinx, which
# the suite runs as `make docs`), and make sure Dr.Jit loads an LLVM it can
# compile with (scripts/ensure_llvm.py). `make docs` builds docs/_build/html with
# warnings as errors.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test docs venv clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,sweep,plot,docs]'
	$(PY) scripts/ensure_llvm.py
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m thinfilm_mi demo --out out --spp 64

# The suite runs on pytest-xdist's workers, one per core (at most 4: each holds its own
# Mitsuba, kernels and tables): 6.2 min on 2 cores where one process takes 8.4.
test: $(STAMP)
	$(PY) -m pytest -q -n auto --maxprocesses 4

docs: $(STAMP)
	$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html

clean:
	rm -rf $(VENV) out docs/_build docs/plugins/*.rst
