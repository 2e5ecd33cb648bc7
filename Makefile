# Set-up and main entry points. `make demo` runs the main job, `make test` the test suite.
# Both create (once) and reuse .venv; the installed command is .venv/bin/breastplan.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO   := out/demo
TOUR   := out/tour
export PATH := $(PATH):/sbin:/usr/sbin

.PHONY: demo tour test bench screenshot libusb chromium clean

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory libusb
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV) || { \
	  echo "python3 cannot create a virtual environment: install python3-venv (apt-get install python3-venv) and run make again." >&2; exit 1; }
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[test]'
	@# pip compiles the packages it installs, not this editable source; where PYTHONDONTWRITEBYTECODE is set,
	@# every command would otherwise compile breastplan's modules again.
	$(BIN)/python -m compileall -q -x '/(\.venv|\.git|out)/' .
	@touch $@

# open3d cannot be imported without the system library libusb-1.0-0.
libusb:
	@if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing the system library libusb-1.0-0 (needed by open3d)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	  else \
	    echo "breastplan needs the system library libusb-1.0-0: install it (sudo apt-get install libusb-1.0-0) and run make again." >&2; exit 1; \
	  fi; \
	fi

# The browser tests (tests/browser.py) drive Debian's headless Chromium through chromedriver.
chromium:
	@if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing chromium and chromium-driver (needed by the browser tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null; \
	  else \
	    echo "the browser tests need Debian's chromium and chromium-driver: install them (sudo apt-get install chromium chromium-driver) and run make again." >&2; exit 1; \
	  fi; \
	fi

demo: $(STAMP)
	$(BIN)/breastplan plan --out $(DEMO)
	@echo "open $(abspath $(DEMO))/report.html in a browser"

# The stages one by one, as docs/tour.md's tour runs them.
tour: $(STAMP)
	$(BIN)/breastplan synth --db S --out $(TOUR)/database-S --ply
	$(BIN)/breastplan deform $(TOUR)/database-S/S-shape1-00.ply --kind ptosis --param b0=1.125 --param b1=0.25 --out $(TOUR)/S-shape1-00-ptosis.ply
	$(BIN)/breastplan deform $(TOUR)/database-S/S-shape1-00.ply --kind turn --param c0=1.1 --param c1=0.5 --out $(TOUR)/S-shape1-00-turn.ply
	$(BIN)/breastplan ingest examples/sample.mcap --side left --out $(TOUR)/case-left
	$(BIN)/breastplan ingest examples/sample.mcap --side right --out $(TOUR)/case-right
	$(BIN)/breastplan fit $(TOUR)/case-left
	$(BIN)/breastplan fit $(TOUR)/case-right
	$(BIN)/breastplan fit $(TOUR)/S-shape1-00-ptosis.ply --out $(TOUR)/fit-S-shape1-00-ptosis
	$(BIN)/breastplan deform $(TOUR)/database-S/S-shape1-00.ply --kind ptosis --degree 5.5 --out $(TOUR)/S-shape1-00-ptosis-5.5.ply
	$(BIN)/breastplan deform $(TOUR)/database-S/S-shape1-00.ply --kind ptosis --degree 5.5 --method learnt --out $(TOUR)/S-shape1-00-ptosis-5.5-learnt.ply
	$(BIN)/breastplan scan-synth --body makehuman --cup 0.8 --firmness 0.3 --modifier asymmetry=0.4 --pose arms-down --pitch 8 --yaw -6 --frames 8 --out $(TOUR)/patient.mcap --truth $(TOUR)/patient-truth.npz
	$(BIN)/breastplan ingest $(TOUR)/patient.mcap --side left --out $(TOUR)/patient-left
	$(BIN)/breastplan ingest $(TOUR)/patient.mcap --side right --out $(TOUR)/patient-right
	$(BIN)/breastplan fit $(TOUR)/patient-left
	$(BIN)/breastplan evaluate --study all --quick --out $(TOUR)/study
	@echo "tour written to $(abspath $(TOUR))"

test: $(STAMP) chromium
	$(BIN)/python -m pytest -q

# The README's picture of the report: the sample patient's plan in headless Chromium, front view.
screenshot: $(STAMP) chromium
	BREASTPLAN_SCREENSHOT=$(abspath docs/report.png) $(BIN)/python -m pytest -q -n 0 \
	    tests/test_plan.py -k "slider_and_views"

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_cli.py
	$(BIN)/python benchmarks/bench_model.py
	$(BIN)/python benchmarks/bench_lattice.py
	$(BIN)/python benchmarks/bench_ingest.py
	$(BIN)/python benchmarks/bench_wrapped.py
	$(BIN)/python benchmarks/bench_fit.py
	$(BIN)/python benchmarks/bench_learn.py
	$(BIN)/python benchmarks/bench_statistical.py
	$(BIN)/python benchmarks/bench_realistic.py
	$(BIN)/python benchmarks/bench_volume_ceiling.py
	$(BIN)/python benchmarks/bench_low_mounds.py
	$(BIN)/python benchmarks/bench_repeatability.py
	$(BIN)/python benchmarks/bench_volume_repeat.py
	$(BIN)/python benchmarks/bench_follow_up.py
	$(BIN)/python benchmarks/bench_patient_agreement.py
	$(BIN)/python benchmarks/bench_folds.py
	$(BIN)/python benchmarks/bench_symmetry.py
	$(BIN)/python benchmarks/bench_distance.py
	$(BIN)/python benchmarks/bench_operations.py
	$(BIN)/python benchmarks/bench_learnt_operation.py
	$(BIN)/python benchmarks/bench_shifted_pairs.py
	$(BIN)/python benchmarks/bench_refusal.py
	$(BIN)/python benchmarks/bench_plan.py
	$(BIN)/python benchmarks/bench_batch.py

clean:
	rm -rf $(VENV) out
