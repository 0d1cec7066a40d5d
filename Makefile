# spreadmap: the two commands of the README.
#   make map    set everything up, run the workflow at the `default` fidelity level
#   make test   set everything up, run the linters and the test suite
# Both install what is missing (LIGGGHTS from Debian's packages, a virtual
# environment from requirements.txt) and are safe to repeat.

SHELL   := /bin/bash
VENV    := .venv
PYTHON  := $(VENV)/bin/python
CORES   ?= $(shell nproc)
LEVEL   ?= default
SUDO    := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Debian packages: the DEM engine and its MPI launcher, and the GL libraries
# VTK's wheel loads at run time for off-screen rendering.
APT_PACKAGES := liggghts liggghts-doc openmpi-bin libegl1 libegl-mesa0 libgl1-mesa-dri
export VTK_DEFAULT_OPENGL_WINDOW := vtkEGLRenderWindow

# The one-node SLURM cluster of benchmarks/bench_slurm.py (benchmarks/slurm_cluster.py; not needed by `make test`).
SLURM_APT_PACKAGES := slurm-wlm munge libpmix-dev slurmdbd mariadb-server

.PHONY: map test setup system-packages report clean bench-slurm

map: setup
	$(PYTHON) -m snakemake --cores $(CORES) --config level=$(LEVEL) --rerun-incomplete
	$(PYTHON) -m snakemake --cores 1 --config level=$(LEVEL) --report results/$(LEVEL)/report.html
	@echo "Process maps: results/$(LEVEL)/maps/  report: results/$(LEVEL)/report.html"

test: setup
	PYTHON=$(PYTHON) .ci/lint
	$(PYTHON) -m pytest -n 2 --dist loadscope --no-loadscope-reorder -q --durations=15 tests

# The SLURM path on a real one-node cluster (root; its run time: benchmarks/README.md): benchmarks/measured/slurm.md
bench-slurm: setup
	@if ! dpkg -s $(SLURM_APT_PACKAGES) >/dev/null 2>&1; then \
	    echo "Installing $(SLURM_APT_PACKAGES) from Debian's packages"; \
	    $(SUDO) apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $(SLURM_APT_PACKAGES) >/dev/null; \
	fi
	$(PYTHON) benchmarks/bench_slurm.py

setup: system-packages $(VENV)/.installed

system-packages:
	@if ! dpkg -s $(APT_PACKAGES) >/dev/null 2>&1; then \
	    echo "Installing $(APT_PACKAGES) from Debian's packages"; \
	    $(SUDO) apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $(APT_PACKAGES) >/dev/null; \
	fi
	@command -v liggghts >/dev/null || { echo "error: liggghts is not on PATH after installing"; exit 1; }

$(VENV)/.installed: requirements.txt pyproject.toml
	python3 -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --disable-pip-version-check -r requirements.txt  # with bytecode: PYTHONDONTWRITEBYTECODE may be set, and every job would compile its imports
	$(VENV)/bin/pip install --quiet --disable-pip-version-check --no-deps -e .  # the `analysis` package itself
	touch $@

clean:
	rm -rf results .snakemake
