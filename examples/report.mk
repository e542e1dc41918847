# examples/report.mk: the error-against-run-time reports of the papers' three benchmarks
# (make reports, or one of make report-quadpend, report-slidercrank, report-spatial-slidercrank;
# run by bench/reports.sh under make bench). One driver for all three: examples/report.py, which
# takes the body's make chain from the scene (fmbd-run -M) and runs the family: the reference
# (the full FE model once fmbd-run takes a .fe.h5 body, else an all-modes CB body, labelled as
# such), CB and RFlex at the tolerances 10 %, 1 %, 0.1 %, NM with as many modes as the RFlex
# body. Each writes $(BUILD)/reports/NAME/report.{md,csv,svg} (and report.log: every command).
#
# The reference is the full FE model (the rod's .fe.h5 in the same scene). Its cost (about
# n^1.7 a step in the rod's dofs n: bench/README.md, fmbd-run: full FE bodies) sets each
# benchmark's mesh and length below (QP_ARGS, SC_ARGS, SSC_ARGS; the README of each example says
# why, and compares the mesh's frequencies with the scene's own mesh); RP_ARGS adds to them.
BUILD  ?= build
PYTHON ?= /usr/bin/python3
RP_OUT ?= $(BUILD)/reports
RP_ARGS ?=
# fmbd-run runs side by side (report.py --jobs): the table's CPU times are each run's own
RP_JOBS ?= 2
# quadruple pendulum: tet10 of 15 mm (3045 dofs; the scene's 7.5 mm mesh: 14667), 3 s (the
# trajectories separate near 2.8 s: beyond, the errors measure the chaos, not the model, and
# the FM's cost buys nothing); the window errors over 0..0.994 s (an output instant), where the FM and the CB
# bodies still agree to 1e-8 m: by the separation (2.8 s) chaos has grown any difference 1e4 x
QP_ARGS ?= --size 0.015 --t-end 3 --window-end 0.994
# planar slider-crank: tet10 of 12 mm (6741 dofs; the scene's 6 mm: 34860), the whole 0.5 s
# (the FM: 76 s of CPU with the binary of c3fde74, 272 s before, half of it then at the crank's
# dead point, 0.3..0.4 s; to 0.1 s, the torque's ramp: 12 s, 22 s before); the held RFlex body
# also with Nm 20 and 40 (the tolerance cannot lower its error)
SC_ARGS ?= --size 0.012 --t-end 0.5 --ranges 20,40
# spatial slider-crank: tet10 of 10 mm (4068 dofs; the scene's 4 mm: 37857), 0.054 s; the window
# errors over 0..0.02 s, before the crank's first pass near its dead point (README.md); also CB
# bodies with 0 and 2 fixed-interface modes (the constraint modes: the rod's axial stretch) and
# NM with 9 and 10 modes (the free rod's first axial mode is its 10th)
SSC_ARGS ?= --size 0.01 --t-end 0.054 --window-end 0.02 --cb-nd 0,2 --nm-modes 9,10
export PATH := $(abspath $(BUILD)/bin):$(PATH)
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: reports report-quadpend report-slidercrank report-spatial-slidercrank
reports: report-slidercrank report-spatial-slidercrank report-quadpend

# the quadruple pendulum (first paper, 5.1): node A; chaotic, so also the error over a window
# before two runs (fixed 1e-3 s and 5e-4 s steps) separate (QP_ARGS); the paper's Nd 35, 58, 446.
# Fixed steps for every model, so that all runs share one time grid and the differences are
# the models' (the scene's own variable steps separate the trajectories sooner).
report-quadpend:
	$(PYTHON) examples/report.py examples/quadpend/quadpend.yaml --body rod --output A \
	  --out $(RP_OUT)/quadpend --step 1e-3 --window --paper-nd 35,58,446 $(QP_ARGS) --jobs $(RP_JOBS) $(RP_ARGS)

# the planar slider-crank (first paper, 5.2): node A at the rod's largest stress; Nd 8, 25, 105
report-slidercrank:
	$(PYTHON) examples/report.py examples/slidercrank/slidercrank.yaml --body rod --output A \
	  --out $(RP_OUT)/slidercrank --paper-nd 8,25,105 $(SC_ARGS) --jobs $(RP_JOBS) $(RP_ARGS)

# the spatial slider-crank (second paper, 4.1): the rod's mid-span node. Its crank swings to
# within 0.086 rad of the dead point (at t = 0.025 s), where the mechanism amplifies any
# difference between models (README.md): the window before that pass (SSC_ARGS) is reported too.
report-spatial-slidercrank:
	$(PYTHON) examples/report.py examples/spatial-slidercrank/spatial-slidercrank.yaml \
	  --body rod --output mid --out $(RP_OUT)/spatial-slidercrank --window $(SSC_ARGS) --jobs $(RP_JOBS) $(RP_ARGS)
