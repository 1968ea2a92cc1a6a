# Two entry points (see README): `make demo` and `make test`. Each creates .venv on first use.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/demo

.PHONY: demo test test-all bench addon clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	# The CPU build, named exactly: an open `torch` requirement would pull a multi-GB CUDA build.
	$(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -e ".[dev,blender,diffusion,dist,traffic]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/symdrive demo --quick --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest

test-all: $(STAMP)
	$(BIN)/python -m pytest -m "slow or not slow"

bench: $(STAMP)
	$(BIN)/python scripts/bench_ply.py
	$(BIN)/python scripts/bench_render.py --quick

addon: $(STAMP)
	$(BIN)/python scripts/build_addon

clean:
	rm -rf $(VENV) out build dist *.egg-info
