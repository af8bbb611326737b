# Every target sets up .venv first; nothing needs installing by hand.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
GCODE ?= testdata/part_3tool_prusaslicer_rel.gcode
TRACE ?= out/trace.vcd
REPORT ?= out/report.json

.PHONY: all setup test sim clean

all: setup

setup: $(STAMP)

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

test: setup
	$(PY) -m pytest -q

sim: setup
	@mkdir -p $(dir $(TRACE)) $(dir $(REPORT))
	$(VENV)/bin/mixstep sim $(GCODE) --trace $(TRACE) --report $(REPORT)

clean:
	rm -rf $(VENV) out build *.egg-info

# Cost of one step-loop call (viper vs bytecode vs an empty viper call) on the unix port.
.PHONY: step-cost
step-cost: setup
	MICROPYPATH=firmware:boards/sim $(VENV)/bin/micropython bench/step_cost.py
