# Quick start: `make demo` runs the simulated robot demo, `make test` runs every test.
# Both set the workspace up first (venv, pinned wheels, colcon build) and skip what is done.
PYTHON ?= python3
PYTEST_ARGS ?=
# Parallel test workers (pytest-xdist, one test file per worker at a time, in the order
# of conftest.py; tests marked `alone` still run by themselves).
TEST_WORKERS ?= auto

.PHONY: setup demo scenarios test lint colcon-test bench docker-check clean firmware-flash

setup:
	@$(PYTHON) tools/bootstrap.py

# The simulated robot tours the apartment (12 goals), then writes reports/demo_<time>/:
# run.png, summary.json, an MCAP bag of every topic. DEMO_ARGS: e.g. --foxglove.
DEMO_ARGS ?=
demo:
	@$(PYTHON) tools/bootstrap.py --no-firmware-tests
	@./mecanum run mecanum_bringup demo $(DEMO_ARGS)

# Every scenario file of mecanum_bringup, headless: a pass/fail table, JUnit XML.
scenarios: setup
	@./mecanum run mecanum_bringup run_scenarios src/mecanum_bringup/scenarios \
	  --out reports/scenarios --junit reports/scenarios/junit.xml

test: setup
	@./mecanum exec python -m pytest -n $(TEST_WORKERS) --dist loadfile \
	  --no-loadscope-reorder $(PYTEST_ARGS)

colcon-test: setup
	@./mecanum exec colcon --log-base log/colcon test --base-paths src --build-base build \
	  --install-base install --event-handlers console_cohesion+
	@./mecanum exec colcon test-result --test-result-base build --verbose

# The ESP32 firmware (firmware/README.md): copy it, with board_params.py generated from
# the robot config, to a board running MicroPython; then check it with
# `./mecanum run mecanum_control board_check --port $(PORT)`. FLASH_ARGS: e.g. --no-reset.
PORT ?= /dev/ttyUSB0
FLASH_ARGS ?=
firmware-flash: setup
	@./mecanum exec python firmware/flash.py --port $(PORT) $(FLASH_ARGS)

# Speed benchmarks (not tests: shared machines are noisy); each prints a table.
bench: setup
	@for script in bench/*.py; do ./mecanum exec python $$script || exit 1; done

# The Docker image of the committed HEAD, from a clean clone: docker build, then `make demo`
# in it (and `make test` with DOCKER_CHECK_TESTS=1), a table of the results; the script exits
# 77 where no Docker engine answers (make reports "Error 77"). DOCKER_CHECK_ARGS: e.g.
# --make-base. No setup: it needs git and docker only.
DOCKER_CHECK_ARGS ?=
docker-check:
	@tools/docker_check.sh $(DOCKER_CHECK_ARGS)

clean:
	rm -rf build install log .venv
