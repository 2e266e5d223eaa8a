# darthand: `make assets` builds the default assets, `make test` runs the tests, `make bench` measures.
# Each target bootstraps .venv from pyproject.toml on first use (idempotent); Node tooling (the Khronos glTF
# validator, three.js) comes from package-lock.json when npm is on the machine.
#
# Variables: MANO=path/to/MANO_RIGHT.pkl (source model; default: the open CC0 hand), BETAS="b1 b2 ..." (build the
# hand of that shape: every package, texture and accessory fits it; default the mean shape), RES (texture size,
# default 2048), TX=1 (also the tiled, mip-mapped .tx textures for offline renderers: about 0.2 s of CPU per
# variant), SIDE (right, left or both), TEXTURE / ACCESSORY (catalogue ids for `make usdz`; default: the package's
# default texture and no accessory).

PYTHON ?= python3
# Steps whose inputs are ready run JOBS at a time: on two cores the single-threaded steps (gestures, the USD and
# glTF writers, validation) overlap the two-process ones (textures, accessories) instead of leaving a core idle.
JOBS   ?= 2
ifeq ($(MAKELEVEL),0)   # a second make (assets, after the repair) shares the first one's job slots
MAKEFLAGS += -j$(JOBS)
endif
VENV   := .venv
# Blender as a Python module (bpy from PyPI) in its own environment: bpy 5.0 pins numpy < 2, the project uses
# numpy 2. Tests import packages with it; `make assets` writes the .blend rigs with it.
BLENDER_VENV  := .venv-blender
BPY           ?= bpy==5.0.1
BLENDER_STAMP := $(BLENDER_VENV)/.installed-stamp
# The realism benchmark's hand detector (MediaPipe) in its own environment: `make detector`.
DETECTOR_VENV  := .venv-detector
DETECTOR_STAMP := $(DETECTOR_VENV)/.installed-stamp
PY     := $(VENV)/bin/python
DH     := $(VENV)/bin/darthand
STEP    = $(PY) -m darthand.step
STAMP  := $(VENV)/.installed-stamp
BENCH_STAMP := $(VENV)/.bench-stamp
NODE_STAMP := node_modules/.installed-stamp
MANO   ?=
BETAS  ?=
RES    ?= 2048
TX     ?= 0
SIDE   ?= both
TEXTURE   ?=
ACCESSORY ?= none
PYTEST_ARGS ?=

