// cbcheck-mpi/main.c: cbcheck with its --exact eigensolution on several MPI processes (PETSc,
// SLEPc, MUMPS). See docs/SCALE.md and docs/man/cbcheck-mpi.1.
// SPDX-License-Identifier: MIT
//
// Why a program and not a flag of cbcheck: cbcheck links no MPI (it runs everywhere, without
// mpirun); an engine flag would force MPI and PETSc on every build of it. Why not a second
// cbcheck: process 0 runs cbcheck's own main (cbcheck-mpi/cbcheck.c compiles cbcheck/main.c
// again as fmbd_cbcheck_main), so the options, the report, the CSV, the plots and the rflex
// file are cbcheck's by construction. The one difference is the engine behind --exact
// (fmbd_check_set_exact_engine): process 0 sends the other processes the fe file's name and
// the number of eigenvalues, and all of them solve together (fmbd_slepc_exact), each reading
// its own row block of /K and /M. The other processes wait for process 0's orders without
// spinning (a non-blocking broadcast tested every millisecond): cbcheck's serial work on process
// 0 keeps its core.
#include <slepcsys.h>
#include <stdbool.h>
#include <stdint.h>
#include <string.h>
#include <time.h>

#include "fmbd_alloc.h"
#include "fmbd_check.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_slepc.h"

int fmbd_cbcheck_main(int argc, char **argv);  // cbcheck-mpi/cbcheck.c

enum { CMD_QUIT = 0, CMD_EXACT = 1 };

// a broadcast from process 0 (every process calls it): non-blocking, tested every millisecond
// (OpenMPI's blocking collectives poll the CPU at 100 % while they wait)
static void bcast(void *buf, int count, MPI_Datatype type) {
  MPI_Request r;
  int done = 0;
  (void)MPI_Ibcast(buf, count, type, 0, PETSC_COMM_WORLD, &r);
  for (;;) {
    MPI_Test(&r, &done, MPI_STATUS_IGNORE);
    if (done) break;
    struct timespec ms = {0, 1000000};
    nanosleep(&ms, NULL);
  }
}

// the collective solve (every process)
static int solve(const char *fe_path, int64_t nev, bool free_body, double *lambda) {
  fmbd_h5 *f = NULL;
  fmbd_slepc_exact_info info;
  int rc = fmbd_h5_open(fe_path, &f);
  rc = fmbd_slepc_agree(rc);
  if (rc == FMBD_OK) {
    fmbd_err_context(fe_path, "");
    rc = fmbd_slepc_exact(f, nev, free_body, NULL, lambda, &info);
  }
  if (rc == FMBD_OK) {
    fmbd_log(FMBD_LOG_INFO,
             "exact eigenvalues on %d process%s: %lld pairs, shift %.6g, largest residual %.2g, "
             "Sturm count %lld below %.10g; time: read %.3g s, shift pass %.3g s, MUMPS "
             "factorisation %.3g s, Krylov-Schur %.3g s (%lld restarts), Sturm count %.3g s",
             fmbd_slepc_size(), fmbd_slepc_size() > 1 ? "es" : "", (long long)nev, info.sigma,
             info.max_residual, (long long)info.sturm_count, info.sturm_shift, info.t_read,
             info.t_first, info.t_factor, info.t_solve, (long long)info.its, info.t_sturm);
  }
  fmbd_h5_close(&f);
  return rc;
}

// fmbd_check_exact_engine of process 0: the order to the others, then the solve with them
static int engine(void *ctx, const char *fe_path, const fmbd_csr *K, const fmbd_csr *M, int64_t nev,
                  bool free_body, double *lambda) {
  (void)ctx;
  (void)K;  // each process reads its own rows from the file
  (void)M;
  int64_t len = (int64_t)strlen(fe_path) + 1;
  int64_t cmd[4] = {CMD_EXACT, nev, free_body, len};
  bcast(cmd, 4, MPI_INT64_T);
  bcast((void *)fe_path, (int)len, MPI_CHAR);
  return solve(fe_path, nev, free_body, lambda);
}

int main(int argc, char **argv) {
  int rc = fmbd_slepc_init();
  if (rc) {
    fmbd_cli_init("cbcheck-mpi", argc, argv);
    return fmbd_cli_finish(rc);
  }
  if (fmbd_slepc_rank() == 0) {
    fmbd_check_set_exact_engine(engine, NULL);
    rc = fmbd_cbcheck_main(argc, argv);  // cbcheck's exit status, its summary printed
    int64_t cmd[4] = {CMD_QUIT, 0, 0, 0};
    bcast(cmd, 4, MPI_INT64_T);
    fmbd_slepc_finalize();
    return rc;
  }
  // the other processes: errors of their own only (process 0 reports), orders from process 0
  fmbd_cli_init("cbcheck-mpi", argc, argv);
  fmbd_cli_set_verbosity(1, 0);
  for (;;) {
    int64_t cmd[4] = {0, 0, 0, 0};
    bcast(cmd, 4, MPI_INT64_T);
    if (cmd[0] != CMD_EXACT) break;
    char *path = fmbd_malloc((size_t)cmd[3]);
    double *lambda = fmbd_malloc((size_t)cmd[1] * sizeof(double));
    if (!path || !lambda) {
      fmbd_log(FMBD_LOG_ERROR, "out of memory");
      MPI_Abort(PETSC_COMM_WORLD, 1);
    }
    bcast(path, (int)cmd[3], MPI_CHAR);
    (void)solve(path, cmd[1], cmd[2] != 0, lambda);  // the code is process 0's to report
    fmbd_free(path);
    fmbd_free(lambda);
  }
  fmbd_slepc_finalize();
  return 0;
}
