// mpi/fmbd_slepc.h: the Craig-Bampton reduction of one FE body on a distributed matrix (PETSc,
// SLEPc, MUMPS over MPI), for fe2cb-mpi. Not part of libfmbd: only fe2cb-mpi links MPI.
// SPDX-License-Identifier: MIT
//
// The same reduction as fmbd_cb_reduce (docs/THEORY.md section 1), with its two costly parts on
// MPI processes (docs/SCALE.md):
//   fixed-interface modes  Ks phi = kappa Ms phi: SLEPc Krylov-Schur (EPSKRYLOVSCHUR, problem
//                          type GHEP) with shift-and-invert at target 0 (STSINVERT), the
//                          factor of Ks by MUMPS' parallel Cholesky (PCCHOLESKY, MATSOLVERMUMPS)
//   constraint modes etc.  Psi = -Ks^-1 Kc, A = Ms Psi + Mc, Ks^-1 A, Ks^-1 Ms Ks^-1 A: solves
//                          with the same MUMPS factor
//   completeness           a Sturm count: the inertia of an LDL' factor (MUMPS, ICNTL(13) = 1)
//                          of Ks - s Ms, s midway between the last mode and the next
// Ks and Ms are split into contiguous row blocks (PETSc's default ownership); every process
// reads only its rows of the body's K and M from the file (HDF5 hyperslabs of the CSR,
// fmbd_h5_read_csr_rows) and takes its blocks with the library's fmbd_csr_submatrix. The dense
// results (Phi, Psi, A, Ks^-1 A, Ks^-1 Ms Ks^-1 A) are gathered on process 0, where the
// library's own code finishes the job: the boundary block (fmbd_cb_condense_boundary), Phi' A,
// the reduced eigensolution (fmbd_cb_update_reduced) and the file (fmbd_cb_write), so the
// .cb.h5 is the serial fe2cb's, to round-off.
// fmbd_slepc_exact: the whole body's lowest eigenvalues the same way (cbcheck-mpi --exact).
#ifndef FMBD_SLEPC_H
#define FMBD_SLEPC_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_cb.h"
#include "fmbd_csr.h"
#include "fmbd_h5.h"

/// @brief SlepcInitialize (and MPI_Init) without command-line options (PETSc options come from
/// the PETSC_OPTIONS environment variable). FMBD_OK or FMBD_ERR_EXTERNAL.
int fmbd_slepc_init(void);
/// @brief SlepcFinalize (and MPI_Finalize).
void fmbd_slepc_finalize(void);
/// @brief This process's rank and the number of processes in MPI_COMM_WORLD.
int fmbd_slepc_rank(void);
int fmbd_slepc_size(void);
/// @brief The largest of every process's rc, on every process (a collective failure check).
int fmbd_slepc_agree(int rc);
/// @brief Peak resident memory of this process (MB) and the largest over the processes.
void fmbd_slepc_peak_mb(double *mine, double *largest);

/// Options of fmbd_slepc_cb_reduce.
typedef struct fmbd_slepc_opts {
  int64_t nmodes;     ///< fixed-interface modes wanted (>= 1)
  double tol;         ///< SLEPc relative tolerance of each pair (default 1e-12, as ARPACK's)
  double resid_tol;   ///< accepted relative residual of each pair (1e-6, as fmbd_eig)
  bool sturm;         ///< the Sturm count check (default true)
  double rigid_rtol;  ///< as fmbd_cb_opts (1e-6)
  double sym_rtol;    ///< symmetry test of K and M, as fmbd_cb_opts (1e-10)
} fmbd_slepc_opts;

void fmbd_slepc_defaults(fmbd_slepc_opts *o);

/// Where the time went (wall seconds, the slowest process's).
typedef struct fmbd_slepc_timing {
  double distribute, factor, modes, sturm, constraint, gather, reduced;
  double factor_cpu, constraint_cpu;  ///< process 0's CPU seconds of the same (load-independent)
  int64_t nconv, its;                 ///< converged pairs, Krylov-Schur restarts
  int64_t solves;         ///< solves with the factor of Ks (Krylov-Schur's and the 3 nb others)
  double factor_entries;  ///< entries of MUMPS's factor of Ks (INFOG(29))
  double factor_flops;    ///< its elimination flops (RINFOG(3))
  double factor_mb_max;   ///< MUMPS memory of the largest process, MB (INFOG(21))
  double factor_mb_sum;   ///< summed over the processes, MB (INFOG(22))
  double read_peak_mb;    ///< largest process's peak memory when its rows are distributed, MB
} fmbd_slepc_timing;

/// @brief Reduce (method cb). Collective: every process passes its own open handle f of the
/// same fmbd-fe file, its dofs n and the same boundary. Each process reads only its row block of
/// /K and /M (fmbd_h5_read_csr_rows): the interior rows PETSc gives it, with the boundary rows
/// between them; process 0 gathers the sparse coupling and boundary blocks. On process 0 *out
/// is the reduced body (fmbd_cb_write writes it); elsewhere NULL.
/// @return the same code on every process: FMBD_OK; FMBD_ERR_VALUE (more modes than interior
///         dofs, K or M not symmetric, a bad diagonal); FMBD_ERR_FORMAT (a bad /K or /M);
///         FMBD_ERR_CONVERGE (fewer pairs converged, residual or Sturm count wrong);
///         FMBD_ERR_EXTERNAL (PETSc/SLEPc/MUMPS failed: its message is on standard error)
int fmbd_slepc_cb_reduce(fmbd_h5 *f, int64_t n, int64_t nb, const int64_t *boundary,
                         const fmbd_slepc_opts *o, fmbd_cb **out, fmbd_slepc_timing *t);

/// What fmbd_slepc_exact did (wall seconds: the slowest process's).
typedef struct fmbd_slepc_exact_info {
  double sigma;         ///< shift of the final pass (0, or -lambda_f / 2 for a free body)
  double next;          ///< the eigenvalue after the last returned
  double sturm_shift;   ///< s of the Sturm count
  int64_t sturm_count;  ///< eigenvalues below s by the inertia of K - s M
  int64_t nconv, its;   ///< converged pairs and restarts of the final pass
  double max_residual;  ///< largest relative residual of the returned pairs
  double t_read, t_first, t_factor, t_solve, t_sturm;
} fmbd_slepc_exact_info;

/// @brief The lowest nev eigenvalues of the whole body, K x = lambda M x (cbcheck --exact),
/// ascending into lambda (nev doubles, on every process), with fmbd_eig_solve's strategy:
/// free_body (K singular: rigid-body modes) shifts below zero from a first loose pass; each
/// pair's relative residual <= o->resid_tol; a Sturm count (MUMPS inertia of K - s M, s in the
/// first gap of 1e-6 above the last wanted eigenvalue) proves that none was skipped. Collective:
/// every process passes its own open handle of the same fmbd-fe file and reads only its row block
/// of /K and /M.
/// @return the same code on every process (as fmbd_slepc_cb_reduce)
int fmbd_slepc_exact(fmbd_h5 *f, int64_t nev, bool free_body, const fmbd_slepc_opts *o,
                     double *lambda, fmbd_slepc_exact_info *info);

#endif