SOURCE_MODEL := $(if $(MANO),$(MANO),open)
SOURCE_DEPS  := $(if $(MANO),$(MANO),$(wildcard assets_src/template/*.npz))
SIDES        := $(if $(filter both,$(SIDE)),right left,$(SIDE))
POSES        := $(wildcard assets_src/poses/*.json)
# A stage's outputs depend on its own code too, so editing a generator rebuilds what it made.
src = $(wildcard tools/darthand/$(1)/*.py tools/darthand/$(1)/*/*.py)

.PHONY: assets verify-build shapes test test-all lint bench usdz clean venv node blender chromium detector FORCE
.DEFAULT_GOAL := assets
# A step that fails leaves no output make would take as up to date next time (grouped targets: all of them), so a
# failed step fails again on every run until its cause is fixed.
.DELETE_ON_ERROR:

# ------------------------------------------------------------------ set-up
venv: $(STAMP)
$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install -q --disable-pip-version-check --upgrade pip
	@$(PY) -m pip install -q --disable-pip-version-check -e '.[test,cluster]'
	@touch $@

blender: $(BLENDER_STAMP)
$(BLENDER_STAMP): Makefile
	@test -x $(BLENDER_VENV)/bin/python || $(PYTHON) -m venv $(BLENDER_VENV)
	@$(BLENDER_VENV)/bin/python -m pip install -q --disable-pip-version-check '$(BPY)'
	@touch $@

node: $(NODE_STAMP)
$(NODE_STAMP): package.json package-lock.json
	@if command -v npm >/dev/null 2>&1; then npm ci --no-audit --no-fund --loglevel=error && touch $@; \
	 else echo "npm not found: glTF validator tests will be skipped"; fi

# Debian's chromium drives the studio's browser tests (through puppeteer-core, which never downloads a browser): apt
# installs it where it can (root, as on CI); otherwise those tests skip and say why.
chromium:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing Debian's chromium for the studio's browser tests"; \
	    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	      chromium >/dev/null; } || echo "chromium could not be installed: the studio's browser tests will skip"; \
	  else echo "chromium is not installed (needs root and apt): the studio's browser tests will skip"; fi; }

# ------------------------------------------------------------------ assets
# The source model and shape are recorded so that switching MANO=... or BETAS=... rebuilds everything that depends
# on them.
build/model/source.txt: FORCE | $(STAMP)
	@mkdir -p build/model
	@echo '$(SOURCE_MODEL) $(strip $(BETAS))' | cmp -s - $@ || echo '$(SOURCE_MODEL) $(strip $(BETAS))' > $@

# The model carries its gestures fitted to it (model/gesture_fit), so the gesture files are its inputs too.
build/model/right.npz build/model/left.npz &: build/model/source.txt $(SOURCE_DEPS) $(POSES) $(call src,model) $(STAMP)
	@$(STEP) model -- $(DH) model build $(SOURCE_MODEL) --out-dir build/model --atlas-res $(RES) \
	    $(if $(strip $(BETAS)),--betas '$(strip $(BETAS))')

build/template/gestures.json build/template/gestures.png &: build/model/right.npz $(POSES) $(call src,template)
	@$(STEP) gestures -- $(DH) template gestures build/model/right.npz --out-dir build/template

# The pose library fitted to the model (model/library_fit) and drawn on it, a sheet per group: a step of its own that
# nothing else in ASSETS waits for, so its 165 fits (about 4 min of CPU, in two processes) overlap the textures and
# packages; one fit serves both sides (the left model is the right one's mirror, the angles mirror-symmetric). A
# pose whose fit inputs did not change since the record it replaces keeps its fit (editing model code the fit does
# not run refits nothing). LIBRARY_POSES="name name ...": fit only these (the whole-pipeline test's economy; a
# dataset drawing from the library needs all of them).
LIBRARY := $(wildcard assets_src/poses/library/*.json)
build/poses/right.json: build/model/right.npz $(POSES) $(LIBRARY) $(call src,model) $(STAMP)
	@$(STEP) pose-library -- $(DH) model fit-library build/model/right.npz --out $@ --jobs 2 \
	    $(if $(LIBRARY_POSES),--poses $(LIBRARY_POSES))
	@$(STEP) pose-library-sheets -- $(DH) model library-sheet build/model/right.npz --fit $@ --out-dir build/poses

# The shape space: extreme shapes at rest and through every gesture (fitted to each shape, as `model build` fits them
# to the hand it builds), hand sizes against ANSUR II (`make shapes`: about 2.5 min of CPU for the 21 gesture fits,
# so not part of `make assets`).
shapes: build/template/shapes.json

build/template/shapes.json build/template/shapes.png build/template/shape_gestures.png &: build/model/right.npz $(POSES) $(call src,template)
	@$(STEP) shapes -- $(DH) template shapes build/model/right.npz --out-dir build/template

build/textures/res.txt: FORCE | $(STAMP)
	@mkdir -p build/textures
	@echo '$(RES) tx=$(TX)' | cmp -s - $@ || echo '$(RES) tx=$(TX)' > $@

build/textures/catalog.json: build/model/right.npz build/textures/res.txt $(wildcard assets_src/textures/*.json) \
                             $(call src,textures)
	@$(STEP) textures -- $(DH) textures build build/model/right.npz --out build/textures --res $(RES) --jobs 2 \
	    $(if $(filter 1,$(TX)),,--no-tx)

build/accessories/catalog.json: build/model/right.npz $(wildcard assets_src/accessories/*.json) \
                                $(call src,accessories)
	@$(STEP) accessories -- $(DH) accessories build build/model/right.npz --out build/accessories --jobs 2

# The objects a hand holds: generated and imported meshes, checked (no model needed).
build/objects/catalog.json: $(wildcard assets_src/objects/*.json assets_src/objects/*/*) $(call src,objects) \
                            | $(STAMP)
	@$(STEP) objects -- $(DH) objects build --out build/objects

# Grasps of the taxonomy fitted to every catalogue object, both hands (grasps stage, after the objects stage; about 4
# min of CPU). GRASP_OBJECTS="id id ...": grasp only these (the whole-pipeline test's economy).
build/grasps/catalog.json: build/model/right.npz build/model/left.npz build/objects/catalog.json \
                           assets_src/poses/library/grasps.json $(call src,grasps)
	@$(STEP) grasps -- $(DH) grasps build build/model/right.npz build/model/left.npz \
	    --objects build/objects/catalog.json --out build/grasps --jobs 2 $(if $(GRASP_OBJECTS),--ids $(GRASP_OBJECTS))

# One USD package and one glTF file per side.
define side_rules
build/usd/$(1)/$(1).usda: build/model/$(1).npz build/textures/catalog.json build/accessories/catalog.json \
                          $(call src,export)
	@$$(STEP) usd-$(1) -- $$(DH) export usd build/model/$(1).npz --out build/usd/$(1) \
	    --textures build/textures/catalog.json --accessories build/accessories/catalog.json

# glTF: the hand with the default texture (.glb), and every texture as KHR_materials_variants (.gltf package).
build/gltf/$(1).glb: build/model/$(1).npz build/textures/catalog.json $(call src,export)
	@$$(STEP) gltf-$(1) -- $$(DH) export gltf build/model/$(1).npz --out $$@ \
	    --textures build/textures/catalog.json

build/gltf/$(1)/$(1).gltf: build/model/$(1).npz build/textures/catalog.json $(call src,export)
	@$$(STEP) gltf-variants-$(1) -- $$(DH) export gltf build/model/$(1).npz --out $$@ \
	    --textures build/textures/catalog.json --all-textures

# Blender-native rig: correctives driven by the bones (USD and glTF keep baked gesture animations).
build/blender/$(1).blend: build/model/$(1).npz build/textures/catalog.json $(call src,export) $(BLENDER_STAMP)
	@$$(STEP) blend-$(1) -- $$(DH) export blend build/model/$(1).npz --out $$@ --textures build/textures/catalog.json
endef
$(foreach s,right left,$(eval $(call side_rules,$(s))))

build/checks/report.json: $(foreach s,$(SIDES),build/usd/$(s)/$(s).usda) $(call src,render)
	@$(STEP) checks -- $(DH) render-checks --build build --sides $(SIDES)

build/validate/report.json: $(foreach s,$(SIDES),build/usd/$(s)/$(s).usda build/gltf/$(s).glb build/gltf/$(s)/$(s).gltf) \
                            $(call src,validate) $(NODE_STAMP)
	@$(STEP) validate -- $(DH) validate $(foreach s,$(SIDES),build/usd/$(s) build/gltf/$(s).glb build/gltf/$(s)) \
	    --out $@

ASSETS := build/model/right.npz build/template/gestures.json build/poses/right.json build/textures/catalog.json \
          build/accessories/catalog.json build/objects/catalog.json \
          $(foreach s,$(SIDES),build/usd/$(s)/$(s).usda build/gltf/$(s).glb build/gltf/$(s)/$(s).gltf \
                               build/blender/$(s).blend) \
          build/checks/report.json build/validate/report.json

# The grasps come after the objects stage's catalogue, which they grasp.
ASSETS += build/grasps/catalog.json

build/manifest.json: $(ASSETS)
	@$(DH) manifest --build build

# Outputs damaged since the manifest was written (a truncated texture, a deleted file) are removed and their steps
# dated back, so the rules above rebuild them (no-op without a manifest). The build is a second make, started after
# the repair: with JOBS > 1 a prerequisite listed beside verify-build would be judged while the repair runs.
verify-build: | $(STAMP)
	@$(DH) verify --build build --repair

assets: verify-build
	@$(MAKE) --no-print-directory build/.checks-passed

# Exit 1 while any check the manifest records fails. The stamp is made only when they all pass, so a failed check
# fails every run until it passes, and a manifest written since (a rebuild, an edit) is checked again; a no-op run
# starts no Python for it.
build/.checks-passed: build/manifest.json
	@$(DH) manifest --build build --check
	@touch $@

# One variant combination as a .usdz: make usdz TEXTURE=light_tattoos_07 ACCESSORY=watch_03_round_metal
usdz: build/usd/right/right.usda
	@$(DH) export usdz build/usd/right $(if $(TEXTURE),--texture $(TEXTURE)) --accessory $(ACCESSORY) \
	    --out build/usdz/right_$(or $(TEXTURE),default)_$(ACCESSORY).usdz

# ------------------------------------------------------------------ tests and benchmarks
# Two pytest workers, each with single-threaded BLAS: threaded BLAS in both workers oversubscribes two cores.
# --dist loadgroup keeps the tests marked xdist_group (the Ray cluster's) on one worker, with one cluster.
# --durations=25: the slowest tests, in CI's log.
TEST_ENV := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

# Lint first: ruff and mypy (settings in pyproject.toml) take seconds, the tests minutes.
test: lint $(STAMP) $(NODE_STAMP) $(BLENDER_STAMP) chromium
	@$(TEST_ENV) $(PY) -m pytest -q -m "not slow" -n 2 --dist loadgroup --durations=25 $(PYTEST_ARGS)

test-all: lint $(STAMP) $(NODE_STAMP) $(BLENDER_STAMP) chromium
	@$(TEST_ENV) $(PY) -m pytest -q -n 2 --dist loadgroup --durations=25 $(PYTEST_ARGS)

# Zero findings: ruff over the package, the tests, the benchmarks and testkit; mypy over the package (about a minute
# on the first run, a few seconds from its cache, .mypy_cache/).
LINT_PATHS := tools/darthand tests benchmarks testkit
lint: $(STAMP)
	@$(PY) -m ruff check --quiet $(LINT_PATHS)
	@$(PY) -m mypy

# The benchmarks' own dependencies (the bench extra: Mitsuba, the path-traced reference); without them the
# render_reference benchmark reports itself skipped.
$(BENCH_STAMP): pyproject.toml | $(STAMP)
	@$(PY) -m pip install -q --disable-pip-version-check -e '.[test,bench]' && touch $@ \
	 || echo "bench extra not installed: the render_reference benchmark will be skipped"

# The realism benchmark's hand landmarker (MediaPipe, trained on real photographs) in its own environment, out of the
# project's dependencies (benchmarks/detector-requirements.txt says why each pin); without it the realism benchmark
# reports itself skipped.
detector: $(DETECTOR_STAMP)
$(DETECTOR_STAMP): benchmarks/detector-requirements.txt
	@{ test -x $(DETECTOR_VENV)/bin/python || $(PYTHON) -m venv $(DETECTOR_VENV); } && \
	 $(DETECTOR_VENV)/bin/python -m pip install -q --disable-pip-version-check --no-deps \
	   -r benchmarks/detector-requirements.txt && touch $@ \
	 || echo "hand detector not installed: the realism benchmark will be skipped"

bench: $(STAMP) $(BENCH_STAMP) $(NODE_STAMP) build/model/right.npz detector
	@$(PY) -m benchmarks --out build/bench

clean:
	rm -rf build
