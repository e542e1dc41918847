# Makefile: the flexible multibody toolchain (one non-recursive GNU Makefile)
# SPDX-License-Identifier: MIT
#
#   make            build libfmbd.a and the programs into build/
#   make check      install missing Debian packages, build, run every test (SANITIZE=1: ASan+UBSan;
#                   VALGRIND=1: the unit tests under valgrind memcheck)
#   make demo       the main job end to end (examples/)
#   make bench      benchmarks under bench/ (minutes; see bench/README.md)
#   make fuzz       libFuzzer on every file reader, FUZZ_SECONDS (60) each (clang; fuzz/run.sh)
#   make reports    error-against-run-time reports of the papers' benchmarks (examples/report.mk;
#                   also report-quadpend, report-slidercrank, report-spatial-slidercrank)
#   make install    PREFIX=/usr/local DESTDIR=
#   make format     reformat the C/C++ sources with .clang-format (make check checks it)
#   make info       resolved flags;  V=1 full command lines
.DELETE_ON_ERROR:
.SUFFIXES:
.SECONDARY:
SHELL := /bin/bash

VERSION := $(shell cat VERSION)
PREFIX  ?= /usr/local
BINDIR  ?= $(PREFIX)/bin
MANDIR  ?= $(PREFIX)/share/man
PYTHON  ?= /usr/bin/python3
PKG_CONFIG ?= pkg-config

CC  ?= gcc
CXX ?= g++
CFLAGS   ?= -O2 -g
CXXFLAGS ?= -O2 -g

# --- dependencies (each overridable) ------------------------------------------------------
# the serial HDF5 by name: installing PETSc points Debian's hdf5.pc at the MPI build
HDF5_CFLAGS    ?= $(shell $(PKG_CONFIG) --cflags hdf5-serial 2>/dev/null || $(PKG_CONFIG) --cflags hdf5 2>/dev/null || echo -I/usr/include/hdf5/serial)
HDF5_LIBS      ?= $(shell $(PKG_CONFIG) --libs hdf5-serial 2>/dev/null || $(PKG_CONFIG) --libs hdf5 2>/dev/null || echo -L/usr/lib/x86_64-linux-gnu/hdf5/serial -lhdf5)
CHOLMOD_CFLAGS ?= -I/usr/include/suitesparse
CHOLMOD_LIBS   ?= -lklu -lumfpack -lcholmod -lsuitesparseconfig
LAPACK_LIBS    ?= -llapacke -llapack -lblas
ARPACK_LIBS    ?= -larpack
GMSH_LIBS      ?= -lgmsh
YAML_LIBS      ?= -lyaml
CGAL_CXXFLAGS  ?= -std=c++17 -frounding-math -DNDEBUG
CGAL_LIBS      ?= -lmpfr -lgmp -lstdc++

# project flags, kept apart from the user's CFLAGS/CPPFLAGS/LDFLAGS/LDLIBS
FMBD_CFLAGS   := -std=c11 -Wall -Wextra -Wpedantic -Wno-unused-parameter -MMD -MP
FMBD_CPPFLAGS := -D_XOPEN_SOURCE=700 -DFMBD_VERSION='"$(VERSION)"' -Icommon $(HDF5_CFLAGS) $(CHOLMOD_CFLAGS)
# --as-needed: a program records only the shared libraries its own objects call; the programs
# that do not mesh then do not load gmsh and its 130 libraries (0.1 s at every start)
FMBD_LDFLAGS  += -Wl,--as-needed
FMBD_LDLIBS   := $(GMSH_LIBS) $(HDF5_LIBS) -ldeflate $(ARPACK_LIBS) $(CHOLMOD_LIBS) $(LAPACK_LIBS) $(YAML_LIBS) $(CGAL_LIBS) -lm
ifeq ($(FUZZ),1)  # the libFuzzer build (make fuzz): clang, coverage and sanitizers everywhere
  SAN := -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
  FMBD_CFLAGS += $(SAN)
  FMBD_LDFLAGS += -fsanitize=address,undefined
  BUILD ?= build-fuzz
endif
ifeq ($(SANITIZE),1)
  SAN := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
  FMBD_CFLAGS += $(SAN)
  FMBD_LDFLAGS += $(SAN)
  BUILD ?= build-san
endif
BUILD ?= build

ifeq ($(V),1)
  Q :=
  msg = @true
else
  Q := @
  msg = @printf '  %-6s %s\n' $(1) $(2)
endif

