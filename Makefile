# Every target sets up .venv first; nothing needs installing by hand.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
GCODE ?= testdata/part_3tool_prusaslicer_rel.gcode
TRACE ?= out/trace.vcd
REPORT ?= out/report.json

.PHONY: all setup test test-all sim serve clean

all: setup

setup: $(STAMP)

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	# printcore, the host client of Printrun, is all the tests use: its GUI
	# dependencies (wxPython, ...) are left out.
	$(PY) -m pip install --quiet --no-deps Printrun==2.2.0
	$(PY) -m pip install --quiet pyserial==3.5
	touch $(STAMP)

# The tests run in parallel, one worker per core (pytest-xdist). `make test` is the
# quick check of every feature (a few minutes); `make test-all` (what CI runs) adds the
# tests marked slow (long fuzzing, whole prints on every board, the emulated chip's
# longer runs, real host clients) and the firmware's tests on the 32-bit,
# single-precision MicroPython when one is at hand (CHIP32=path, default
# ../shared/chip32/micropython; no package registry has one).
CHIP32 ?= ../shared/chip32/micropython
CHIP32_TESTS := host_tests/test_mixer.py host_tests/test_planner.py \
	host_tests/test_gradient.py host_tests/test_transition.py host_tests/test_tools.py \
	host_tests/test_protocol.py host_tests/test_host_commands.py host_tests/test_safety.py \
	host_tests/test_heap.py host_tests/test_flash_writes.py host_tests/test_homing.py \
	host_tests/test_pwm.py host_tests/test_tmc.py host_tests/test_inram.py \
	host_tests/test_piodma.py host_tests/test_ramp.py host_tests/test_lookahead.py \
	host_tests/test_geometry.py host_tests/test_arcs.py host_tests/test_objects.py \
	host_tests/test_job_commands.py host_tests/test_pressure_advance.py \
	host_tests/test_runout.py host_tests/test_mesh.py

test: setup
	$(PY) -m pytest -q -n auto --dist loadscope -m "not slow"

test-all: setup
	$(PY) -m pytest -q -n auto
	@if [ -x "$(CHIP32)" ]; then \
		MIXSTEP_MICROPYTHON="$$(cd "$$(dirname "$(CHIP32)")" && pwd)/$$(basename "$(CHIP32)")" \
			$(PY) -m pytest -q -n auto $(CHIP32_TESTS); \
	else \
		echo "no 32-bit MicroPython at $(CHIP32): its second pass is skipped"; \
	fi

sim: setup
	@mkdir -p $(dir $(TRACE)) $(dir $(REPORT))
	$(VENV)/bin/mixstep sim $(GCODE) --trace $(TRACE) --report $(REPORT)

# make serve TCP=127.0.0.1:8888 and/or HTTP=127.0.0.1:8080 (the web page), or make
# serve PTY=1 (prints the device path); REALTIME=0 runs as fast as it can,
# CONFIG=FILE and FILES=DIR move the simulated flash (default out/printer/).
serve: setup
	$(VENV)/bin/mixstep serve $(if $(TCP),--tcp $(TCP)) $(if $(HTTP),--http $(HTTP)) \
		$(if $(PTY),--pty) \
		$(if $(REALTIME),--realtime $(REALTIME)) $(if $(CONFIG),--config $(CONFIG)) \
		$(if $(FILES),--files $(FILES))

clean:
	rm -rf $(VENV) $(HOSTS_VENV) out build *.egg-info emu/node_modules

# The firmware on an emulated Pico: make emu [GCODE=file] [IMAGE=dir] [TRACE=..] [REPORT=..].
# Without GCODE it prints a short excerpt of the example (the whole example would take
# hours of wall time). emu-setup installs rp2040js into emu/node_modules with npm ci.
EMU_STAMP := emu/node_modules/.installed
EMU_GCODE = $(if $(filter file,$(origin GCODE)),testdata/part_3tool_emu_excerpt.gcode,$(GCODE))
EMU_TRACE = $(if $(filter file,$(origin TRACE)),out/emu.vcd,$(TRACE))
EMU_REPORT = $(if $(filter file,$(origin REPORT)),out/emu.json,$(REPORT))
.PHONY: emu emu-setup
emu-setup: $(EMU_STAMP)

$(EMU_STAMP): emu/package.json emu/package-lock.json
	@command -v node >/dev/null && command -v npm >/dev/null || { echo "node and npm not found: install Node.js 18 or newer with npm (e.g. apt-get install nodejs npm)"; exit 2; }
	cd emu && npm ci --no-audit --no-fund
	touch $(EMU_STAMP)

emu: setup emu-setup
	@mkdir -p $(dir $(EMU_TRACE)) $(dir $(EMU_REPORT))
	$(VENV)/bin/mixstep emu print $(EMU_GCODE) --board pico --trace $(EMU_TRACE) \
		--report $(EMU_REPORT) $(if $(IMAGE),--image $(IMAGE))

# Cost of one step-loop call (a stepping tick, an idle tick, the Pin.value path), each as a
# ratio to an empty viper call, on the unix port.
.PHONY: step-cost
step-cost: setup
	MICROPYPATH=firmware:boards/sim $${MIXSTEP_MICROPYTHON:-$(VENV)/bin/micropython} bench/step_cost.py

# Onto a board: make deploy BOARD=pico PORT=/dev/ttyACM0 (DRY_RUN=1 prints the
# mpremote commands; FROZEN=1 on a board flashed with the image make freeze describes),
# make freeze BOARD=esp32_devkit, make board-check BOARD=... PORT=...
.PHONY: deploy freeze board-check boards-check
NEED_BOARD = @test -n "$(BOARD)" || { echo "give BOARD=<name>, one of: $(notdir $(patsubst %/board.py,%,$(wildcard boards/*/board.py)))"; exit 2; }
NEED_PORT = @test -n "$(PORT)" || { echo "give PORT=<serial port>, e.g. PORT=/dev/ttyACM0"; exit 2; }
deploy: setup
	$(NEED_BOARD)
	$(NEED_PORT)
	$(VENV)/bin/mixstep deploy --board $(BOARD) --port $(PORT) $(if $(DRY_RUN),--dry-run) \
		$(if $(FROZEN),--frozen)
freeze: setup
	$(NEED_BOARD)
	$(VENV)/bin/mixstep freeze --board $(BOARD)
board-check: setup
	$(NEED_BOARD)
	$(NEED_PORT)
	$(VENV)/bin/mixstep board-check --board $(BOARD) --port $(PORT) $(if $(DRY_RUN),--dry-run)
boards-check: setup
	$(VENV)/bin/mixstep boards check $(BOARD)

# Benchmarks: bench.json and a table of figures against their targets. QUICK=1 gives
# the host tools ~100 MB inputs instead of 1 GB (generated under out/bench/).
.PHONY: bench
bench: setup
	$(PY) bench/run.py $(if $(QUICK),--quick)

# OctoPrint, for host_tests/test_octoprint.py, in a venv of its own (its pinned
# dependencies must not meet the project's). make hosts installs it once.
HOSTS_VENV := .venv-hosts
HOSTS_STAMP := $(HOSTS_VENV)/.installed
OCTOPRINT_VERSION := 1.11.8
.PHONY: hosts
hosts: $(HOSTS_STAMP)

$(HOSTS_STAMP):
	python3 -m venv $(HOSTS_VENV)
	$(HOSTS_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(HOSTS_VENV)/bin/python -m pip install --quiet OctoPrint==$(OCTOPRINT_VERSION)
	touch $(HOSTS_STAMP)
