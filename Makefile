# Everything runs from a project-local virtualenv that these targets create.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The extras the suite needs (pyproject.toml): web is the Draco and meshopt decoders; vdb and
# noise read density grids from OpenVDB files and bake them from noise.
EXTRAS := test,bench,distributed,video,web,vdb,noise

.PHONY: demo test test-device test-slow bench results info intel-cpu clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[$(EXTRAS)]'
	@# PoCL's compiler (LLVM 14) does not know the newest CPUs: Intel's CPU runtime serves there.
	$(BIN)/python -c 'import sys; from clrays import runtimes; sys.exit(not runtimes.pocl_builds_here())' \
	  || { echo "PoCL cannot build for this CPU: installing Intel's CPU runtime (clrays[intel-cpu])"; \
	       $(BIN)/python -m pip install -q -e '.[$(EXTRAS),intel-cpu]'; }
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/clrays render scenes/demo.yaml -o out/demo.png

# The suite runs on PoCL's CPU device whatever CLRAYS_DEVICE says (tests/conftest.py pins
# it), as CI does. `make test-device DEVICE=nvidia` runs it on another device instead:
# DEVICE is a `--device` spec, `P:D` or a name substring (see `make info`); the golden
# images are PoCL renders, so tests/golden skips on any other device. Rewrite the golden
# images (after a change meant to move them): .venv/bin/python -m pytest tests/golden --regen-golden
test: $(STAMP)
	$(BIN)/python -m pytest

# DEVICE=Intel (any case) first installs Intel's CPU runtime, the `intel-cpu` extra (about
# 800 MB); clrays registers it with the OpenCL loader itself.
INTEL_STAMP := $(VENV)/.intel-cpu
NEEDS_INTEL := $(if $(findstring intel,$(shell echo '$(DEVICE)' | tr 'A-Z' 'a-z')),$(INTEL_STAMP))

$(INTEL_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -e '.[$(EXTRAS),intel-cpu]'
	touch $(INTEL_STAMP)

intel-cpu: $(INTEL_STAMP)

test-device: $(STAMP) $(NEEDS_INTEL)
	@test -n "$(DEVICE)" || { echo "usage: make test-device DEVICE=<spec, e.g. nvidia, Intel or 1:0>"; exit 2; }
	CLRAYS_TEST_DEVICE='$(DEVICE)' $(BIN)/python -m pytest

test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow

# The run-time/error benchmark on every bench scene (tens of minutes on 2 cores), into out/bench/.
bench: $(STAMP)
	$(BIN)/clrays bench -r 1280x720 --volume-only --repeats 3 --out out/bench/volume-1280x720
	$(BIN)/clrays bench -r 1280x720 --repeats 3 --out out/bench/1280x720
	$(BIN)/clrays bench -r 640x360 --repeats 3 --out out/bench/640x360
	$(BIN)/clrays bench -r 640x360 --volume-only --repeats 3 --out out/bench/volume-640x360

# Rewrite bench/RESULTS.md's tables from the maintained benchmarks (bench/scoreboard.py; hours
# on 2 cores). RESULTS_ARGS="--only stages,accuracy" runs some, "--device intel" names the
# device, "--quick" is a smoke run at thumbnail sizes into out/RESULTS.quick.md.
results: $(STAMP)
	$(BIN)/python bench/scoreboard.py $(RESULTS_ARGS)

info: $(STAMP)
	$(BIN)/clrays info

clean:
	rm -rf $(VENV) out build *.egg-info