# --- sources ------------------------------------------------------------------------------
LIB_C    := $(sort $(wildcard common/*.c))
LIB_CXX  := $(sort $(wildcard common/*.cpp))
LIB_OBJ  := $(LIB_C:%.c=$(BUILD)/%.o) $(LIB_CXX:%.cpp=$(BUILD)/%.o)
LIB      := $(BUILD)/libfmbd.a
PROGRAMS := $(sort $(patsubst %/main.c,%,$(wildcard mesh2fe/main.c fe2cb/main.c cbcheck/main.c gmsolve/main.c fmbd-run/main.c)))
BINS     := $(PROGRAMS:%=$(BUILD)/bin/%)
UNIT_SRC := $(sort $(wildcard tests/unit/t*.c))
UNITS    := $(UNIT_SRC:tests/unit/%.c=$(BUILD)/tests/%)
TOOL_SRC := $(sort $(wildcard tests/tools/*.c))
TOOLS    := $(TOOL_SRC:tests/tools/%.c=$(BUILD)/tools/%)
FUZZ_KINDS  := $(patsubst fuzz/fuzz_%.c,%,$(sort $(wildcard fuzz/fuzz_*.c)))
FUZZ_REPLAY := $(FUZZ_KINDS:%=$(BUILD)/fuzz/replay-%)
FUZZ_SECONDS ?= 60

all: $(BINS)

$(BUILD)/%.o: %.c
	$(call msg,CC,$<)
	@mkdir -p $(@D)
	$(Q)$(CC) $(FMBD_CPPFLAGS) $(CPPFLAGS) $(FMBD_CFLAGS) $(CFLAGS) -c -o $@ $<

# CGAL stays in its own rarely-changing translation unit, mesh2fe/cgal_shim.cpp (~45 s, ~3 GB
# to compile); only mesh2fe links it, so no other program pays for it. It is not instrumented
# under SANITIZE=1 (CGAL under ASan takes ~10 min and 6.5 GB to compile); the C around it is.
$(BUILD)/%.o: %.cpp
	$(call msg,CXX,$<)
	@mkdir -p $(@D)
	$(Q)$(CXX) -Icommon $(CPPFLAGS) $(CGAL_CXXFLAGS) -Wall -Wextra -MMD -MP $(CXXFLAGS) -c -o $@ $<

$(LIB): $(LIB_OBJ)
	$(call msg,AR,$@)
	$(Q)rm -f $@ && ar rcs $@ $^

.SECONDEXPANSION:
$(BUILD)/bin/%: $$(addprefix $(BUILD)/,$$(addsuffix .o,$$(basename $$(wildcard %/*.c)))) $$(addprefix $(BUILD)/,$$(addsuffix .o,$$(basename $$(wildcard %/*.cpp)))) $(LIB)
	$(call msg,LD,$@)
	@mkdir -p $(@D)
	$(Q)$(CC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $(filter %.o,$^) $(LIB) $(FMBD_LDLIBS) $(LDLIBS)

$(BUILD)/tests/%: $(BUILD)/tests/unit/%.o $(LIB)
	$(call msg,LD,$@)
	$(Q)$(CC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $< $(LIB) $(FMBD_LDLIBS) $(LDLIBS)

$(BUILD)/tools/%: $(BUILD)/tests/tools/%.o $(LIB)
	$(call msg,LD,$@)
	@mkdir -p $(@D)
	$(Q)$(CC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $< $(LIB) $(FMBD_LDLIBS) $(LDLIBS)

# fuzz targets: replayers (fuzz/replay.c main, any compiler; make check) and libFuzzer binaries
$(BUILD)/fuzz/replay-%: $(BUILD)/fuzz/fuzz_%.o $(BUILD)/fuzz/replay.o $(LIB)
	$(call msg,LD,$@)
	$(Q)$(CC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $(filter %.o,$^) $(LIB) $(FMBD_LDLIBS) $(LDLIBS)

$(BUILD)/fuzz/fuzz-%: $(BUILD)/fuzz/fuzz_%.o $(LIB)
	$(call msg,LD,$@)
	$(Q)$(CC) -fsanitize=fuzzer $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $< $(LIB) $(FMBD_LDLIBS) $(LDLIBS)

# --- targets ------------------------------------------------------------------------------
.PHONY: all deps check check-build demo bench fuzz fuzz-build install uninstall clean info format reports \
        report-quadpend report-slidercrank report-spatial-slidercrank
deps:
	@bash scripts/install-deps.sh

check-build: $(BINS) $(UNITS) $(TOOLS) $(FUZZ_REPLAY)

check: deps
	@$(MAKE) --no-print-directory check-build
	@BUILD=$(BUILD) PYTHON=$(PYTHON) SANITIZE=$(SANITIZE) VALGRIND=$(VALGRIND) bash tests/run.sh

demo: deps
	@$(MAKE) --no-print-directory all
	@$(MAKE) --no-print-directory -f examples/demo.mk BUILD=$(BUILD) PYTHON=$(PYTHON)

reports report-quadpend report-slidercrank report-spatial-slidercrank: deps
	@$(MAKE) --no-print-directory all
	@$(MAKE) --no-print-directory -f examples/report.mk BUILD=$(BUILD) PYTHON=$(PYTHON) $@

bench: deps
	@$(MAKE) --no-print-directory all $(TOOLS)
	@BUILD=$(BUILD) PYTHON=$(PYTHON) bash bench/run.sh

fuzz-build: $(FUZZ_KINDS:%=$(BUILD)/fuzz/fuzz-%)

fuzz:
	@bash scripts/install-deps.sh && bash scripts/install-deps.sh --fuzz
	@$(MAKE) --no-print-directory all
	@$(MAKE) --no-print-directory FUZZ=1 CC=clang BUILD=build-fuzz fuzz-build
	@FUZZ_BUILD=build-fuzz BUILD=$(BUILD) PYTHON=$(PYTHON) FUZZ_SECONDS=$(FUZZ_SECONDS) bash fuzz/run.sh

install: $(BINS)
	install -d $(DESTDIR)$(BINDIR) $(DESTDIR)$(MANDIR)/man1
	install -m 755 $(BINS) $(DESTDIR)$(BINDIR)
	for p in $(PROGRAMS); do [ -f docs/man/$$p.1 ] && install -m 644 docs/man/$$p.1 $(DESTDIR)$(MANDIR)/man1/ || true; done

uninstall:
	for p in $(PROGRAMS); do rm -f $(DESTDIR)$(BINDIR)/$$p $(DESTDIR)$(MANDIR)/man1/$$p.1; done

clean:
	rm -rf build build-san build-fuzz

format:
	@bash scripts/format-check.sh --fix

info:
	@echo "VERSION       $(VERSION)"
	@echo "PROGRAMS      $(PROGRAMS)"
	@echo "CC            $(CC) $(FMBD_CFLAGS) $(CFLAGS)"
	@echo "CPPFLAGS      $(FMBD_CPPFLAGS) $(CPPFLAGS)"
	@echo "LDLIBS        $(FMBD_LDLIBS) $(LDLIBS)"
	@echo "BUILD         $(BUILD)"

# >>> batch and distributed (issue 13): make batch; fe2cb-mpi (docs/SCALE.md) >>>
.PHONY: batch
batch: deps
	@$(MAKE) --no-print-directory all
	@$(MAKE) --no-print-directory -f examples/batch/Makefile BUILD=$(BUILD) PYTHON=$(PYTHON)
# fe2cb-mpi: the distributed reduction, built only where PETSc and SLEPc are installed (Debian
# libpetsc-real-dev libslepc-real-dev openmpi-bin; make deps installs them). Its objects are
# compiled with mpicc and never enter libfmbd.a: fe2cb and the other programs link no MPI.
MPICC        ?= mpicc
PETSC_CFLAGS ?= $(shell $(PKG_CONFIG) --cflags slepc petsc 2>/dev/null)
PETSC_LIBS   ?= $(shell $(PKG_CONFIG) --libs slepc petsc 2>/dev/null)
MPI_OBJ      := $(BUILD)/mpi/fmbd_slepc.o $(BUILD)/fe2cb-mpi/main.o
CBMPI_OBJ    := $(BUILD)/mpi/fmbd_slepc.o $(BUILD)/cbcheck-mpi/main.o $(BUILD)/cbcheck-mpi/cbcheck.o
.PHONY: mpi
mpi: $(BUILD)/bin/fe2cb-mpi $(BUILD)/bin/cbcheck-mpi
$(BUILD)/cbcheck-mpi/%.o: cbcheck-mpi/%.c
	$(call msg,MPICC,$<)
	@mkdir -p $(@D)
	$(Q)$(MPICC) $(FMBD_CPPFLAGS) -Impi $(PETSC_CFLAGS) $(CPPFLAGS) $(FMBD_CFLAGS) $(CFLAGS) -c -o $@ $<
$(BUILD)/bin/cbcheck-mpi: $(CBMPI_OBJ) $(LIB)
	$(call msg,LD,$@)
	@mkdir -p $(@D)
	$(Q)$(MPICC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $(CBMPI_OBJ) $(LIB) $(PETSC_LIBS) $(FMBD_LDLIBS) $(LDLIBS)
$(BUILD)/mpi/%.o: mpi/%.c
	$(call msg,MPICC,$<)
	@mkdir -p $(@D)
	$(Q)$(MPICC) $(FMBD_CPPFLAGS) -Impi $(PETSC_CFLAGS) $(CPPFLAGS) $(FMBD_CFLAGS) $(CFLAGS) -c -o $@ $<
$(BUILD)/fe2cb-mpi/%.o: fe2cb-mpi/%.c
	$(call msg,MPICC,$<)
	@mkdir -p $(@D)
	$(Q)$(MPICC) $(FMBD_CPPFLAGS) -Impi $(PETSC_CFLAGS) $(CPPFLAGS) $(FMBD_CFLAGS) $(CFLAGS) -c -o $@ $<
$(BUILD)/bin/fe2cb-mpi: $(MPI_OBJ) $(LIB)
	$(call msg,LD,$@)
	@mkdir -p $(@D)
	$(Q)$(MPICC) $(FMBD_LDFLAGS) $(LDFLAGS) -o $@ $(MPI_OBJ) $(LIB) $(PETSC_LIBS) $(FMBD_LDLIBS) $(LDLIBS)
ifneq ($(strip $(PETSC_LIBS)),)
check-build: $(BUILD)/bin/fe2cb-mpi $(BUILD)/bin/cbcheck-mpi
endif
# <<< batch and distributed <<<

-include $(shell find $(BUILD) -name '*.d' -not -path '*/test-tmp/*' -not -path '*/demo/*' -not -path '*/bench/*' 2>/dev/null)
