# The two commands a planner needs: `make run` and `make test`.
# Both create .venv and install fleet_sim into it on first use.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: run shift test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]'
	touch $(STAMP)

STUDY := experiments/warehouse_sizing.yaml
STUDY_OUT := results/warehouse_sizing

# Main job: how many AGVs does the bundled warehouse need? Sweep the fleet-size grid, search the
# smallest fleet that meets the targets with 95 % confidence, write the report. Resumable: run
# it again after an interruption and finished runs are kept.
run: $(STAMP)
	$(VENV)/bin/fleet-sim sweep $(STUDY) --out $(STUDY_OUT)
	$(VENV)/bin/fleet-sim size $(STUDY) --out $(STUDY_OUT)
	$(VENV)/bin/fleet-sim report $(STUDY_OUT)

# One 8-hour shift of the warehouse with 12 AGVs, KPIs printed.
shift: $(STAMP)
	$(VENV)/bin/fleet-sim run experiments/warehouse_shift.yaml --out results/warehouse_shift

# The whole test suite, ruff and mypy included.
test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

bench: $(STAMP)
	$(VENV)/bin/python bench/engine_scaling.py
	$(VENV)/bin/python bench/sweep_scaling.py

clean:
	rm -rf $(VENV)
