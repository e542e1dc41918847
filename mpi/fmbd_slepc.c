// mpi/fmbd_slepc.c: the distributed Craig-Bampton reduction (see fmbd_slepc.h)
// SPDX-License-Identifier: MIT
//
// References: SLEPc Users Manual (Roman et al., 3.18), sections 2.5 (Krylov-Schur), 3.4
// (shift-and-invert spectral transformation) and 3.4.5 (its linear solves: KSPPREONLY with a
// direct factorisation); PETSc Users Manual, MATSOLVERMUMPS (Cholesky of AIJ matrices,
// MatGetInertia with ICNTL(13) = 1 on more than one process); MUMPS 5.5 Users' guide, ICNTL(13).
#include "fmbd_slepc.h"

#include <limits.h>
#include <math.h>
#include <slepceps.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

// a PETSc/SLEPc call inside a function with rc and a done: label
#define PCALL(call)                                                                          \
  do {                                                                                       \
    PetscErrorCode ierr_ = (call);                                                           \
    if (ierr_)                                                                               \
      FMBD_GFAIL(FMBD_ERR_EXTERNAL, "PETSc/SLEPc: %s failed (error %d)", #call, (int)ierr_); \
  } while (0)

int fmbd_slepc_init(void) {
  PetscErrorCode ierr = SlepcInitialize(NULL, NULL, NULL, NULL);
  if (ierr) FMBD_FAIL(FMBD_ERR_EXTERNAL, "SlepcInitialize failed (error %d)", (int)ierr);
  return FMBD_OK;
}

void fmbd_slepc_finalize(void) {
  (void)SlepcFinalize();
}

int fmbd_slepc_rank(void) {
  int r = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &r);
  return r;
}

int fmbd_slepc_size(void) {
  int s = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &s);
  return s;
}

