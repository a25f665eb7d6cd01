# The two commands a planner needs: `make run` and `make test`.
# Both create .venv and install fleet_sim into it on first use.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: run test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]'
	touch $(STAMP)

# Main job: a one-shift run of the realistic warehouse, KPIs printed, run directory under results/.
run: $(STAMP)
	$(VENV)/bin/fleet-sim run experiments/warehouse_shift.yaml --out results/warehouse_shift

# The whole test suite, ruff and mypy included.
test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

bench: $(STAMP)
	$(VENV)/bin/python bench/engine_scaling.py

clean:
	rm -rf $(VENV)
