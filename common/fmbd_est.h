// common/fmbd_est.h: a posteriori relative eigenvalue error estimates of a Craig-Bampton body
// and the boundary-block algebra they need (docs/THEORY.md section 2, Han et al. 2020 [H24-H45])
// SPDX-License-Identifier: MIT
//
// Notation (docs/THEORY.md section 1): interior dofs s (ns), boundary dofs b (nb); fixed-interface
// modes Phi (Ms-normalised), eigenvalues kappa ascending; the "pool" holds the npool lowest
// modes known (computed by fe2cb, possibly extended); the reduced body uses the nd <= npool
// lowest. A = Ms Psi + Mc (lumped mass: Mc = 0), p_k = phi_k' A (row k of PhitA, 1 x nb).
//
//   Xb(nd) = A' Frs A = A' Ks^-1 A - sum_{k<=nd} p_k' p_k / kappa_k        [HA7]
//   Gb(nd) = A' G A   = A' Ks^-1 Ms Ks^-1 A - sum_{k<=nd} p_k' p_k / kappa_k^2
//
// Adding mode nd+1 is the rank-one downdate Xb -= p' p / kappa, Gb -= p' p / kappa^2
// (fmbd_est_set_nd); removing one is the matching update.
//
// ROUND-OFF. A' Ks^-1 A is dominated by the lowest modes; Xb is what is left after they are
// subtracted, so the plain formula loses log10(|A' Ks^-1 A| / |Xb|) digits on top of the
// error of the solves Ks^-1 A (relative error up to eps * cond(Ks)). On a slender beam
// (docs/THEORY.md section 8: cond(Ks) ~ 4e11, ratio ~ 3e5) this destroyed every digit of the
// bending modes' estimates when Ks^-1 A came from dense LAPACK solves (Gb is worse: ratio
// squared); with CHOLMOD's solves of fe2cb the loss measured 1.7e-6 there. fmbd_est_base_projected
// computes the same Xb, Gb without the cancellation when the FE matrices Ks, Ms are at hand: with
// W = Ks^-1 A - Phi Lambda^-1 PhitA (= Frs A in exact arithmetic), the errors of the solve
// lie mostly along the low modes, which are removed by the Ms-orthogonal projection
// W := W - Phi (Phi' Ms W) (exactly zero in exact arithmetic); then Xb = W' Ks W and
// Gb = W' Ms W (since Frs Ks Frs = Frs and Phi_r Lambda_r^-2 Phi_r' = Frs Ms Frs), whose
// errors are second order in the error of W. fmbd_est_base_plain is the formula of the
// brief from the cb file alone, with a noise estimate from the asymmetry of A' (Ks^-1 A).
//
// Estimates of reduced mode n (1-based, counting rigid-body modes), chibar_n, Xi_n, b_n the
// boundary part of Xi_n, x = b' Xb b, g = b' Gb b:
//   lower        eta_n   = chibar x                                   (Boo et al. 2016 [H45])
//   second order         = chibar x + chibar^2 g                         [H36]
//   upper, kappa_n       = (chibar + chibar^2 / kappa_n) x              [H42], kappa_n the
//                          n-th fixed-interface eigenvalue (n counts the rigid-body modes, as
//                          docs/THEORY.md section 8's table does); kappa_n must be among the
//                          dominant eigenvalues [H37], so for n > nd: kappa_nd
//   upper, kappa_(nd+1)  = (chibar + chibar^2 / kappa_(nd+1)) x        (tighter, still above
//                          [H36] since Phi_r Lambda_r^-2 Phi_r' <= Frs / kappa_(nd+1) [H38])
// When kappa_(nd+1) is unknown (nd == npool), kappa_nd is used instead: smaller, so still a
// valid (slightly looser) upper estimate; `knext_known` reports it.
// Rigid-body modes (chibar ~ 0) get 0 and are flagged. Clusters get consistent values: each
// member gets the cluster's largest upper and second-order estimates and the cluster's
// smallest lower estimate (so that the bracket stays conservative), independent of the
// arbitrary basis inside the cluster (docs/THEORY.md section 8). A cluster is a run of consecutive
// flexible modes each within cluster_rtol of the previous one (repeated eigenvalues), or whose
// uncertainty interval [chibar / (1 + upper), chibar] reaches the previous eigenvalue: the full
// body's eigenvalues of such modes may come in another order than the reduced ones, so the
// error of "the n-th mode" is not defined better than over the cluster.
#ifndef FMBD_EST_H
#define FMBD_EST_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"

