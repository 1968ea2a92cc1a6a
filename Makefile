# Two entry points (see README): `make demo` and `make test`. Each creates .venv on first use.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/demo

.PHONY: demo test test-all test-addon-4.2 bench addon clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	# The CPU build, named exactly: an open `torch` requirement would pull a multi-GB CUDA build.
	$(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -e ".[dev,blender,diffusion,dist,traffic,import]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/symdrive demo --quick --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest

test-all: $(STAMP)
	$(BIN)/python -m pytest -m "slow or not slow"

# The add-on tests again on the oldest Blender the add-on supports (bpy 4.2 LTS, put first on the path).
# test_helpers.py is bpy-free (run by `make test`); left out here because bpy 4.2 segfaults at
# interpreter exit in any process that also ran a hypothesis test, after every test has passed.
BPY42 := build/bpy-4.2
$(BPY42)/.installed: | $(STAMP)
	$(BIN)/python -m pip install --no-deps --target $(BPY42) "bpy>=4.2,<4.3"
	touch $@

test-addon-4.2: $(BPY42)/.installed
	PYTHONPATH=$(BPY42) $(BIN)/python -m pytest tests/addon -m "slow or not slow" --ignore tests/addon/test_helpers.py

bench: $(STAMP)
	$(BIN)/python scripts/bench_ply.py
	$(BIN)/python scripts/bench_render.py --quick

addon: $(STAMP)
	$(BIN)/python scripts/build_addon

clean:
	rm -rf $(VENV) out build dist *.egg-info
