// cbcheck-mpi/cbcheck.c: cbcheck's own main (cbcheck/main.c) compiled again as the function
// fmbd_cbcheck_main of cbcheck-mpi, under cbcheck-mpi's name and with a note in its help: every
// option, report, CSV, plot and rflex file is cbcheck's, by construction. Only the eigensolver
// behind --exact differs (cbcheck-mpi/main.c sets it through fmbd_check_set_exact_engine).
// SPDX-License-Identifier: MIT
#define CBCHECK_PROG "cbcheck-mpi"
#define CBCHECK_USAGE_NOTE "cbcheck-mpi: --exact on MPI processes (SLEPc, MUMPS; man cbcheck-mpi)\n"
#define main fmbd_cbcheck_main
int fmbd_cbcheck_main(int argc, char **argv);
#include "../cbcheck/main.c"