typedef struct fmbd_est fmbd_est;

/// Per-mode results (arrays of nmodes, caller-owned, see fmbd_est_estimate).
typedef struct fmbd_est_modes {
  int64_t nmodes;    ///< reduced modes described
  double *chibar;    ///< eigenvalue of the reduced body
  bool *rigid;       ///< rigid-body mode (error 0, not a flexible mode)
  int64_t *cluster;  ///< index of the first member of the mode's cluster (itself if alone)
  double *lower, *second, *upper, *upper_next;  ///< the estimates (0 for rigid modes)
  double *x;                                    ///< b' Xb b (diagnostic)
  double *g;                                    ///< b' Gb b (diagnostic)
} fmbd_est_modes;

/// Options of the estimator. Fill with fmbd_est_opts_defaults.
typedef struct fmbd_est_opts {
  double rigid_rtol;     ///< chibar <= rigid_rtol * kappa_1 is a rigid-body mode. Default 1e-6
                         ///< (a frequency 1e-3 of the first fixed-interface one)
  double cluster_rtol;   ///< |chibar_i - chibar_j| <= cluster_rtol * chibar_j groups modes into a
                         ///< repeated cluster. Default 1e-3 (tet meshes of symmetric sections
                         ///< split pairs by ~1e-4)
  bool cluster_overlap;  ///< also cluster modes whose intervals [chibar / (1 + upper), chibar]
                         ///< overlap. Default true
} fmbd_est_opts;

/// @brief The defaults documented in fmbd_est_opts.
void fmbd_est_opts_defaults(fmbd_est_opts *o);

// --- the residual blocks at nd = npool ------------------------------------------------------
/// @brief Xb, Gb at nd = npool from the cb file alone (the brief's formula):
/// Xb = A' KsinvA - PhitA' Lambda^-1 PhitA, Gb = A' KsinvMsKsinvA - PhitA' Lambda^-2 PhitA,
/// both symmetrised.
/// @param[in]  A, KsinvA, KsinvMsKsinvA  ns x nb column-major (KsinvMsKsinvA may be NULL: Gb = 0)
/// @param[in]  kappa (npool), PhitA npool x nb column-major
/// @param[out] Xb, Gb nb x nb (caller allocates)
/// @param[out] noise (may be NULL): estimated absolute round-off of Xb entries, from the
///             asymmetry of A' KsinvA (an exact symmetric matrix) plus eps * |A' KsinvA|
int fmbd_est_base_plain(int64_t ns, int64_t nb, int64_t npool, const double *A,
                        const double *KsinvA, const double *KsinvMsKsinvA, const double *kappa,
                        const double *PhitA, double *Xb, double *Gb, double *noise);

/// @brief Xb, Gb at nd = npool without the cancellation (see ROUND-OFF above).
/// @param[in] K, M   the FE matrices (full symmetric CSR), n x n
/// @param[in] ns, interior  the interior rows of K, M (interior == NULL: K, M are already the
///            ns x ns blocks Ks, Ms). Products Ks W are formed as K W0 (W0 = W on the interior
///            rows, 0 elsewhere) restricted to the interior rows: no submatrix is extracted.
/// @param[in] A, KsinvA ns x nb; Phi ns x npool (Ms-normalised); kappa (npool); PhitA npool x nb
/// @param[out] Xb, Gb nb x nb (caller allocates)
/// @return FMBD_OK, FMBD_ERR_VALUE (shapes), FMBD_ERR_NOMEM
int fmbd_est_base_projected(const fmbd_csr *K, const fmbd_csr *M, int64_t ns,
                            const int64_t *interior, int64_t nb, int64_t npool, const double *A,
                            const double *KsinvA, const double *Phi, const double *kappa,
                            const double *PhitA, double *Xb, double *Gb);

// --- the estimator state ---------------------------------------------------------------------
/// @brief Create an estimator for a body with nb boundary dofs.
/// @param[in] Mbb, Kbb nb x nb boundary blocks of the reduced matrices (independent of nd):
///            Mb_ = Psi' Ms Psi + Psi' Mc + Mc' Psi + Mb, Kb_ = Kb + Kc' Psi (copied)
/// @param[in] opt NULL = defaults (copied)
/// @param[out] out caller destroys with fmbd_est_destroy
int fmbd_est_create(int64_t nb, const double *Mbb, const double *Kbb, const fmbd_est_opts *opt,
                    fmbd_est **out);
