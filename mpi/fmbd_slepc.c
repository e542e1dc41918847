// mpi/fmbd_slepc.c: the distributed Craig-Bampton reduction (see fmbd_slepc.h)
// SPDX-License-Identifier: MIT
//
// References: SLEPc Users Manual (Roman et al., 3.18), sections 2.5 (Krylov-Schur), 3.4
// (shift-and-invert spectral transformation) and 3.4.5 (its linear solves: KSPPREONLY with a
// direct factorisation); PETSc Users Manual, MATSOLVERMUMPS (Cholesky of AIJ matrices,
// MatGetInertia with ICNTL(13) = 1 on more than one process); MUMPS 5.5 Users' guide, ICNTL(13).
#include "fmbd_slepc.h"

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

// error codes are negative: the "worst" is the smallest
int fmbd_slepc_agree(int rc) {
  int all = rc;
  MPI_Allreduce(&rc, &all, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
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

int fmbd_slepc_cb_reduce(fmbd_csr **Kp, fmbd_csr **Mp, int64_t nb, const int64_t *boundary,
                         const fmbd_slepc_opts *oin, fmbd_cb **out, fmbd_slepc_timing *t) {
  int rc = FMBD_OK;
  fmbd_slepc_opts o;
  if (oin) {
    o = *oin;
  } else {
    fmbd_slepc_defaults(&o);
  }
  memset(t, 0, sizeof *t);
  const int rank = fmbd_slepc_rank();
  fmbd_cb *cb = NULL;
  fmbd_csr *Ksl = NULL, *Msl = NULL, *Kcl = NULL, *Mcl = NULL;
  fmbd_csr *Kc = NULL, *Mc = NULL, *Kb = NULL, *Mb = NULL;
  char *mark = NULL;
  idx_val *order = NULL;
  double *lam = NULL;
  Mat Ks = NULL, Ms = NULL;
  EPS eps = NULL;
  KSP ksp = NULL;
  Vec x = NULL, y = NULL, z = NULL, x0 = NULL;
  VecScatter sc = NULL;
  *out = NULL;
  const fmbd_csr *K = *Kp, *M = *Mp;
  int64_t n = K->nrows;
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

  // --- this process's rows of Ks, Ms, Kc, Mc; process 0 keeps the boundary blocks ---
  PetscInt nloc = PETSC_DECIDE, Ns = (PetscInt)ns, rstart = 0;
  PCALL(PetscSplitOwnership(PETSC_COMM_WORLD, &nloc, &Ns));
  {
    PetscInt end = 0;
    MPI_Scan(&nloc, &end, 1, MPIU_INT, MPI_SUM, PETSC_COMM_WORLD);
    rstart = end - nloc;
  }
  const int64_t *rows = cb->interior + rstart;
  FMBD_GCALL(fmbd_csr_submatrix(K, nloc, rows, ns, cb->interior, &Ksl));
  FMBD_GCALL(fmbd_csr_submatrix(M, nloc, rows, ns, cb->interior, &Msl));
  FMBD_GCALL(fmbd_csr_submatrix(K, nloc, rows, nb, cb->boundary, &Kcl));
  FMBD_GCALL(fmbd_csr_submatrix(M, nloc, rows, nb, cb->boundary, &Mcl));
  if (rank == 0) {
    FMBD_GCALL(fmbd_csr_submatrix(K, ns, cb->interior, nb, cb->boundary, &Kc));
    FMBD_GCALL(fmbd_csr_submatrix(M, ns, cb->interior, nb, cb->boundary, &Mc));
    FMBD_GCALL(fmbd_csr_submatrix(K, nb, cb->boundary, nb, cb->boundary, &Kb));
    FMBD_GCALL(fmbd_csr_submatrix(M, nb, cb->boundary, nb, cb->boundary, &Mb));
  }
  fmbd_csr_destroy(Kp);  // the whole body is not needed any more (peak memory)
  fmbd_csr_destroy(Mp);
  K = M = NULL;
  FMBD_GCALL(to_petsc(Ksl, nloc, Ns, nloc, Ns, &Ks));
  fmbd_csr_destroy(&Ksl);
  FMBD_GCALL(to_petsc(Msl, nloc, Ns, nloc, Ns, &Ms));
  fmbd_csr_destroy(&Msl);
  PCALL(MatSetOption(Ks, MAT_SYMMETRIC, PETSC_TRUE));
  PCALL(MatSetOption(Ks, MAT_SPD, PETSC_TRUE));
  PCALL(MatSetOption(Ms, MAT_SYMMETRIC, PETSC_TRUE));
  t->distribute = tmax(MPI_Wtime() - t0);

  // --- fixed-interface modes: Krylov-Schur, shift-and-invert at 0, MUMPS Cholesky of Ks ---
  double t1 = MPI_Wtime(), c1 = fmbd_cpu_s();
  int64_t nd = o.nmodes, want = nd + 1 < ns ? nd + 1 : nd;  // one more: kappa_next
  ST st = NULL;
  PC pc = NULL;
  PCALL(EPSCreate(PETSC_COMM_WORLD, &eps));
  PCALL(EPSSetOperators(eps, Ks, Ms));
  PCALL(EPSSetProblemType(eps, EPS_GHEP));
  PCALL(EPSSetType(eps, EPSKRYLOVSCHUR));
  PCALL(EPSSetWhichEigenpairs(eps, EPS_TARGET_MAGNITUDE));
  PCALL(EPSSetTarget(eps, 0.0));
  PCALL(EPSSetDimensions(eps, (PetscInt)want, PETSC_DEFAULT, PETSC_DEFAULT));
  PCALL(EPSSetTolerances(eps, o.tol, 1000));
  PCALL(EPSGetST(eps, &st));
  PCALL(STSetType(st, STSINVERT));
  PCALL(STGetKSP(st, &ksp));
  PCALL(KSPSetType(ksp, KSPPREONLY));
  PCALL(KSPGetPC(ksp, &pc));
  PCALL(PCSetType(pc, PCCHOLESKY));
  PCALL(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  PCALL(EPSSetFromOptions(eps));  // PETSC_OPTIONS may change any of it (-eps_view etc.)
  PCALL(EPSSetUp(eps));           // the MUMPS factorisation of Ks (analysis + numeric)
  t->factor = tmax(MPI_Wtime() - t1);
  t->factor_cpu = fmbd_cpu_s() - c1;
  {
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
  }
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
  FMBD_GALLOC(order = fmbd_malloc((size_t)want * sizeof *order));
  FMBD_GALLOC(lam = fmbd_malloc((size_t)want * sizeof(double)));
  for (int64_t k = 0; k < want; k++) {
    PetscScalar kr = 0, ki = 0;
    PCALL(EPSGetEigenvalue(eps, (PetscInt)k, &kr, &ki));
    order[k] = (idx_val){kr, k};
  }
  qsort(order, (size_t)want, sizeof *order, cmp_idx_val);
  for (int64_t k = 0; k < want; k++) lam[k] = order[k].v;
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
    // relative residual ||Ks x - kappa Ms x|| / max(||Ks x||, kappa ||Ms x||) (fmbd_eig's)
    {
      PetscReal nk = 0, nm = 0, nr = 0;
      PCALL(MatMult(Ks, x, y));
      PCALL(MatMult(Ms, x, z));
      PCALL(VecNorm(y, NORM_2, &nk));
      PCALL(VecNorm(z, NORM_2, &nm));
      PCALL(VecAXPY(y, -lam[k], z));
      PCALL(VecNorm(y, NORM_2, &nr));
      double r = nr / fmax(nk, fabs(lam[k]) * nm);
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
