# examples/demo.mk: `make demo`, the main job end to end (run by the top Makefile after the
# programs are built):
#
#   examples/geometry/rod.geo --mesh2fe--> rod.fe.h5 --fe2cb--> rod.cb.h5
#        --cbcheck (error estimates, mode selection)--> rod.rflex.h5
#   examples/quadpend/quadpend.yaml + rod.rflex.h5 --fmbd-run--> quadpend.run.h5 + pictures
#
# The rules that make rod.fe.h5, rod.cb.h5 and rod.rflex.h5 come from the scene itself
# (fmbd-run -M, in examples/quadpend/Makefile.inc), so only what the scene needs is built.
# Beside the run, the demo writes the estimator report of the reduced body: the estimates of
# every flexible mode against the exact error of a full eigensolution (CSV + SVG).
# Everything goes to $(BUILD)/demo/.
BUILD  ?= build
PYTHON ?= /usr/bin/python3
QP_OUT := $(BUILD)/demo/quadpend
.DELETE_ON_ERROR:

demo-all: quadpend $(QP_OUT)/rod-estimates.csv
	@echo
	@echo "demo: files in $(QP_OUT)/:"
	@cd $(QP_OUT) && ls -1 *.h5 *.svg *.csv | sed 's/^/  /'
	@$(PYTHON) examples/demo_summary.py $(QP_OUT)

include examples/quadpend/Makefile.inc

# estimates against the exact error for the reduced rod as fe2cb made it (paper Figs 3/13
# and 4/14): lower, second-order and upper estimates of the first 20 flexible modes
$(QP_OUT)/rod-estimates.csv: $(QP_OUT)/rod.cb.h5 $(QP_OUT)/rod.fe.h5 $(BUILD)/bin/cbcheck
	cbcheck $< --fe $(QP_OUT)/rod.fe.h5 --exact --range 20 --csv $@ --plot $(QP_OUT)/rod > $(QP_OUT)/rod-estimates.txt
