# Two commands on a fresh machine (README quick start):
#   make demo   -> creates .venv, installs, runs the main job (the 2-D reproduction study, with figures)
#   make test   -> creates .venv, installs, runs the test suite
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup demo demo3d test test-all docs clean

setup: $(STAMP)

$(STAMP): setup.cfg pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# The pinned CPU torch first (local wheel on our machines); setup.cfg keeps a range it satisfies.
	$(PY) -m pip install --quiet torch==2.13.0
	# every optional world and tool, so that the suite exercises them all (MuJoCo, Ray, rosbags, viser, Foxglove, docs)
	$(PY) -m pip install --quiet -e ".[test,raycast,mujoco,shapes,ray,rosbag,viewer,foxglove,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/gpioius simulate --object all --out outputs/study2d

demo3d: $(STAMP)
	$(VENV)/bin/gpioius simulate3d --object all --out outputs/study3d

test: $(STAMP)
	$(PY) -m pytest -m "not slow" -q -n auto

test-all: $(STAMP)
	$(PY) -m pytest -q

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

clean:
	rm -rf $(VENV) outputs *.egg-info
