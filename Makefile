# Quick start: `make demo` runs the simulated robot demo, `make test` runs every test.
# Both set the workspace up first (venv, pinned wheels, colcon build) and skip what is done.
PYTHON ?= python3
PYTEST_ARGS ?=

.PHONY: setup demo test lint colcon-test bench clean

setup:
	@$(PYTHON) tools/bootstrap.py

demo: setup
	@echo "Demo: kinematic robot simulation + text-command controller, each its own process,"
	@echo "driven through a script of mecanum moves; Ctrl-C stops everything."
	@./mecanum launch mecanum_bringup demo.launch.yaml

test: setup
	@./mecanum exec python -m pytest $(PYTEST_ARGS)

colcon-test: setup
	@./mecanum exec colcon --log-base log/colcon test --base-paths src --build-base build \
	  --install-base install --event-handlers console_cohesion+
	@./mecanum exec colcon test-result --test-result-base build --verbose

# Speed benchmarks (not tests: shared machines are noisy); each prints a table.
bench: setup
	@for script in bench/*.py; do ./mecanum exec python $$script || exit 1; done

clean:
	rm -rf build install log .venv
