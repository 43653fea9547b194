# Everything runs from a project-local virtualenv that these targets create.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow bench info clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test,bench]'
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/clrays render scenes/demo.yaml -o out/demo.png

test: $(STAMP)
	$(BIN)/python -m pytest

test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow

# The run-time/error benchmark behind bench/RESULTS.md (tens of minutes on 2 cores).
bench: $(STAMP)
	$(BIN)/clrays bench -r 640x360 -r 1280x720 --out bench/results
	$(BIN)/clrays bench -r 640x360 --volume-only --out bench/results-volume

info: $(STAMP)
	$(BIN)/clrays info

clean:
	rm -rf $(VENV) out build *.egg-info