// error codes are negative: the "worst" is the smallest. Process 0 reports: when it did not
// fail itself, the first process that failed sends it its message
int fmbd_slepc_agree(int rc) {
  int all = rc;
  (void)MPI_Allreduce(&rc, &all, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
  if (all == FMBD_OK) return all;
  const int rank = fmbd_slepc_rank();
  int me = rc != FMBD_OK ? rank : fmbd_slepc_size(), first = me;
  (void)MPI_Allreduce(&me, &first, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
  if (first > 0) {
    struct {
      int code;
      char msg[1024], file[512], where[512];
    } m;
    memset(&m, 0, sizeof m);
    if (rank == first) {
      const fmbd_err *e = fmbd_err_get();
      m.code = e->code;
      snprintf(m.msg, sizeof m.msg, "%s", e->msg);
      snprintf(m.file, sizeof m.file, "%s", e->file);
      snprintf(m.where, sizeof m.where, "%s", e->where);
      (void)MPI_Send(&m, (int)sizeof m, MPI_BYTE, 0, 7, PETSC_COMM_WORLD);
    } else if (rank == 0) {
      (void)MPI_Recv(&m, (int)sizeof m, MPI_BYTE, first, 7, PETSC_COMM_WORLD, MPI_STATUS_IGNORE);
      fmbd_err_context(m.file, m.where);
      (void)fmbd_err_set(m.code ? m.code : all, __FILE__, __LINE__, __func__, "process %d: %s",
                         first, m.msg);
    }
  }
  return all;
}

void fmbd_slepc_peak_mb(double *mine, double *largest) {
  double kb = -1.0;
  FILE *f = fopen("/proc/self/status", "r");
  if (f) {
    char line[256];
    while (fgets(line, sizeof line, f)) {
      if (!strncmp(line, "VmHWM:", 6)) kb = atof(line + 6);
    }
    fclose(f);
  }
  *mine = kb / 1024.0;
  MPI_Allreduce(mine, largest, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
}

void fmbd_slepc_defaults(fmbd_slepc_opts *o) {
  memset(o, 0, sizeof *o);
  o->nmodes = 20;
  o->tol = 1e-12;
  o->resid_tol = 1e-6;
  o->sturm = true;
  o->rigid_rtol = 1e-6;
  o->sym_rtol = 1e-10;
}

static double tmax(double t) {
  double m = t;
  MPI_Allreduce(&t, &m, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return m;
}

// a row block of A(rows, cols) as a PETSc MPIAIJ matrix (nloc local rows, ncols_local local
// columns of the square or rectangular global matrix)
static int to_petsc(const fmbd_csr *blk, PetscInt nloc, PetscInt nglob_rows, PetscInt nloc_cols,
                    PetscInt nglob_cols, Mat *out) {
  int rc = FMBD_OK;
  PetscInt *ip = NULL, *jp = NULL;
  FMBD_GALLOC(ip = fmbd_malloc((size_t)(nloc + 1) * sizeof(PetscInt)));
  int64_t nnz = blk->indptr[blk->nrows];
  FMBD_GALLOC(jp = fmbd_malloc((size_t)(nnz ? nnz : 1) * sizeof(PetscInt)));
  FMBD_GCHECK(nnz < PETSC_MAX_INT && nglob_cols < PETSC_MAX_INT, FMBD_ERR_VALUE,
              "%lld entries in one process's rows: beyond this PETSc's 32-bit indices (use a "
              "PETSc built with --with-64-bit-indices, Debian libpetsc64-real-dev)",
              (long long)nnz);
  for (PetscInt i = 0; i <= nloc; i++) ip[i] = (PetscInt)blk->indptr[i];
  for (int64_t p = 0; p < nnz; p++) jp[p] = (PetscInt)blk->indices[p];
  // the arrays are copied by PETSc
  PCALL(MatCreateMPIAIJWithArrays(PETSC_COMM_WORLD, nloc, nloc_cols, nglob_rows, nglob_cols, ip, jp,
                                  blk->data, out));
done:
  fmbd_free(ip);
  fmbd_free(jp);
  return rc;
}

// gather a distributed vector on process 0 into dst (n doubles there; ignored elsewhere)
static int gather0(VecScatter sc, Vec x, Vec x0, double *dst) {
  int rc = FMBD_OK;
  PCALL(VecScatterBegin(sc, x, x0, INSERT_VALUES, SCATTER_FORWARD));
  PCALL(VecScatterEnd(sc, x, x0, INSERT_VALUES, SCATTER_FORWARD));
  if (fmbd_slepc_rank() == 0) {
    const PetscScalar *a = NULL;
    PetscInt n = 0;
    PCALL(VecGetLocalSize(x0, &n));
    PCALL(VecGetArrayRead(x0, &a));
    memcpy(dst, a, (size_t)n * sizeof(double));
    PCALL(VecRestoreArrayRead(x0, &a));
  }
done:
  return rc;
}

// local column j of a row block (nloc x nb CSR) into x's local part, times s
static int set_column(const fmbd_csr *blk, int64_t j, double s, Vec x) {
  int rc = FMBD_OK;
  PetscScalar *a = NULL;
  PCALL(VecSet(x, 0.0));
  PCALL(VecGetArray(x, &a));
  for (int64_t i = 0; i < blk->nrows; i++) {
    for (int64_t p = blk->indptr[i]; p < blk->indptr[i + 1]; p++) {
      if (blk->indices[p] == j) a[i] += s * blk->data[p];
    }
  }
  PCALL(VecRestoreArray(x, &a));
done:
  return rc;
}

// the Sturm count: eigenvalues of Ks x = kappa Ms x below s, by the inertia of an LDL' factor
// of Ks - s Ms (MUMPS, symmetric indefinite; Sylvester's law of inertia)
static int sturm_count(Mat Ks, Mat Ms, double s, int64_t *count) {
  int rc = FMBD_OK;
  Mat A = NULL, F = NULL;
  PetscInt nneg = 0, nzero = 0, npos = 0;
  MatFactorInfo info;
  PCALL(MatDuplicate(Ks, MAT_COPY_VALUES, &A));
  PCALL(MatAXPY(A, -s, Ms, DIFFERENT_NONZERO_PATTERN));
  PCALL(MatSetOption(A, MAT_SYMMETRIC, PETSC_TRUE));
  PCALL(MatGetFactor(A, MATSOLVERMUMPS, MAT_FACTOR_CHOLESKY, &F));
  PCALL(MatMumpsSetIcntl(F, 13, 1));  // inertia of the whole matrix on several processes
  PCALL(MatMumpsSetIcntl(F, 24, 1));  // null pivots detected (counted as zero eigenvalues)
  PCALL(MatFactorInfoInitialize(&info));
  PCALL(MatCholeskyFactorSymbolic(F, A, NULL, &info));  // MUMPS orders it itself
  PCALL(MatCholeskyFactorNumeric(F, A, &info));
  PCALL(MatGetInertia(F, &nneg, &nzero, &npos));
  *count = nneg;
done:
  MatDestroy(&F);
  MatDestroy(&A);
  return rc;
}

typedef struct idx_val {
  double v;
  int64_t i;
} idx_val;
static int cmp_idx_val(const void *a, const void *b) {
  double x = ((const idx_val *)a)->v, y = ((const idx_val *)b)->v;
  return (x > y) - (x < y);
}

// rows of every process's block (in rank order) stacked on process 0 into *out0 (NULL
// elsewhere): the row blocks of a matrix whose rows are split over the processes in order
static int gather_rows0(const fmbd_csr *loc, fmbd_csr **out0) {
  int rc = FMBD_OK;
  const int rank = fmbd_slepc_rank(), np = fmbd_slepc_size();
  int *cnt = NULL, *disp = NULL, *ncnt = NULL, *ndisp = NULL, *all = NULL;
  int64_t *len = NULL, *rowlen = NULL;
  fmbd_csr *A = NULL;
  int64_t nnz = loc->indptr[loc->nrows];
  FMBD_GCHECK(loc->nrows < INT_MAX && nnz < INT_MAX, FMBD_ERR_VALUE,
              "%lld rows, %lld entries in one process's block: beyond MPI's int counts",
              (long long)loc->nrows, (long long)nnz);
  int my[2] = {(int)loc->nrows, (int)nnz};
  FMBD_GALLOC(all = fmbd_malloc((size_t)(2 * np) * sizeof(int)));
  (void)MPI_Gather(my, 2, MPI_INT, all, 2, MPI_INT, 0, PETSC_COMM_WORLD);
  FMBD_GALLOC(rowlen = fmbd_malloc((size_t)(loc->nrows + 1) * sizeof(int64_t)));
  for (int64_t i = 0; i < loc->nrows; i++) rowlen[i] = loc->indptr[i + 1] - loc->indptr[i];
  if (rank == 0) {
    FMBD_GALLOC(cnt = fmbd_calloc((size_t)np, sizeof(int)));
    FMBD_GALLOC(disp = fmbd_calloc((size_t)np, sizeof(int)));
    FMBD_GALLOC(ncnt = fmbd_calloc((size_t)np, sizeof(int)));
    FMBD_GALLOC(ndisp = fmbd_calloc((size_t)np, sizeof(int)));
    int64_t rows = 0, tot = 0;
    for (int q = 0; q < np; q++) {
      cnt[q] = all[2 * q];
      ncnt[q] = all[2 * q + 1];
      disp[q] = (int)rows;
      ndisp[q] = (int)tot;
      rows += cnt[q];
      tot += ncnt[q];
    }
    FMBD_GCHECK(rows < INT_MAX && tot < INT_MAX, FMBD_ERR_VALUE,
                "%lld rows, %lld entries gathered: beyond MPI's int counts", (long long)rows,
                (long long)tot);
    FMBD_GCALL(fmbd_csr_create(rows, loc->ncols, tot, &A));
    FMBD_GALLOC(len = fmbd_malloc((size_t)(rows + 1) * sizeof(int64_t)));
  }
  (void)MPI_Gatherv(rowlen, my[0], MPI_INT64_T, len, cnt, disp, MPI_INT64_T, 0, PETSC_COMM_WORLD);
  (void)MPI_Gatherv(loc->indices, my[1], MPI_INT64_T, A ? A->indices : NULL, ncnt, ndisp,
                    MPI_INT64_T, 0, PETSC_COMM_WORLD);
  (void)MPI_Gatherv(loc->data, my[1], MPI_DOUBLE, A ? A->data : NULL, ncnt, ndisp, MPI_DOUBLE, 0,
                    PETSC_COMM_WORLD);
  if (rank == 0) {
    A->indptr[0] = 0;
    for (int64_t i = 0; i < A->nrows; i++) A->indptr[i + 1] = A->indptr[i] + len[i];
    *out0 = A;
    A = NULL;
  }
done:
  fmbd_free(all);
  fmbd_free(cnt);
  fmbd_free(disp);
  fmbd_free(ncnt);
  fmbd_free(ndisp);
  fmbd_free(len);
  fmbd_free(rowlen);
  fmbd_csr_destroy(&A);
  return rc;
}

// the checks fmbd_cb_check_body makes on the whole body, on this process's rows r0.. of K and
// M (row blocks with the whole matrix's columns): a positive diagonal of K, a non-negative one
// of M (collective: the same code on every process)
static int check_rows(const fmbd_csr *K, const fmbd_csr *M, int64_t r0) {
  int rc = FMBD_OK;
  for (int64_t i = 0; i < K->nrows; i++) {
    double k = fmbd_csr_get(K, i, r0 + i), m = fmbd_csr_get(M, i, r0 + i);
    if (!(k > 0.0)) {
      fmbd_err_context(NULL, "/K");
      FMBD_GFAIL(FMBD_ERR_VALUE,
                 "diagonal entry %.6g at dof %lld (a stiffness matrix has a positive diagonal)", k,
                 (long long)(r0 + i));
    }
    if (m < 0.0) {
      fmbd_err_context(NULL, "/M");
      FMBD_GFAIL(FMBD_ERR_VALUE, "diagonal entry %.6g at dof %lld (negative mass)", m,
                 (long long)(r0 + i));
    }
  }
done:
  return rc;
}

// A symmetric to rtol max|A| (fmbd_cb_check_body's test, on the distributed matrix)
static int check_symmetric(Mat A, const char *name, double rtol) {
  int rc = FMBD_OK;
  PetscBool sym = PETSC_FALSE;
  PetscReal amax = 0;
  PCALL(MatNorm(A, NORM_MAX, &amax));
  PCALL(MatIsSymmetric(A, rtol * amax, &sym));
  if (!sym) {
    fmbd_err_context(NULL, name);
    FMBD_GFAIL(FMBD_ERR_VALUE, "matrix is not symmetric (|A(i,j) - A(j,i)| > %.0e max|A|)", rtol);
  }
done:
  return rc;
}

// SLEPc Krylov-Schur for the lowest `want` pairs of A x = lambda B x, shift-and-invert at
// `target` (below every wanted eigenvalue), the factor of A - target B by MUMPS' Cholesky; set
// up (factored) on return, *ksp/*pc its linear solver
static int eps_setup(Mat A, Mat B, double target, int64_t want, double tol, EPS *eps, KSP *ksp,
                     PC *pc) {
  int rc = FMBD_OK;
  ST st = NULL;
  PCALL(EPSCreate(PETSC_COMM_WORLD, eps));
  PCALL(EPSSetOperators(*eps, A, B));
  PCALL(EPSSetProblemType(*eps, EPS_GHEP));
  PCALL(EPSSetType(*eps, EPSKRYLOVSCHUR));
  PCALL(EPSSetWhichEigenpairs(*eps, EPS_TARGET_MAGNITUDE));
  PCALL(EPSSetTarget(*eps, target));
  PCALL(EPSSetDimensions(*eps, (PetscInt)want, PETSC_DEFAULT, PETSC_DEFAULT));
  PCALL(EPSSetTolerances(*eps, tol, 1000));
  PCALL(EPSGetST(*eps, &st));
  PCALL(STSetType(st, STSINVERT));
  PCALL(STGetKSP(st, ksp));
  PCALL(KSPSetType(*ksp, KSPPREONLY));
  PCALL(KSPGetPC(*ksp, pc));
  PCALL(PCSetType(*pc, PCCHOLESKY));
  PCALL(PCFactorSetMatSolverType(*pc, MATSOLVERMUMPS));
  PCALL(EPSSetFromOptions(*eps));  // PETSC_OPTIONS may change any of it (-eps_view etc.)
  PCALL(EPSSetUp(*eps));           // the MUMPS factorisation (analysis + numeric)
done:
  return rc;
}

// MUMPS' figures of the factor behind pc into t
static int factor_figures(PC pc, fmbd_slepc_timing *t) {
  int rc = FMBD_OK;
  Mat F = NULL;
  PetscInt entries = 0, mb_max = 0, mb_sum = 0;
  PetscReal flops = 0;
  PCALL(PCFactorGetMatrix(pc, &F));
  PCALL(MatMumpsGetInfog(F, 29, &entries));
  PCALL(MatMumpsGetInfog(F, 21, &mb_max));
  PCALL(MatMumpsGetInfog(F, 22, &mb_sum));
  PCALL(MatMumpsGetRinfog(F, 3, &flops));
  // INFOG(29) < 0: -entries in millions (MUMPS guide, overflow of 32-bit integers)
  t->factor_entries = entries >= 0 ? (double)entries : -1e6 * (double)entries;
  t->factor_flops = flops;
  t->factor_mb_max = (double)mb_max;
  t->factor_mb_sum = (double)mb_sum;
done:
  return rc;
}

// the converged eigenvalues of eps, ascending, with their SLEPc indices (*order, *lam: want)
static int sorted_values(EPS eps, int64_t want, idx_val **order, double **lam) {
  int rc = FMBD_OK;
  FMBD_GALLOC(*order = fmbd_malloc((size_t)want * sizeof **order));
  FMBD_GALLOC(*lam = fmbd_malloc((size_t)want * sizeof(double)));
  for (int64_t k = 0; k < want; k++) {
    PetscScalar kr = 0, ki = 0;
    PCALL(EPSGetEigenvalue(eps, (PetscInt)k, &kr, &ki));
    (*order)[k] = (idx_val){kr, k};
  }
  qsort(*order, (size_t)want, sizeof **order, cmp_idx_val);
  for (int64_t k = 0; k < want; k++) (*lam)[k] = (*order)[k].v;
done:
  return rc;
}

// relative residual ||A x - lam B x|| / max(||A x||, max(|lam|, |scale|) ||B x||) (fmbd_eig's;
// scale keeps rigid-body pairs, A x ~ 0, meaningful); y, z: work vectors
static int residual(Mat A, Mat B, Vec x, double lam, double scale, Vec y, Vec z, double *r) {
  int rc = FMBD_OK;
  PetscReal nk = 0, nm = 0, nr = 0;
  PCALL(MatMult(A, x, y));
  PCALL(MatMult(B, x, z));
  PCALL(VecNorm(y, NORM_2, &nk));
  PCALL(VecNorm(z, NORM_2, &nm));
  PCALL(VecAXPY(y, -lam, z));
  PCALL(VecNorm(y, NORM_2, &nr));
  *r = nr / fmax(nk, fmax(fabs(lam), fabs(scale)) * nm);
done:
  return rc;
}

// this process's blocks of the reduction from rows g0 .. g1-1 of the file's K and M (see
// fmbd_slepc_cb_reduce): interior rows rstart .. rstart+nloc-1 against the interior (Ksl, Msl)
// and the boundary (Kcl, Mcl) columns, its boundary rows against the boundary (Kbl, Mbl). Local:
// no collective call
static int read_blocks(fmbd_h5 *f, const fmbd_cb *cb, int64_t g0, int64_t g1, int64_t nloc,
                       int64_t rstart, fmbd_csr **Ksl, fmbd_csr **Msl, fmbd_csr **Kcl,
                       fmbd_csr **Mcl, fmbd_csr **Kbl, fmbd_csr **Mbl) {
  int rc = FMBD_OK;
  fmbd_csr *Kr = NULL, *Mr = NULL;
  int64_t *lrows = NULL;
  const int64_t n = cb->ndof, ns = cb->ns, nb = cb->nb;
  FMBD_GCALL(fmbd_h5_read_csr_rows(f, "/K", g0, g1, NULL, &Kr));
  FMBD_GCALL(fmbd_h5_read_csr_rows(f, "/M", g0, g1, NULL, &Mr));
  FMBD_GCHECK(Kr->ncols == n && Mr->ncols == n, FMBD_ERR_FORMAT,
              "/K or /M has %lld or %lld columns, /dofs %lld rows", (long long)Kr->ncols,
              (long long)Mr->ncols, (long long)n);
  FMBD_GCALL(check_rows(Kr, Mr, g0));
  int64_t b0 = 0, b1 = 0;  // the boundary dofs in g0 .. g1-1: boundary[b0 .. b1-1]
  while (b0 < nb && cb->boundary[b0] < g0) b0++;
  for (b1 = b0; b1 < nb && cb->boundary[b1] < g1;) b1++;
  int64_t nl = nloc > b1 - b0 ? nloc : b1 - b0;
  FMBD_GALLOC(lrows = fmbd_malloc((size_t)(nl ? nl : 1) * sizeof(int64_t)));
  for (int64_t i = 0; i < nloc; i++) lrows[i] = cb->interior[rstart + i] - g0;
  FMBD_GCALL(fmbd_csr_submatrix(Kr, nloc, lrows, ns, cb->interior, Ksl));
  FMBD_GCALL(fmbd_csr_submatrix(Mr, nloc, lrows, ns, cb->interior, Msl));
  FMBD_GCALL(fmbd_csr_submatrix(Kr, nloc, lrows, nb, cb->boundary, Kcl));
  FMBD_GCALL(fmbd_csr_submatrix(Mr, nloc, lrows, nb, cb->boundary, Mcl));
  for (int64_t k = b0; k < b1; k++) lrows[k - b0] = cb->boundary[k] - g0;
  FMBD_GCALL(fmbd_csr_submatrix(Kr, b1 - b0, lrows, nb, cb->boundary, Kbl));
  FMBD_GCALL(fmbd_csr_submatrix(Mr, b1 - b0, lrows, nb, cb->boundary, Mbl));
done:
  fmbd_csr_destroy(&Kr);  // the rows are not needed any more (peak memory)
  fmbd_csr_destroy(&Mr);
  fmbd_free(lrows);
  return rc;
}

int fmbd_slepc_cb_reduce(fmbd_h5 *f, int64_t n, int64_t nb, const int64_t *boundary,
                         const fmbd_slepc_opts *oin, fmbd_cb **out, fmbd_slepc_timing *t) {
  int rc = FMBD_OK;
  fmbd_slepc_opts o;
  if (oin) {
    o = *oin;
  } else {
    fmbd_slepc_defaults(&o);
  }
  memset(t, 0, sizeof *t);
  const int rank = fmbd_slepc_rank(), np = fmbd_slepc_size();
  fmbd_cb *cb = NULL;
  fmbd_csr *Ksl = NULL, *Msl = NULL, *Kcl = NULL, *Mcl = NULL, *Kbl = NULL, *Mbl = NULL;
  fmbd_csr *Kc = NULL, *Mc = NULL, *Kb = NULL, *Mb = NULL;
  char *mark = NULL;
  idx_val *order = NULL;
  double *lam = NULL;
  Mat Ks = NULL, Ms = NULL;
  EPS eps = NULL;
  KSP ksp = NULL;
  PC pc = NULL;
  Vec x = NULL, y = NULL, z = NULL, x0 = NULL;
  VecScatter sc = NULL;
  *out = NULL;
  double t0 = MPI_Wtime();

  // --- the partition (every process, as fmbd_cb_reduce) ---
  FMBD_GALLOC(cb = fmbd_calloc(1, sizeof *cb));
  snprintf(cb->method, sizeof cb->method, "cb");
  cb->ndof = n;
  cb->kappa_next = NAN;
  cb->sturm_shift = NAN;
  cb->sturm_count = -1;
  FMBD_GALLOC(mark = fmbd_calloc((size_t)(n ? n : 1), 1));
  for (int64_t k = 0; k < nb; k++) {
    FMBD_GCHECK(boundary[k] >= 0 && boundary[k] < n && (k == 0 || boundary[k] > boundary[k - 1]),
                FMBD_ERR_VALUE, "boundary dof list not sorted, unique and in range at %lld",
                (long long)k);
    mark[boundary[k]] = 1;
  }
  int64_t ns = n - nb;
  FMBD_GCHECK(ns > 0, FMBD_ERR_VALUE, "every dof of the body is a boundary dof: nothing to reduce");
  FMBD_GCHECK(o.nmodes >= 1 && o.nmodes < ns, FMBD_ERR_VALUE,
              "%lld modes asked for, but the body has %lld interior dofs (%lld dofs, %lld on the "
              "boundary); fe2cb-mpi needs 1 <= modes < interior dofs",
              (long long)o.nmodes, (long long)ns, (long long)n, (long long)nb);
  cb->ns = ns;
  cb->nb = nb;
  FMBD_GALLOC(cb->interior = fmbd_malloc((size_t)ns * sizeof(int64_t)));
  FMBD_GALLOC(cb->boundary = fmbd_malloc((size_t)(nb ? nb : 1) * sizeof(int64_t)));
  for (int64_t i = 0, a = 0, b = 0; i < n; i++) {
    if (mark[i])
      cb->boundary[b++] = i;
    else
      cb->interior[a++] = i;
  }

  // --- this process's rows: interior rows rstart.. (PETSc's split), read from the file as the
  // contiguous block of the whole matrix's rows g0 .. g1-1 that holds them and the boundary rows
  // up to the next process's first interior row (process 0 from row 0, the last to row n), so
  // that every row is read by exactly one process ---
  PetscInt nloc = PETSC_DECIDE, Ns = (PetscInt)ns, rstart = 0;
  PCALL(PetscSplitOwnership(PETSC_COMM_WORLD, &nloc, &Ns));
  {
    PetscInt end = 0;
    MPI_Scan(&nloc, &end, 1, MPIU_INT, MPI_SUM, PETSC_COMM_WORLD);
    rstart = end - nloc;
  }
  int64_t g0 = rank == 0 ? 0 : (rstart < ns ? cb->interior[rstart] : n);
  int64_t g1 = rank == np - 1 ? n : (rstart + nloc < ns ? cb->interior[rstart + nloc] : n);
  // local work: a failure on one process is agreed on before the next collective call
  rc = fmbd_slepc_agree(
      read_blocks(f, cb, g0, g1, nloc, rstart, &Ksl, &Msl, &Kcl, &Mcl, &Kbl, &Mbl));
  if (rc) goto done;
  // process 0 gets the (sparse) coupling and boundary blocks: Kc, Mc (ns x nb), Kb, Mb
  FMBD_GCALL(gather_rows0(Kcl, &Kc));
  FMBD_GCALL(gather_rows0(Mcl, &Mc));
  FMBD_GCALL(gather_rows0(Kbl, &Kb));
  FMBD_GCALL(gather_rows0(Mbl, &Mb));
  fmbd_csr_destroy(&Kbl);
  fmbd_csr_destroy(&Mbl);
  FMBD_GCALL(to_petsc(Ksl, nloc, Ns, nloc, Ns, &Ks));
  fmbd_csr_destroy(&Ksl);
  FMBD_GCALL(to_petsc(Msl, nloc, Ns, nloc, Ns, &Ms));
  fmbd_csr_destroy(&Msl);
  FMBD_GCALL(check_symmetric(Ks, "/K", o.sym_rtol));
  FMBD_GCALL(check_symmetric(Ms, "/M", o.sym_rtol));
  PCALL(MatSetOption(Ks, MAT_SYMMETRIC, PETSC_TRUE));
  PCALL(MatSetOption(Ks, MAT_SPD, PETSC_TRUE));
  PCALL(MatSetOption(Ms, MAT_SYMMETRIC, PETSC_TRUE));
  t->distribute = tmax(MPI_Wtime() - t0);
  {
    double mine = 0;
    fmbd_slepc_peak_mb(&mine, &t->read_peak_mb);
  }

  // --- fixed-interface modes: Krylov-Schur, shift-and-invert at 0, MUMPS Cholesky of Ks ---
  double t1 = MPI_Wtime(), c1 = fmbd_cpu_s();
  int64_t nd = o.nmodes, want = nd + 1 < ns ? nd + 1 : nd;  // one more: kappa_next
  FMBD_GCALL(eps_setup(Ks, Ms, 0.0, want, o.tol, &eps, &ksp, &pc));
  t->factor = tmax(MPI_Wtime() - t1);
  t->factor_cpu = fmbd_cpu_s() - c1;
  FMBD_GCALL(factor_figures(pc, t));
  t1 = MPI_Wtime();
  PCALL(EPSSolve(eps));
  {
    PetscInt nconv = 0, its = 0;
    PCALL(EPSGetConverged(eps, &nconv));
    PCALL(EPSGetIterationNumber(eps, &its));
    t->nconv = nconv;
    t->its = its;
    FMBD_GCHECK(nconv >= nd, FMBD_ERR_CONVERGE,
                "SLEPc Krylov-Schur: %lld of %lld fixed-interface modes converged (tol %g)",
                (long long)nconv, (long long)nd, o.tol);
    if (nconv < want) want = nd;
  }
  t->modes = tmax(MPI_Wtime() - t1);
  {
    PetscInt nsolve = 0;
    PCALL(KSPGetTotalIterations(ksp, &nsolve));  // preonly: one per application
    t->solves = nsolve + 3 * nb;
  }

  // --- the pairs, ascending, M-normalised, signed and checked; gathered on process 0 ---
  t1 = MPI_Wtime();
  PCALL(MatCreateVecs(Ks, &x, &y));
  PCALL(VecDuplicate(x, &z));
  PCALL(VecScatterCreateToZero(x, &sc, &x0));
  FMBD_GCALL(sorted_values(eps, want, &order, &lam));
  cb->nd = nd;
  if (want > nd) cb->kappa_next = lam[nd];
  FMBD_GALLOC(cb->kappa = fmbd_malloc((size_t)nd * sizeof(double)));
  memcpy(cb->kappa, lam, (size_t)nd * sizeof(double));
  if (rank == 0) FMBD_GALLOC(cb->Phi = fmbd_malloc((size_t)(ns * nd) * sizeof(double)));
  for (int64_t k = 0; k < nd; k++) {
    PCALL(EPSGetEigenvector(eps, (PetscInt)order[k].i, x, NULL));
    // Ms-normalise (SLEPc returns B-normalised vectors for GHEP; done again at our round-off)
    PetscScalar xmx = 0;
    PCALL(MatMult(Ms, x, y));
    PCALL(VecDot(x, y, &xmx));
    PCALL(VecScale(x, 1.0 / sqrt(xmx)));
    // the sign convention of fmbd_eig: the largest-magnitude component positive (the first
    // such index on ties, as the serial loop)
    {
      PetscInt imax = 0;
      PetscReal vmax = 0;
      PCALL(VecMax(x, NULL, &vmax));
      PetscReal vmin = 0;
      PCALL(VecMin(x, &imax, &vmin));
      PetscInt imx = 0;
      PCALL(VecMax(x, &imx, &vmax));
      // |min| > max strictly, or equal magnitude with the minimum first
      if (-vmin > vmax || (-vmin == vmax && imax < imx)) PCALL(VecScale(x, -1.0));
    }
    {
      double r = 0;
      FMBD_GCALL(residual(Ks, Ms, x, lam[k], 0.0, y, z, &r));
      if (r > cb->max_residual) cb->max_residual = r;
    }
    FMBD_GCALL(gather0(sc, x, x0, rank == 0 ? cb->Phi + k * ns : NULL));
  }
  FMBD_GCHECK(cb->max_residual <= o.resid_tol, FMBD_ERR_CONVERGE,
              "largest relative residual of the fixed-interface modes %.3g > %.3g",
              cb->max_residual, o.resid_tol);
  t->gather = MPI_Wtime() - t1;

  // --- constraint modes and projections with the same factor (the ST's KSP) ---
  t1 = MPI_Wtime();
  c1 = fmbd_cpu_s();
  if (rank == 0) {
    FMBD_GALLOC(cb->Psi = fmbd_malloc((size_t)(ns * (nb ? nb : 1)) * sizeof(double)));
    FMBD_GALLOC(cb->A = fmbd_malloc((size_t)(ns * (nb ? nb : 1)) * sizeof(double)));
    FMBD_GALLOC(cb->KsinvA = fmbd_malloc((size_t)(ns * (nb ? nb : 1)) * sizeof(double)));
    FMBD_GALLOC(cb->KsinvMsKsinvA = fmbd_malloc((size_t)(ns * (nb ? nb : 1)) * sizeof(double)));
  }
  for (int64_t j = 0; j < nb; j++) {
    size_t off = (size_t)(j * ns);
    FMBD_GCALL(set_column(Kcl, j, -1.0, y));
    PCALL(KSPSolve(ksp, y, x));  // Psi_j = -Ks^-1 Kc_j
    FMBD_GCALL(gather0(sc, x, x0, rank == 0 ? cb->Psi + off : NULL));
    FMBD_GCALL(set_column(Mcl, j, 1.0, z));
    PCALL(MatMultAdd(Ms, x, z, y));  // A_j = Ms Psi_j + Mc_j
    FMBD_GCALL(gather0(sc, y, x0, rank == 0 ? cb->A + off : NULL));
    PCALL(KSPSolve(ksp, y, x));  // Ks^-1 A_j
    FMBD_GCALL(gather0(sc, x, x0, rank == 0 ? cb->KsinvA + off : NULL));
    PCALL(MatMult(Ms, x, y));
    PCALL(KSPSolve(ksp, y, z));  // Ks^-1 Ms Ks^-1 A_j
    FMBD_GCALL(gather0(sc, z, x0, rank == 0 ? cb->KsinvMsKsinvA + off : NULL));
  }
  t->constraint = tmax(MPI_Wtime() - t1);
  t->constraint_cpu = fmbd_cpu_s() - c1;
  t->gather = tmax(t->gather);
  EPSDestroy(&eps);  // the factor of Ks: freed before the Sturm factor (as large)
  ksp = NULL;

  // --- Sturm count: no mode below kappa_nd skipped ---
  if (o.sturm && want > nd) {
    t1 = MPI_Wtime();
    double lo = cb->kappa[nd - 1], hi = cb->kappa_next;
    if (hi - lo > 1e-6 * hi) {
      double s = 0.5 * (lo + hi);
      int64_t count = -1;
      FMBD_GCALL(sturm_count(Ks, Ms, s, &count));
      cb->sturm_shift = s;
      cb->sturm_count = count;
      FMBD_GCHECK(count == nd, FMBD_ERR_CONVERGE,
                  "Sturm count %lld eigenvalues below %.6g Hz, Krylov-Schur found %lld: a mode "
                  "was skipped (ask for more modes)",
                  (long long)count, sqrt(s) / (2 * M_PI), (long long)nd);
    } else {
      fmbd_log(FMBD_LOG_WARN, "no gap between mode %lld and the next: Sturm count not done",
               (long long)nd);
    }
    t->sturm = tmax(MPI_Wtime() - t1);
  }

  // --- process 0: the library's boundary block, Phi' A and reduced eigensolution ---
  t1 = MPI_Wtime();
  if (rank == 0) {
    FMBD_GCALL(fmbd_cb_condense_boundary(cb, Kc, Mc, Kb, Mb));
    FMBD_GALLOC(cb->PhitA = fmbd_malloc((size_t)(nd * (nb ? nb : 1)) * sizeof(double)));
    if (nb > 0) {
      fmbd_dense_gemm('T', 'N', nd, nb, ns, 1.0, cb->Phi, ns, cb->A, ns, 0.0, cb->PhitA, nd);
    }
    FMBD_GCALL(fmbd_cb_update_reduced(cb, o.rigid_rtol));
    *out = cb;
    cb = NULL;
  }
  t->reduced = MPI_Wtime() - t1;
done:
  rc = fmbd_slepc_agree(rc);
  if (rc != FMBD_OK && *out) fmbd_cb_destroy(out);
  fmbd_cb_destroy(&cb);
  EPSDestroy(&eps);
  MatDestroy(&Ks);
  MatDestroy(&Ms);
  VecDestroy(&x);
  VecDestroy(&y);
  VecDestroy(&z);
  VecDestroy(&x0);
  VecScatterDestroy(&sc);
  fmbd_csr_destroy(&Kbl);
  fmbd_csr_destroy(&Mbl);
  fmbd_csr_destroy(&Ksl);
  fmbd_csr_destroy(&Msl);
  fmbd_csr_destroy(&Kcl);
  fmbd_csr_destroy(&Mcl);
  fmbd_csr_destroy(&Kc);
  fmbd_csr_destroy(&Mc);
  fmbd_csr_destroy(&Kb);
  fmbd_csr_destroy(&Mb);
  fmbd_free(mark);
  fmbd_free(order);
  fmbd_free(lam);
  return rc;
}

int fmbd_slepc_exact(fmbd_h5 *f, int64_t nev, bool free_body, const fmbd_slepc_opts *oin,
                     double *lambda, fmbd_slepc_exact_info *info) {
  int rc = FMBD_OK;
  fmbd_slepc_opts o;
  if (oin) {
    o = *oin;
  } else {
    fmbd_slepc_defaults(&o);
  }
  memset(info, 0, sizeof *info);
  info->sturm_shift = NAN;
  info->sturm_count = -1;
  fmbd_csr *Kr = NULL, *Mr = NULL;
  Mat K = NULL, M = NULL;
  EPS eps = NULL;
  KSP ksp = NULL;
  PC pc = NULL;
  Vec x = NULL, y = NULL, z = NULL;
  idx_val *order = NULL;
  double *lam = NULL;
  int64_t shape[2] = {0, 0};
  double t0 = MPI_Wtime();

  // --- this process's rows of the whole K and M (PETSc's split of the n rows) ---
  FMBD_GCALL(fmbd_h5_read_attr_i64(f, "/K", "shape", 2, shape));
  int64_t n = shape[0];
  FMBD_GCHECK(n >= 2 && shape[1] == n && n < PETSC_MAX_INT, FMBD_ERR_FORMAT,
              "/K has shape (%lld, %lld): not a square matrix of at least 2 rows within this "
              "PETSc's 32-bit indices",
              (long long)shape[0], (long long)shape[1]);
  FMBD_GCHECK(nev >= 1 && nev < n - 1, FMBD_ERR_VALUE,
              "%lld eigenvalues asked for, the body has %lld dofs", (long long)nev, (long long)n);
  PetscInt nloc = PETSC_DECIDE, N = (PetscInt)n, rstart = 0;
  PCALL(PetscSplitOwnership(PETSC_COMM_WORLD, &nloc, &N));
  {
    PetscInt end = 0;
    MPI_Scan(&nloc, &end, 1, MPIU_INT, MPI_SUM, PETSC_COMM_WORLD);
    rstart = end - nloc;
  }
  // local work: a failure on one process is agreed on before the next collective call
  rc = fmbd_h5_read_csr_rows(f, "/K", rstart, rstart + nloc, NULL, &Kr);
  if (!rc) rc = fmbd_h5_read_csr_rows(f, "/M", rstart, rstart + nloc, NULL, &Mr);
  if (!rc && (Kr->ncols != n || Mr->ncols != n)) {
    fmbd_err_context(NULL, "/M");
    rc = FMBD_ERR_FORMAT;
    (void)fmbd_err_set(rc, __FILE__, __LINE__, __func__, "%lld columns, /K %lld rows",
                       (long long)Mr->ncols, (long long)n);
  }
  if (!rc) rc = check_rows(Kr, Mr, rstart);
  rc = fmbd_slepc_agree(rc);
  if (rc) goto done;
  // the upper end of the spectrum, max K_ii / M_ii (fmbd_eig_spectrum_scale), over the processes
  double scale = 0.0;
  for (int64_t i = 0; i < Kr->nrows; i++) {
    double m = fmbd_csr_get(Mr, i, rstart + i);
    if (m > 0) scale = fmax(scale, fmbd_csr_get(Kr, i, rstart + i) / m);
  }
  (void)MPI_Allreduce(MPI_IN_PLACE, &scale, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  FMBD_GCALL(to_petsc(Kr, nloc, N, nloc, N, &K));
  fmbd_csr_destroy(&Kr);
  FMBD_GCALL(to_petsc(Mr, nloc, N, nloc, N, &M));
  fmbd_csr_destroy(&Mr);
  FMBD_GCALL(check_symmetric(K, "/K", o.sym_rtol));
  FMBD_GCALL(check_symmetric(M, "/M", o.sym_rtol));
  PCALL(MatSetOption(K, MAT_SYMMETRIC, PETSC_TRUE));
  PCALL(MatSetOption(M, MAT_SYMMETRIC, PETSC_TRUE));
  info->t_read = tmax(MPI_Wtime() - t0);

  // --- the shift: fmbd_eig's strategy (docs/THEORY.md section 8). K may be singular (rigid-
  // body modes): a loose first pass of 12 pairs at -1e-6 scale finds the first flexible
  // eigenvalue lambda_f (the lowest above 1e-6 of the largest found), and the real pass shifts
  // to -lambda_f / 2, where rigid and flexible modes are of the same order for the operator ---
  double sigma = 0.0;
  if (free_body) {
    double t1 = MPI_Wtime();
    int64_t w1 = n - 2 < 12 ? n - 2 : 12;
    FMBD_GCALL(eps_setup(K, M, -1e-6 * scale, w1, 1e-6, &eps, &ksp, &pc));
    PCALL(EPSSolve(eps));
    PetscInt nc = 0;
    PCALL(EPSGetConverged(eps, &nc));
    FMBD_GCHECK(nc >= 1, FMBD_ERR_CONVERGE,
                "SLEPc Krylov-Schur: no eigenvalue converged in the first pass (shift %.3g)",
                -1e-6 * scale);
    FMBD_GCALL(sorted_values(eps, nc, &order, &lam));
    double lf = NAN;
    for (int64_t k = 0; k < nc; k++) {
      if (lam[k] > 1e-6 * lam[nc - 1]) {
        lf = lam[k];
        break;
      }
    }
    sigma = isfinite(lf) ? -0.5 * lf : -1e-6 * scale;
    fmbd_free(order);
    fmbd_free(lam);
    order = NULL;
    lam = NULL;
    EPSDestroy(&eps);
    info->t_first = tmax(MPI_Wtime() - t1);
  }
  info->sigma = sigma;

  // --- the pairs: nev and one more (the Sturm shift goes between them) ---
  double t1 = MPI_Wtime();
  int64_t want = nev + 1;
  FMBD_GCALL(eps_setup(K, M, sigma, want, o.tol, &eps, &ksp, &pc));
  info->t_factor = tmax(MPI_Wtime() - t1);
  t1 = MPI_Wtime();
  PCALL(EPSSolve(eps));
  {
    PetscInt nconv = 0, its = 0;
    PCALL(EPSGetConverged(eps, &nconv));
    PCALL(EPSGetIterationNumber(eps, &its));
    info->nconv = nconv;
    info->its = its;
    FMBD_GCHECK(nconv >= want, FMBD_ERR_CONVERGE,
                "SLEPc Krylov-Schur: %lld of %lld eigenpairs converged (tol %g)", (long long)nconv,
                (long long)want, o.tol);
  }
  FMBD_GCALL(sorted_values(eps, want, &order, &lam));
  PCALL(MatCreateVecs(K, &x, &y));
  PCALL(VecDuplicate(x, &z));
  for (int64_t k = 0; k < nev; k++) {
    double r = 0;
    PCALL(EPSGetEigenvector(eps, (PetscInt)order[k].i, x, NULL));
    PetscScalar xmx = 0;  // M-normalised (SLEPc's B-normalisation, at our round-off)
    PCALL(MatMult(M, x, y));
    PCALL(VecDot(x, y, &xmx));
    PCALL(VecScale(x, 1.0 / sqrt(xmx)));
    FMBD_GCALL(residual(K, M, x, lam[k], sigma, y, z, &r));
    if (r > info->max_residual) info->max_residual = r;
  }
  FMBD_GCHECK(info->max_residual <= o.resid_tol, FMBD_ERR_CONVERGE,
              "largest relative residual of the eigenpairs %.3g > %.3g", info->max_residual,
              o.resid_tol);
  info->t_solve = tmax(MPI_Wtime() - t1);
  info->next = lam[nev];
  EPSDestroy(&eps);  // the factor: freed before the Sturm factor (as large)

  // --- never missed: the inertia of K - s M, s midway between the last pair and the next ---
  {
    t1 = MPI_Wtime();
    double lo = lam[nev - 1], hi = lam[nev];
    FMBD_GCHECK(hi - lo > 1e-6 * fabs(hi), FMBD_ERR_CONVERGE,
                "eigenvalues %lld and %lld are equal to 1e-6 (%.10g): no gap to place the Sturm "
                "shift in (ask for one more mode)",
                (long long)nev, (long long)(nev + 1), hi);
    double s = 0.5 * (lo + hi);
    int64_t count = -1;
    FMBD_GCALL(sturm_count(K, M, s, &count));
    info->sturm_shift = s;
    info->sturm_count = count;
    FMBD_GCHECK(count == nev, FMBD_ERR_CONVERGE,
                "Sturm count %lld eigenvalues below %.6g Hz, Krylov-Schur found %lld: a mode was "
                "skipped",
                (long long)count, sqrt(fabs(s)) / (2 * M_PI), (long long)nev);
    info->t_sturm = tmax(MPI_Wtime() - t1);
  }
  memcpy(lambda, lam, (size_t)nev * sizeof(double));
done:
  rc = fmbd_slepc_agree(rc);
  EPSDestroy(&eps);
  MatDestroy(&K);
  MatDestroy(&M);
  VecDestroy(&x);
  VecDestroy(&y);
  VecDestroy(&z);
  fmbd_csr_destroy(&Kr);
  fmbd_csr_destroy(&Mr);
  fmbd_free(order);
  fmbd_free(lam);
  return rc;
}
