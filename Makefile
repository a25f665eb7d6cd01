# The two commands a planner needs: `make run` and `make test`.
# Both create .venv and install fleet_sim into it on first use: '.[dev]' is the test tools,
# pyserial and every extra (sumo, cluster, export; see pyproject.toml), so both have all they need.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: run sweep shift design test bench docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]'
	touch $(STAMP)

STUDY := experiments/warehouse_sizing.yaml
STUDY_OUT := results/warehouse_sizing

# Main job: how many AGVs does the bundled warehouse need? Search the smallest fleet that meets
# the targets with 95 % confidence, from the analytic estimate, replicating each fleet size
# only until it is decided (sequential stopping), warm-up by MSER-5; write the report; print
# the wall time. Resumable: run it again after an interruption and finished runs are kept.
run: $(STAMP)
	@start=$$(date +%s); status=0; \
	$(VENV)/bin/fleet-sim size $(STUDY) --out $(STUDY_OUT) \
	  && $(VENV)/bin/fleet-sim report $(STUDY_OUT) || status=$$?; \
	t=$$(( $$(date +%s) - start )); \
	echo "make run: wall time $$((t / 60)) min $$((t % 60)) s on $$(nproc) cores"; \
	exit $$status

# The same, after sweeping the study's whole grid (every fleet size and demand level, 3
# replications each) for the report's curves; several minutes more.
sweep: $(STAMP)
	@start=$$(date +%s); status=0; \
	$(VENV)/bin/fleet-sim sweep $(STUDY) --out $(STUDY_OUT) \
	  && $(VENV)/bin/fleet-sim size $(STUDY) --out $(STUDY_OUT) \
	  && $(VENV)/bin/fleet-sim report $(STUDY_OUT) || status=$$?; \
	t=$$(( $$(date +%s) - start )); \
	echo "make sweep: wall time $$((t / 60)) min $$((t % 60)) s on $$(nproc) cores"; \
	exit $$status

# One 8-hour shift of the warehouse with 12 AGVs, KPIs printed.
shift: $(STAMP)
	$(VENV)/bin/fleet-sim run experiments/warehouse_shift.yaml --out results/warehouse_shift

# Which system to buy for the warehouse at 108 orders/h: the cheapest design (fleet, chargers,
# charging policy, one-way aisle pairs) that meets the targets, with a guarantee; its report.
design: $(STAMP)
	@start=$$(date +%s); status=0; \
	$(VENV)/bin/fleet-sim optimise experiments/warehouse_design.yaml --out results/warehouse_design \
	  && $(VENV)/bin/fleet-sim report results/warehouse_design || status=$$?; \
	t=$$(( $$(date +%s) - start )); \
	echo "make design: wall time $$((t / 60)) min $$((t % 60)) s on $$(nproc) cores"; \
	exit $$status

# The whole test suite, ruff and mypy included, on every core (pytest-xdist; each test on its
# own tmp_path). --dist worksteal: a worker that runs out of tests takes some of the other's.
test: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n auto --dist worksteal

# The documentation site into site/ (MkDocs, Material theme); --strict: a broken link fails.
# The KPI catalogue and the file-format pages are generated from the code (tools/docs_hook.py).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site
	@echo "make docs: open site/index.html"

bench: $(STAMP)
	$(VENV)/bin/python bench/engine_scaling.py
	$(VENV)/bin/python bench/admission.py
	$(VENV)/bin/python bench/sweep_scaling.py

clean:
	rm -rf $(VENV)
