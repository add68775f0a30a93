# Two commands do all setup on a fresh machine:
#   make demo   create .venv if missing, install torch (CPU) then margin_rl, run the main job (evaluate the
#               bundled ANYmal B and C policies: comparison table and plot, push recovery, in results/<bundle>;
#               C's rough-ground policies on their card's terrain, in results/anymal_c_rough)
#   make test   same setup, then ruff and the full test suite (the MuJoCo Warp backend's tests run on Warp's CPU
#               device; its kernels compile on first use into ~/.cache/warp)
# torch is installed first and explicitly: on these machines `torch==2.13.0` is a local CPU wheel,
# while any other torch request (e.g. pulled in by a dependency) downloads GBs of CUDA packages.

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
TORCH_SPEC ?= torch==2.13.0
STAMP := $(VENV)/.margin_rl-installed
export PIP_NO_INPUT := 1
export PIP_DISABLE_PIP_VERSION_CHECK := 1
export GIT_PYTHON_REFRESH := quiet
# Headless rendering (videos, rgb_array) through Mesa's EGL; override with MUJOCO_GL=osmesa if preferred.
export MUJOCO_GL ?= egl

.PHONY: install demo test lint clean gl-deps

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

# Mesa's EGL for headless rendering; best effort (rendering tests skip without it).
gl-deps:
	@ldconfig -p | grep -q libEGL_mesa || { \
	  command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ] && \
	  (apt-get update -qq && apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri) \
	  || echo "note: install libegl1 libegl-mesa0 libgl1-mesa-dri for headless rendering"; }

$(STAMP): $(PY) pyproject.toml | gl-deps
	$(PY) -m pip install -q "$(TORCH_SPEC)"
	$(PY) -m pip install -q -e ".[dev,gpu]"
	touch $(STAMP)

install: $(STAMP)

# The main job: evaluate the bundled ANYmal B and C policies (with and without the margin term) and write, per
# robot into results/<bundle>, the comparison table with its statistics, the Fig. 9-style plot and the
# push-recovery curves; then the rough-ground bundle of C on its card's terrain (a few minutes on CPU).
DEMO_BUNDLES ?= anymal_b anymal_c
DEMO_ROUGH_BUNDLE ?= anymal_c_rough
# the cards measure 64 episodes per policy and cell in four conditions; the demo, the three commands on flat ground
# and on rough ground the 0.75 m/s command (the rough card adds 0.5 m/s)
DEMO_EPISODES ?= 16
demo: install
	@for bundle in $(DEMO_BUNDLES); do \
	  $(PY) -m margin_rl.train compare --bundled $$bundle --eval-episodes $(DEMO_EPISODES) \
	    --eval-conditions nominal --out results/$$bundle || exit 1; \
	  $(PY) -m margin_rl.train push-recovery --bundled $$bundle --episodes 8 --forward-velocities 0.75 \
	    --out results/$$bundle || exit 1; \
	done
	$(PY) -m margin_rl.train compare --bundled $(DEMO_ROUGH_BUNDLE) --eval-episodes $(DEMO_EPISODES) \
	  --eval-commands 0.75 --out results/$(DEMO_ROUGH_BUNDLE)

lint: install
	$(PY) -m ruff check .

test: install lint
	$(PY) -m pytest

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .hypothesis
