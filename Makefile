# jellysim: set-up and the main jobs. `make demo` runs the main job, `make test` the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: demo test test-all test-gpu lint docs clean venv povray web chromium tbb fish blender

# A virtual environment with jellysim installed (editable). On Debian/Ubuntu the venv module
# lives in the python3-venv package: installed here when run as root, otherwise named.
$(BIN)/jellysim: pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "jellysim needs Python >= 3.11 (found $$($(PYTHON) --version))"; exit 1; }
	@$(PYTHON) -m venv $(VENV) 2>/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null && $(PYTHON) -m venv $(VENV); \
	  else \
	    echo "cannot create a virtual environment: run 'sudo apt-get install python3-venv' and retry"; exit 1; \
	  fi; }
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	@touch $@

venv: $(BIN)/jellysim

# POV-Ray renders the movies (Debian/Ubuntu package povray): installed here when run as root;
# otherwise a note says what to run, and jellysim render falls back to its preview renderer.
povray:
	@command -v povray >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing POV-Ray: apt-get install povray"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends povray >/dev/null; \
	  else \
	    echo "note: POV-Ray is not installed; run 'sudo apt-get install povray' for POV-Ray renders"; \
	  fi; }

# The web viewer's JavaScript (three.js) and the test-only validator and browser driver, pinned
# in web/package.json and web/package-lock.json, installed from the npm registry by npm ci.
# Node.js and npm come from Debian (packages nodejs, npm): installed here when run as root.
web/node_modules/.installed: web/package.json web/package-lock.json
	@command -v npm >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing Node.js and npm: apt-get install nodejs npm"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null; \
	  else \
	    echo "note: npm is not installed; run 'sudo apt-get install nodejs npm' for jellysim view"; \
	    exit 0; \
	  fi; }
	@command -v npm >/dev/null && cd web && npm ci --no-audit --no-fund --loglevel=error && touch node_modules/.installed || true

web: web/node_modules/.installed

# Headless Chromium for the viewer's end-to-end test (Debian package chromium): installed here
# when run as root; otherwise a note says what to run, and that test is skipped outside CI.
chromium:
	@command -v chromium >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing Chromium: apt-get install chromium"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends chromium >/dev/null; \
	  else \
	    echo "note: Chromium is not installed; run 'sudo apt-get install chromium' for the viewer test"; \
	  fi; }

# Debian's TBB runtime (libtbb12), which Blender, OpenCV and others bring and which Numba would take
# as its threading layer: the tests run with it installed to show that jellysim avoids it, and with
# GNU OpenMP (libgomp1), the layer jellysim takes, to show its threads wait passively
# (tests/integration/test_threads.py). Installed here when run as root; otherwise those tests skip.
tbb:
	@{ ldconfig -p | grep -q 'libtbb\.so\.12 ' && ldconfig -p | grep -q 'libgomp\.so\.1 '; } || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing libtbb12 and libgomp1 (the threading-layer tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends libtbb12 libgomp1 >/dev/null; \
	  else \
	    echo "note: libtbb12 or libgomp1 is not installed; the threading-layer tests skip them"; \
	  fi; }

# The fish shell, for the shell-completion test (bash is always there). Installed here when run
# as root; otherwise that test skips its fish part.
fish:
	@command -v fish >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing fish (the shell-completion test)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends fish >/dev/null; \
	  else \
	    echo "note: fish is not installed; the shell-completion test skips it"; \
	  fi; }

# Blender as a Python module (bpy from PyPI, built for CPython 3.11 only) in its own venv, so
# that its numpy pin stays out of jellysim's: the Blender import test runs the exported
# import_into_blender.py with it, headless (Cycles on the CPU). bpy links X11, GL and xkbcommon
# client libraries (no display is used): installed here from Debian when run as root.
BPY_VERSION  := 5.0.1
BLENDER_VENV ?= .venv-blender
BPY_LIBS     := libx11-6 libxext6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libgl1
blender:
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && \
	  ! dpkg -s $(BPY_LIBS) >/dev/null 2>&1; then \
	  echo "installing the libraries bpy links: $(BPY_LIBS)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	    apt-get install -y -qq --no-install-recommends $(BPY_LIBS) >/dev/null; \
	fi
	@$(BLENDER_VENV)/bin/python -c 'import bpy' 2>/dev/null || { \
	  py=; for p in $(PYTHON) python3.11; do \
	    $$p -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null && { py=$$p; break; }; \
	  done; \
	  if [ -z "$$py" ]; then \
	    echo "note: bpy $(BPY_VERSION) needs Python 3.11 (none found); the Blender import test skips"; \
	  else \
	    echo "installing bpy $(BPY_VERSION) into $(BLENDER_VENV) (about 400 MB)"; \
	    $$py -m venv $(BLENDER_VENV) && $(BLENDER_VENV)/bin/python -m pip install -q "bpy==$(BPY_VERSION)"; \
	  fi; }

# The main job: simulate the brown-jelly preset, draw its figures and render its movie.
demo: $(BIN)/jellysim povray web
	$(BIN)/jellysim run purple-jelly --out $(OUT)/purple-jelly --force --set duration=6
	$(BIN)/jellysim plot $(OUT)/purple-jelly
	$(BIN)/jellysim render $(OUT)/purple-jelly --force
	$(BIN)/jellysim render $(OUT)/purple-jelly --out $(OUT)/purple-jelly/poster --quality final \
		--size 1280x960 --frames 150:151 --no-video --force
	@echo
	@echo "Result:  $(OUT)/purple-jelly/result.h5 (resolved scene: $(OUT)/purple-jelly/scene.toml)"
	@echo "Figures: $(OUT)/purple-jelly/plots/"
	@echo "Movie:   $(OUT)/purple-jelly/render/movie.mp4 (draft quality, 6 s)"
	@echo "Poster:  $(OUT)/purple-jelly/poster/frames/frame_00150.png (final quality)"
	@echo "Play it: $(BIN)/jellysim view $(OUT)/purple-jelly"

# The tests CI runs: everything but the tests marked slow that guard no physics claim.
test: $(BIN)/jellysim povray web chromium tbb fish blender
	$(BIN)/python -m pytest -q --durations=25

# Every test, slow ones included.
test-all: $(BIN)/jellysim povray web chromium tbb fish blender
	$(BIN)/python -m pytest -q --runslow

# The GPU path's tests on a real NVIDIA GPU (numba-cuda: pip install jellysim[cuda]); without
# one they skip. make test runs the same kernels in Numba's CUDA simulator on tiny scenes.
test-gpu: $(BIN)/jellysim
	$(BIN)/pip install -q -e '.[cuda]'
	JELLYSIM_TEST_GPU=1 $(BIN)/python -m pytest -q tests/gpu

lint: $(BIN)/jellysim
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/mypy

# Regenerate the scene reference from the dataclasses.
docs: $(BIN)/jellysim
	$(BIN)/python -m jellysim.config.docs > docs/scene.md

clean:
	rm -rf $(VENV) $(BLENDER_VENV) $(OUT) build src/*.egg-info .pytest_cache
	find src tests -name __pycache__ -type d -prune -exec rm -rf {} +
