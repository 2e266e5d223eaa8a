# darthand: `make assets` builds the default assets, `make test` runs the tests, `make bench` measures.
# Each target bootstraps .venv from pyproject.toml on first use (idempotent).
# Variables: MANO=path/to/MANO_RIGHT.pkl (source model; default: the open CC0 hand), RES (texture size), SIDE.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
DH     := $(VENV)/bin/darthand
STAMP  := $(VENV)/.installed-stamp
MANO   ?=
RES    ?= 2048
SIDE   ?= both
PYTEST_ARGS ?=

SOURCE_MODEL := $(if $(MANO),$(MANO),open)
SOURCE_DEPS  := $(if $(MANO),$(MANO),$(wildcard assets_src/template/*))

.PHONY: assets test test-all bench clean venv
.DEFAULT_GOAL := assets

venv: $(STAMP)
$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install -q --disable-pip-version-check --upgrade pip
	@$(PY) -m pip install -q --disable-pip-version-check -e '.[test]'
	@touch $@

# The source model is recorded so that switching MANO=... rebuilds what depends on it.
build/model/source.txt: FORCE | $(STAMP)
	@mkdir -p build/model
	@echo '$(SOURCE_MODEL)' | cmp -s - $@ || echo '$(SOURCE_MODEL)' > $@
FORCE:

build/model/right.npz build/model/left.npz &: build/model/source.txt $(SOURCE_DEPS) $(STAMP)
	@echo "[model] wrist-enhanced right and left models from $(SOURCE_MODEL)"
	@$(DH) model build $(SOURCE_MODEL) --out-dir build/model

assets: build/model/right.npz build/model/left.npz

test: $(STAMP)
	@$(PY) -m pytest -q -m "not slow" -n 2 $(PYTEST_ARGS)

test-all: $(STAMP)
	@$(PY) -m pytest -q -n 2 $(PYTEST_ARGS)

bench: $(STAMP)
	@$(PY) -m darthand.bench --out build/bench

clean:
	rm -rf build