void fmbd_est_destroy(fmbd_est **e);

/// @brief Set (or replace, after an extension) the pool of fixed-interface modes: kappa
/// (npool, ascending, > 0), PhitA npool x nb, and the residual blocks Xb, Gb at nd = npool.
/// Copies everything. The current nd becomes npool.
int fmbd_est_set_pool(fmbd_est *e, int64_t npool, const double *kappa, const double *PhitA,
                      const double *Xb, const double *Gb);
/// @brief Move to nd dominant modes (0 <= nd <= npool) by rank-one downdates (nd grows) or
/// updates (nd shrinks) of Xb and Gb.
int fmbd_est_set_nd(fmbd_est *e, int64_t nd);
int64_t fmbd_est_nd(const fmbd_est *e);
int64_t fmbd_est_npool(const fmbd_est *e);
int64_t fmbd_est_nb(const fmbd_est *e);
/// @brief Current Xb, Gb (borrowed, nb x nb, valid until the next call changing nd or pool).
const double *fmbd_est_xb(const fmbd_est *e);
const double *fmbd_est_gb(const fmbd_est *e);

/// @brief Build the reduced matrices for the current nd (docs/THEORY.md section 1, closed form)
/// M_ = [I, PhitA_d; PhitA_d', Mbb], K_ = diag(kappa_d, Kbb), and solve K_ Xi = chibar M_ Xi
/// (dense, LAPACK dsygvd).
/// @param[out] chibar (nd+nb) ascending (caller allocates)
/// @param[out] Xi (nd+nb) x (nd+nb), M_-orthonormal columns (caller allocates)
/// @return FMBD_OK, FMBD_ERR_SINGULAR (M_ not positive definite), FMBD_ERR_NOMEM
int fmbd_est_solve(fmbd_est *e, double *chibar, double *Xi);

/// @brief Estimates for reduced modes 0..m->nmodes-1 of the current nd.
/// @param[in] chibar (nmodes) eigenvalues of the reduced body with the current nd
/// @param[in] Xi eigenvectors, (nd+nb) rows, leading dimension ldxi; rows nd.. are b_n
/// @param[in,out] m arrays of m->nmodes entries, allocated by the caller (fmbd_est_modes_alloc)
int fmbd_est_estimate(const fmbd_est *e, const double *chibar, const double *Xi, int64_t ldxi,
                      fmbd_est_modes *m);
/// @brief Whether kappa_(nd+1) is known (nd < npool, or nd == npool and set with
/// fmbd_est_set_kappa_next) for the upper_next estimate.
bool fmbd_est_knext_known(const fmbd_est *e);
/// @brief The fixed-interface eigenvalue above the pool (kappa_(npool+1)), if known (NAN: not).
void fmbd_est_set_kappa_next(fmbd_est *e, double kappa_next);

/// @brief Solve the reduced problem at the current nd and estimate every reduced mode:
/// m->nmodes is set to nd + nb (m is (re)allocated here; free with fmbd_est_modes_free).
/// @param[out] Xi (nd+nb)^2 eigenvectors if not NULL (caller allocates)
int fmbd_est_run(fmbd_est *e, fmbd_est_modes *m, double *Xi);

// --- iterative selection (docs/THEORY.md section 3, the paper's Figure 1) ------------------------
/// Which estimate drives the selection.
enum fmbd_est_which {
  FMBD_EST_UPPER = 0,       ///< upper, kappa_n (the paper's [H42]; the default)
  FMBD_EST_UPPER_NEXT = 1,  ///< upper, kappa_(nd+1) (tighter)
  FMBD_EST_SECOND = 2,      ///< second order (not a bound)
  FMBD_EST_LOWER = 3        ///< lower (not conservative)
};
/// @brief The estimate `which` of mode n of m.
double fmbd_est_pick(const fmbd_est_modes *m, int which, int64_t n);
/// The names of an estimate: the command-line word ("upper", "upper-next", "second", "lower")
/// and the label of reports and plots ("upper (kappa_n)", ...).
const char *fmbd_est_which_word(int which);
const char *fmbd_est_which_label(int which);
/// The estimate named by a command-line word: 0 and *which, or -1 (unknown word).
int fmbd_est_which_parse(const char *word, int *which);

/// Grow the pool to at least nd_wanted modes (and call fmbd_est_set_pool); return an error
/// (FMBD_ERR_*) if impossible.
typedef int (*fmbd_est_extend_fn)(void *ctx, fmbd_est *e, int64_t nd_wanted);

