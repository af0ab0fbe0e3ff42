# Two commands do all the set-up on a fresh clone: `make demo` and `make test`.
# Each creates .venv when missing and installs what it needs (again only when
# pyproject.toml changes).

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= demo-out

.PHONY: demo test bench soak lint venv clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,realsense,distributed,mqtt,viewer,boson,infiray,monitor,opcua,modbus,ros,foxglove,map]'
	@# PyGObject (RTSP) builds against the system's GObject introspection: without it the RTSP
	@# tests skip, naming what is missing, and everything else runs
	$(BIN)/python -m pip install --quiet -e '.[video]' || echo "video extra not installed (needs: sudo apt install libgirepository1.0-dev libcairo2-dev pkg-config): the RTSP tests will skip"
	@touch $@

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/thermodepth demo --out $(OUT)

# two workers, each a file at a time (a file's fixtures made once), the longest files first
# (tests/conftest.py: LONGEST_FIRST) and numba on one thread; hypothesis draws the same
# examples every run
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder --hypothesis-profile=ci

bench: $(STAMP)
	$(BIN)/python -m bench

# the monitor for an hour with faults; memory, open files and threads (bench-out/soak_monitor.json)
soak: $(STAMP)
	$(BIN)/python -m bench.soak_monitor --minutes 60

lint: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench
	$(BIN)/mypy

clean:
	rm -rf $(VENV) $(OUT) bench-out build *.egg-info
