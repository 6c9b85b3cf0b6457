# accal developer tasks.  Every target installs what it needs into .venv first.
PYTHON ?= python3
VENV   := .venv
# one BLAS thread per process, as the accal CLI sets for itself (accal._runtime): the
# test and benchmark processes call the library directly, and on 2 cores shared with
# forked workers a threaded BLAS spends its time waiting (measured: 30-100x slower)
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out
FUZZ_MINUTES ?= 10
# pytest processes (pytest-xdist): one per core; TEST_WORKERS=0 runs in one process
TEST_WORKERS ?= auto

.PHONY: install run demo test test-all lint bench bench-readers bench-archive bench-demod-year bench-closure closure-detection coupling-scan-null fuzz-cli mc-sigma mc-sigma-indep mc-sigma-demod mc-reference bench-reference compare-outputs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

## run: the main job on the bundled real sample files (GRACE 2003, GRACE-FO 2023)
run: $(STAMP)
	$(BIN)/accal grace-bias data/samples/ACC1B_2003-09-14_A_00.asc data/samples/ACC1B_2003-09-14_B_00.asc \
	    data/samples/ACT1B_2023-06-01_C_04.txt data/samples/ACT1B_2023-06-01_D_04.txt \
	    --method both --format csv --out $(OUT)/grace-bias
	$(BIN)/accal simulate grace --date 2005-01-01 --satellite A --out $(OUT)/sim/ACC1B_2005-01-01_A_sim.asc
	$(BIN)/accal grace-bias $(OUT)/sim/ACC1B_2005-01-01_A_sim.asc --method both --scale tn02 \
	    --format csv --out $(OUT)/grace-bias
	@echo "--- $(OUT)/grace-bias/bias_drift.csv (accal table $(OUT)/grace-bias)"
	@$(BIN)/accal table $(OUT)/grace-bias

## demo: close the loop on measured data (real Swarm-A storm day with injected effects), then the
##       CLI on the real day and on a simulated rotating-platform run with an undeclared coupling
demo: $(STAMP)
	$(BIN)/python benchmarks/closure_demo.py --out $(OUT)/demo
	$(BIN)/accal grace-bias data/samples/SW_A_ACCACAL_20240511_a_cal_x.csv.gz --column x=a_cal_x \
	    --close-loop --plots --force --format csv --out $(OUT)/demo/swarm-cli
	$(BIN)/accal simulate gap --days 0.5 --tau 600 --mask 200 --temperature-coupling 1e-9 \
	    --out $(OUT)/demo/gap/run.parquet
	$(BIN)/accal demod $(OUT)/demo/gap/run.parquet --tau 600 --mask 200 --close-loop --plots \
	    --out $(OUT)/demo/gap/res
	@echo "--- reports: $(OUT)/demo/closure.md, $(OUT)/demo/swarm-cli/closure.md, $(OUT)/demo/gap/res/closure.md"
	@echo "--- plots:   $(OUT)/demo/*.png, $(OUT)/demo/swarm-cli/*.png, $(OUT)/demo/gap/res/*.png"

## test: the full default test suite (what CI runs)
test: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow" -n $(TEST_WORKERS)

## compare-outputs: the outputs of make run, make demo and the README walk-through with
##       accal of git revision BASE and of the working tree, file by file (issue 21)
BASE ?= HEAD
compare-outputs: $(STAMP)
	$(BIN)/python benchmarks/compare_outputs.py $(BASE) --out $(OUT)/compare

## test-all: also the long Monte-Carlo studies
test-all: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)

lint: $(STAMP)
	$(BIN)/ruff check src tests properties benchmarks
	$(BIN)/ruff format --check src tests properties benchmarks

## bench: end-to-end and estimator benchmarks on a 1 Hz, 86,400-row day
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_grace_bias.py

## mc-sigma: Monte-Carlo study of the bias/drift sigmas, day and pooled (~1 min)
mc-sigma: $(STAMP)
	$(BIN)/python benchmarks/mc_sigma.py

## mc-sigma-indep: the same on the tests' realistic days with a reference (~6 min)
mc-sigma-indep: $(STAMP)
	$(BIN)/python benchmarks/mc_sigma_indep.py

## mc-sigma-demod: Monte-Carlo check of demod's per-period sigma from the data (issue 20; ~3 min on one core)
mc-sigma-demod: $(STAMP)
	$(BIN)/python benchmarks/mc_sigma_demod.py

## mc-reference: Monte-Carlo of the reference fit (issue 22): scales, bias and cross-talk test on 30-day 1 Hz arcs (~25 min on 2 cores)
mc-reference: $(STAMP)
	$(BIN)/python benchmarks/mc_reference.py

## bench-reference: a 30-day 1 Hz arc through the CLI, --scale fit-matrix --bias-basis spline:6h --arc 30d: time and peak RSS vs the wavelet baseline (issue 22)
bench-reference: $(STAMP)
	$(BIN)/python benchmarks/bench_reference.py

bench-readers: $(STAMP)
	$(BIN)/python benchmarks/bench_readers.py

## bench-demod-year: a simulated year (and 30 days) of 1 Hz data through accal demod: wall time, peak RSS (minutes, ~1 GB temp)
bench-demod-year: $(STAMP)
	$(BIN)/python benchmarks/bench_demod_year.py

## bench-closure: wall time, CPU time and peak RSS of grace-bias/demod --close-loop vs the plain run on
##                1 Hz days, 3 repeats (targets: <= 15 s and 600 MB per GRACE day, <= 5 s per demod
##                day); QUICK=1: one repeat, two days (~1 min)
bench-closure: $(STAMP)
	$(BIN)/python benchmarks/bench_closure.py $(if $(QUICK),--quick) --out $(OUT)/bench-closure

## closure-detection: false detections on clean days (GRACE A/B, GRACE-FO C/D, noise models, storms,
##                    platform), detection, z-scores and bias/drift errors per injected effect and
##                    size, the real Swarm day (~45 min on 2 idle cores); QUICK=1: a few cases (~2 min)
closure-detection: $(STAMP)
	$(BIN)/python benchmarks/closure_detection.py $(if $(QUICK),--quick) --out $(OUT)/closure-detection

## coupling-scan-null: false-alarm rate of the platform coupling scan (every sample lag vs the
##                     31-lag grid) on clean platform runs, two noises, two temperatures
##                     (~13 min on 2 cores; RUNS=100 per cell)
coupling-scan-null: $(STAMP)
	$(BIN)/python benchmarks/coupling_scan_null.py --runs $(or $(RUNS),100) --out $(OUT)/coupling-scan-null

## fuzz-cli: black-box mutation fuzzing of the CLI on mutated sample files (issue 23): cases,
##           outcomes by kind, every BAD case with its reproduction, peak RSS; FUZZ_MINUTES=10
fuzz-cli: $(STAMP)
	$(BIN)/python benchmarks/fuzz_cli.py --minutes $(FUZZ_MINUTES) --out $(OUT)/fuzz-cli

## bench-archive: 200 synthetic 1 Hz days, 1 and 2 workers, vs raw pyarrow parse (~4 GB in /tmp)
bench-archive: $(STAMP)
	$(BIN)/python benchmarks/bench_archive.py

clean:
	rm -rf $(OUT) .pytest_cache .hypothesis .benchmarks build dist
