# Two entry points (see README): `make demo` and `make test`. Each creates .venv on first use.
PYTHON ?= python3
# One environment per interpreter: .venv for the default python3, .venv-python3.13 and so on for another.
VENV   := $(if $(filter python3,$(PYTHON)),.venv,.venv-$(notdir $(PYTHON)))
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/demo

.PHONY: demo test test-all test-addon-4.2 test-addon-5.2 bench addon clean

# Python 3.11 to 3.13 (bpy wheels exist for 3.11 and 3.13; on 3.12 the add-on tests are skipped).
$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; v = sys.version_info[:2]; sys.exit(0 if (3, 11) <= v <= (3, 13) else \
		"SymDrive needs Python 3.11, 3.12 or 3.13; $(PYTHON) is %d.%d: run make with PYTHON=python3.11" % v)'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	# The CPU build, named exactly: an open `torch` requirement would pull a multi-GB CUDA build.
	$(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -e ".[dev,blender,diffusion,dist,traffic,sim,import]"
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

# The add-on tests on the newest Blender, whose bpy wheels are for Python 3.13 only (5.1, 5.2 LTS):
# a separate venv with what the add-on and its tests need (the `blender` extra's bpy and numpy as
# pip resolves them for Python 3.13, no torch: the one backend test skips).
PYTHON313 ?= $(or $(firstword $(wildcard $(shell pyenv root 2>/dev/null)/versions/3.13*/bin/python3)),python3.13)
VENV52 := build/venv-5.2
$(VENV52)/.installed: pyproject.toml
	$(PYTHON313) -m venv $(VENV52)
	$(VENV52)/bin/python scripts/build_addon --blender-requirements > $(VENV52)/blender-requirements.txt
	$(VENV52)/bin/python -m pip install -r $(VENV52)/blender-requirements.txt "bpy>=5.2,<5.3" \
		pytest hypothesis jsonschema plyfile OpenImageIO trimesh
	touch $@

test-addon-5.2: $(VENV52)/.installed
	$(VENV52)/bin/python -m pytest tests/addon -m "slow or not slow"

bench: $(STAMP)
	$(BIN)/python scripts/bench_ply.py
	$(BIN)/python scripts/bench_render.py --quick

addon: $(STAMP)
	$(BIN)/python scripts/build_addon

clean:
	rm -rf $(VENV) out build dist *.egg-info