typedef struct fmbd_est_select_opts {
  double tol;      ///< relative eigenvalue error tolerance e (> 0)
  int64_t nm;      ///< flexible modes that must meet tol (mode range Nm >= 1)
  int64_t n0;      ///< initial number of dominant modes N_init (>= 0)
  int64_t nd_max;  ///< largest nd tried (the body's interior dofs, or a cap)
  int which;       ///< enum fmbd_est_which (default FMBD_EST_UPPER)
} fmbd_est_select_opts;

/// One iteration of the selection log.
typedef struct fmbd_est_iter {
  int64_t nd;             ///< dominant modes of this iteration
  int64_t first_failing;  ///< first flexible mode (1-based) above tol, 0 if none
  double largest;         ///< largest estimate over flexible modes 1..nm (INFINITY if the
                          ///< reduced body has fewer than nm flexible modes)
} fmbd_est_iter;

typedef struct fmbd_est_select_result {
  bool reached;         ///< every flexible mode 1..nm meets tol at nd
  int64_t nd;           ///< final nd (reached) or the last tried
  int64_t best_nd;      ///< nd with the smallest largest estimate
  double best_largest;  ///< that largest estimate
  int64_t niter;        ///< iterations (entries of log)
  fmbd_est_iter *log;   ///< (niter) owned: fmbd_free
  int64_t nextend;      ///< calls of the extend function
} fmbd_est_select_result;

/// @brief The paper's loop: nd = n0; estimate flexible modes n_first..nm with `which`; if
/// one exceeds tol, nd += 1 (one rank-one downdate) and continue from the first failing
/// mode. When n_first..nm all pass, a final pass checks modes 1..nm again (estimates are
/// not monotone in nd); a mode failing there restarts the loop from it. The pool is grown
/// through `extend` when nd exceeds it (NULL: no growth, the pool size caps nd). Stops
/// unreached when nd would exceed nd_max. On return the estimator is at res->nd when the
/// tolerance was reached, else at res->best_nd.
/// @return FMBD_OK also when the tolerance is not reached (res->reached false); errors of
///         the reduced solve or of extend
int fmbd_est_select(fmbd_est *e, const fmbd_est_select_opts *o, fmbd_est_extend_fn extend,
                    void *ctx, fmbd_est_select_result *res);

/// @brief Allocate the arrays of m for n modes (zeroed). fmbd_est_modes_free releases them.
int fmbd_est_modes_alloc(int64_t n, fmbd_est_modes *m);
void fmbd_est_modes_free(fmbd_est_modes *m);

// --- bodies held at some boundary dofs (docs/THEORY.md section 12) ----------------------------
/// @brief A new estimator of the held problem: the body with the boundary dofs outside free_idx
/// held (the scene's joints hold them). Its boundary is the free subset F (free_idx: nfree
/// indices into 0..nb-1, ascending); it gets full's options, the F blocks of Mbb, Kbb and the
/// pool (fmbd_est_set_pool_subset). full must be at nd = npool (just after fmbd_est_set_pool).
/// @param[out] out caller destroys with fmbd_est_destroy
int fmbd_est_create_subset(const fmbd_est *full, int64_t nfree, const int64_t *free_idx,
                           fmbd_est **out);
/// @brief Set sub's pool from full's (kappa, the F columns of PhitA, the F blocks of Xb and Gb,
/// kappa_next); full at nd = npool. Call after every fmbd_est_set_pool of full (extensions).
int fmbd_est_set_pool_subset(fmbd_est *sub, const fmbd_est *full, int64_t nfree,
                             const int64_t *free_idx);
/// @brief The modes of a body held at boundary dofs `held` (nheld indices into 0..nb-1):
/// Rayleigh-Ritz of the full reduced problem (nd + nb, full's current nd) on the span of the
/// held problem's first nm eigenvectors XiF ((nd + nfree) rows, leading dimension ldxi, zero on
/// the held rows once lifted) and the unit vectors of the held dofs (their constraint modes,
/// the static response to the joint reactions), M_-orthonormal, ascending, rigid-body modes
/// (|chibar| <= rigid_rtol kappa_1) removed.
/// @param[out] nout modes returned; chibar (nout), Xi ((nd + nb) x nout): caller frees both
int fmbd_est_held_modes(const fmbd_est *full, int64_t nheld, const int64_t *held, int64_t nm,
                        const double *XiF, int64_t ldxi, int64_t *nout, double **chibar,
                        double **Xi);

#endif
