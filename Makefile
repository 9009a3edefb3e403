# The two set-up commands of the README: `make demo` and `make test`.
# Both create .venv on first use, install the package with the extras the test
# suite needs ([test], [sweep]: Dask, [plot]: matplotlib), and make sure Dr.Jit
# loads an LLVM it can compile with (scripts/ensure_llvm.py).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test venv clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,sweep,plot]'
	$(PY) scripts/ensure_llvm.py
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m thinfilm_mi demo --out out --spp 64

test: $(STAMP)
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) out
