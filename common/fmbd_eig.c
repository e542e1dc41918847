// common/fmbd_eig.c: lowest eigenpairs of K x = lambda M x (ARPACK shift-invert Lanczos)
// SPDX-License-Identifier: MIT
//
// See fmbd_eig.h for the method. ARPACK-NG 3.8 C wrappers (<arpack/arpack.h>), reverse
// communication, mode 3 (shift-invert), bmat 'G' (M inner product), which "LM":
// Lehoucq, Sorensen, Yang, ARPACK Users' Guide (SIAM 1998), section 4.2 and dsdrv4.f.
#include "fmbd_eig.h"

#include <arpack/arpack.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

void fmbd_eig_opts_defaults(fmbd_eig_opts *o) {
  memset(o, 0, sizeof *o);
  o->nev = 20;
  o->lambda_max = 0.0;
  o->free_body = false;
  o->tol = 1e-12;
  o->resid_tol = 1e-6;
  o->maxit = 500;
  o->max_passes = 4;
  o->sturm = true;
  o->ncv = 0;
  o->dense_max = 400;
  o->block = 0;
  const char *e = getenv("FMBD_EIG_BLOCK");
  if (e && *e) o->block = atoll(e);
}

void fmbd_eig_result_free(fmbd_eig_result *r) {
  if (!r) return;
  fmbd_free(r->lambda);
  fmbd_free(r->X);
  fmbd_free(r->resid);
  memset(r, 0, sizeof *r);
}

static double dot(int64_t n, const double *a, const double *b) {
  double s = 0.0;
  for (int64_t i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

// the relative residual from kx = K x and mx = M x (fmbd_eig_residual, check_normalise)
static double resid_of(int64_t n, const double *kx, const double *mx, double lambda, double scale) {
  double r = 0.0, nk = 0.0, nm = 0.0;
  for (int64_t i = 0; i < n; i++) {
    double d = kx[i] - lambda * mx[i];
    r += d * d;
    nk += kx[i] * kx[i];
    nm += mx[i] * mx[i];
  }
  double den = fmax(sqrt(nk), fabs(scale) * sqrt(nm));
  return den > 0.0 ? sqrt(r) / den : (r > 0.0 ? INFINITY : 0.0);
}

double fmbd_eig_residual(const fmbd_csr *K, const fmbd_csr *M, double lambda, const double *x,
                         double scale, double *work) {
  int64_t n = K->nrows;
  fmbd_csr_matvec(K, x, work);
  fmbd_csr_matvec(M, x, work + n);
  return resid_of(n, work, work + n, lambda, scale);
}

// The residuals of the nv pairs (columns of X, n x nv), scale_j = max(|sigma|, |lambda_j|),
// and their M-normalisation with the sign convention (largest-magnitude component positive),
// by blocks of 8 columns: fmbd_csr_matmat reads K and M once per block instead of once per
// vector (the check is memory-bound: 300 modes of the 51 k-dof rod spent 3 s in it one vector
// at a time). The residual is homogeneous of degree 0 in x, so it is taken before the scaling
// and the block's M X also gives x' M x: one product with M per vector for both (the
// normalisation had its own pass over M per 8 vectors: 0.3 s of 300 modes at 51 k dofs,
// bench/README.md). The scaled X is the same bits as when the normalisation came first.
static int check_normalise(const fmbd_csr *K, const fmbd_csr *M, int64_t nv, const double *lam,
                           double *X, double sigma, double *rs) {
  enum { NB = 8 };
  int64_t n = K->nrows;
  double *kx = fmbd_malloc((size_t)n * 2 * NB * sizeof(double));
  FMBD_CHECK(kx, FMBD_ERR_NOMEM, "out of memory");
  double *mx = kx + n * NB;
  for (int64_t j0 = 0; j0 < nv; j0 += NB) {
    int64_t nb = nv - j0 < NB ? nv - j0 : NB;
    fmbd_csr_matmat(K, nb, X + j0 * n, n, kx, n);
    fmbd_csr_matmat(M, nb, X + j0 * n, n, mx, n);
    for (int64_t j = 0; j < nb; j++) {
      double *x = X + (j0 + j) * n;
      rs[j0 + j] =
          resid_of(n, kx + j * n, mx + j * n, lam[j0 + j], fmax(fabs(sigma), fabs(lam[j0 + j])));
      double s = dot(n, x, mx + j * n);
      s = s > 0.0 ? 1.0 / sqrt(s) : 1.0;
      int64_t imax = 0;
      for (int64_t i = 1; i < n; i++) {
        if (fabs(x[i]) > fabs(x[imax])) imax = i;
      }
      if (x[imax] < 0.0) s = -s;
      for (int64_t i = 0; i < n; i++) x[i] = s * x[i];
    }
  }
  fmbd_free(kx);
  return FMBD_OK;
}

// --- one ARPACK run -----------------------------------------------------------------------
typedef struct run_out {
  int64_t nconv;
  double *lam;  // (nconv) owned
  double *X;    // n x nconv owned
  int64_t solves, restarts;
  double orth_loss;  // block runs: max |V'V - I| of the final basis, when measured (else NAN)
} run_out;

static void run_out_free(run_out *r) {
  fmbd_free(r->lam);
  fmbd_free(r->X);
  memset(r, 0, sizeof *r);
}

// Shift-invert Lanczos on OP = (K - sigma M)^-1 M with the factor F (factored at sigma).
// On FMBD_OK, out holds the converged pairs (maybe fewer than nreq: maxit reached).
static int arpack_run(const fmbd_csr *M, fmbd_chol *F, int64_t nreq, int64_t ncv, double tol,
                      int maxit, const fmbd_eig_opts *o, const double *v0, int64_t solves0,
                      run_out *out) {
  int rc = FMBD_OK;
  int64_t n = M->nrows;
  double *resid = NULL, *v = NULL, *workd = NULL, *workl = NULL, *d = NULL, *tmp = NULL;
  int *select = NULL;
  int threads = -1;
  memset(out, 0, sizeof *out);
  FMBD_CHECK(nreq >= 1 && nreq < n && ncv > nreq && ncv <= n, FMBD_ERR_INTERNAL,
             "bad Lanczos sizes nev %lld ncv %lld n %lld", (long long)nreq, (long long)ncv,
             (long long)n);
  FMBD_CHECK(n < 2147483647 && ncv * (ncv + 8) < 2147483647, FMBD_ERR_VALUE,
             "problem too large for ARPACK's 32-bit integers (n = %lld)", (long long)n);
  int lworkl = (int)(ncv * (ncv + 8));
  FMBD_GALLOC(resid = fmbd_malloc((size_t)n * sizeof(double)));
  FMBD_GALLOC(v = fmbd_malloc((size_t)n * (size_t)ncv * sizeof(double)));
  FMBD_GALLOC(workd = fmbd_malloc(3 * (size_t)n * sizeof(double)));
  FMBD_GALLOC(workl = fmbd_malloc((size_t)lworkl * sizeof(double)));
  FMBD_GALLOC(tmp = fmbd_malloc((size_t)n * sizeof(double)));
  a_int iparam[11] = {0}, ipntr[11] = {0}, ido = 0, info = 0;
  if (v0) {
    memcpy(resid, v0, (size_t)n * sizeof(double));  // info 1: resid is the start vector
    info = 1;
  }
  iparam[0] = 1;      // exact shifts
  iparam[2] = maxit;  // restarts
  iparam[6] = 3;      // mode 3: shift-invert, generalized
  int64_t solves = 0;
  double sigma = fmbd_chol_sigma(F);
  // one BLAS thread for the single-vector solves (see fmbd_blas_set_threads); ARPACK's own
  // orthogonalisation (dgemv on n x ncv) keeps the caller's threads
  threads = fmbd_blas_set_threads(0);
  for (;;) {
    dsaupd_c(&ido, "G", (a_int)n, "LM", (a_int)nreq, tol, resid, (a_int)ncv, v, (a_int)n, iparam,
             ipntr, workd, workl, lworkl, &info);
    double *x = workd + ipntr[0] - 1, *y = workd + ipntr[1] - 1;
    if (ido == -1 || ido == 1) {
      if (ido == -1) {
        fmbd_csr_matvec(M, x, y);  // y = (K - sigma M)^-1 M x
      } else {
        memcpy(y, workd + ipntr[2] - 1, (size_t)n * sizeof(double));  // M x given
      }
      if (threads > 1) fmbd_blas_set_threads(1);
      rc = fmbd_chol_solve(F, 1, y, n);
      if (threads > 1) fmbd_blas_set_threads(threads);
      FMBD_GCALL(rc);
      solves++;
    } else if (ido == 2) {
      fmbd_csr_matvec(M, x, y);
    } else {
      break;
    }
    if (o->progress && (solves & 15) == 0 && (ido == -1 || ido == 1)) {
      o->progress(o->progress_ctx, "Lanczos", solves0 + solves, nreq);
    }
  }
  out->solves = solves;
  out->restarts = iparam[2];
  if (info < 0) {
    FMBD_GFAIL(FMBD_ERR_CONVERGE,
               "ARPACK dsaupd failed with info %d (%lld of %lld eigenpairs converged, ncv %lld)",
               (int)info, (long long)iparam[4], (long long)nreq, (long long)ncv);
  }
  int64_t nconv = iparam[4];
  if (nconv <= 0) {
    rc = FMBD_OK;  // caller decides (retry with more vectors or fail with the count)
    goto done;
  }
  FMBD_GALLOC(select = fmbd_calloc((size_t)ncv, sizeof(int)));
  FMBD_GALLOC(d = fmbd_malloc((size_t)(nreq + 1) * sizeof(double)));
  FMBD_GALLOC(out->X = fmbd_malloc((size_t)n * (size_t)nreq * sizeof(double)));
  a_int einfo = 0;
  dseupd_c(1, "A", select, d, out->X, (a_int)n, sigma, "G", (a_int)n, "LM", (a_int)nreq, tol, resid,
           (a_int)ncv, v, (a_int)n, iparam, ipntr, workd, workl, lworkl, &einfo);
  if (einfo != 0) {
    FMBD_GFAIL(FMBD_ERR_CONVERGE,
               "ARPACK dseupd failed with info %d (%lld of %lld eigenpairs converged)", (int)einfo,
               (long long)nconv, (long long)nreq);
  }
  nconv = iparam[4];  // with info == 1 (maxit), only the converged ones are meaningful
  out->nconv = nconv;
  out->lam = d;
  d = NULL;
done:
  if (rc != 0) run_out_free(out);
  fmbd_free(resid);
  fmbd_free(v);
  fmbd_free(workd);
  fmbd_free(workl);
  fmbd_free(tmp);
  fmbd_free(select);
  fmbd_free(d);
  return rc;
}

// --- block Krylov-Schur run ----------------------------------------------------------------
// Thick-restart block Lanczos with full reorthogonalisation (the block form of Stewart's
// Krylov-Schur method: G. W. Stewart, "A Krylov-Schur algorithm for large eigenproblems",
// SIAM J. Matrix Anal. Appl. 23 (2001) 601-614; block shift-invert Lanczos: Grimes, Lewis,
// Simon, SIAM J. Matrix Anal. Appl. 15 (1994) 228-272). With the LL' factor of the shifted
// matrix, K - sigma M = P' L L' P, the problem is taken to the symmetric standard form
//   C z = theta z,  C = L^-1 P M P' L^-T,  theta = 1 / (lambda - sigma),  x = P' L^-T z
// (Ericsson and Ruhe, Math. Comp. 35 (1980) 1251-1268: the spectral transformation), so that
// the basis is orthonormal in the plain inner product: no M products in the
// orthogonalisation and no stored M V. Each expansion applies C to a block of p vectors: two
// half solves with p right-hand sides (BLAS-3 in the supernodal factor) and one sparse product
// with M, instead of p single-vector solves (memory-bound); the reorthogonalisation is
// matrix-matrix: block classical Gram-Schmidt, a local pass and one pass against the whole
// basis, a second only where Kahan-Parlett's test finds cancellation (bk_orth), Cholesky-QR
// inside the block, with modified Gram-Schmidt as the fallback for an ill-conditioned block.
// Relation kept: C V_m = V_m H_m + Q B, with [V_m Q] orthonormal, H_m = V_m' C V_m symmetric,
// B (p x m). Rayleigh-Ritz when the basis is full: H_m = S Theta S'; the residual of the Ritz
// pair (theta_i, V_m s_i) is ||B s_i||_2 (ARPACK's estimate), converged when <= tol theta_i
// (ARPACK's test). Restart: keep the k leading Ritz vectors and Q; H = diag(theta), B <- B S_k.
// Locking: the leading converged Ritz vectors stay in the basis (orthogonalised against, so
// never found twice) but leave the Rayleigh-Ritz and the restart product V S, which then
// costs n (m - nl) (k - nl) instead of n m k: with many wanted pairs most of them are locked
// long before the last restart.

// lcg: a fixed start block, so that results are reproducible run to run
static double lcg_next(uint64_t *s) {
  *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
  return (double)(*s >> 11) * (1.0 / 9007199254740992.0) - 0.5;
}

static double bk_dot(int64_t n, const double *a, const double *b) {
  double s = 0.0;
  for (int64_t i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

// One block classical Gram-Schmidt pass of W (n x p) against V (n x m, orthonormal);
// C (m x p, ldc) += the coefficients. T: m x p scratch.
static void bk_project(int64_t n, int64_t m, int64_t p, const double *V, double *W, double *C,
                       int64_t ldc, double *T) {
  if (m == 0) return;
  fmbd_dense_gemm('T', 'N', m, p, n, 1.0, V, n, W, n, 0.0, T, m);
  fmbd_dense_gemm('N', 'N', n, p, m, -1.0, V, n, T, m, 1.0, W, n);
  for (int64_t j = 0; j < p; j++) {
    for (int64_t i = 0; i < m; i++) C[i + j * ldc] += T[i + j * m];
  }
}

// Cholesky-QR: G = W' W = L L', W <- W L'^-1, R <- L' (upper). False, W untouched, when W is
// too ill-conditioned for it (a pivot below 1e-6 of the largest: cond(W) > 1e6 would leave
// more than 1e-4 of non-orthogonality, beyond what the second pass repairs); then bk_mgs.
// Work: p x p + rb x p.
static bool bk_cholqr(int64_t n, int64_t p, double *W, double *R, double *G, double *work,
                      int64_t rb) {
  fmbd_dense_gemm('T', 'N', p, p, n, 1.0, W, n, W, n, 0.0, G, p);
  double gmax = 0.0;
  for (int64_t j = 0; j < p; j++) gmax = fmax(gmax, G[j + j * p]);
  if (!(gmax > 0.0) || fmbd_dense_chol(p, G) != FMBD_OK) return false;
  for (int64_t j = 0; j < p; j++) {
    if (!(G[j + j * p] * G[j + j * p] > 1e-12 * gmax)) return false;
  }
  double *Li = work, *buf = work + p * p;  // Li = L'^-1 (upper), by columns: L' y = e_j
  memset(Li, 0, (size_t)(p * p) * sizeof(double));
  for (int64_t j = 0; j < p; j++) {
    for (int64_t i = j; i >= 0; i--) {
      double t = i == j ? 1.0 : 0.0;
      for (int64_t k = i + 1; k <= j; k++) t -= G[k + i * p] * Li[k + j * p];
      Li[i + j * p] = t / G[i + i * p];
    }
  }
  for (int64_t r0 = 0; r0 < n; r0 += rb) {
    int64_t nr = n - r0 < rb ? n - r0 : rb;
    fmbd_dense_gemm('N', 'N', nr, p, p, 1.0, W + r0, n, Li, p, 0.0, buf, nr);
    for (int64_t j = 0; j < p; j++)
      memcpy(W + r0 + j * n, buf + j * nr, (size_t)nr * sizeof(double));
  }
  for (int64_t j = 0; j < p; j++) {
    for (int64_t i = 0; i < p; i++) R[i + j * p] = i <= j ? G[j + i * p] : 0.0;
  }
  return true;
}

// Orthonormalise the columns of W in place by modified Gram-Schmidt with one
// reorthogonalisation inside the block: W_in = W_out R (R upper). A column whose norm falls
// below 1e-13 of ref[j] (its norm before the projections: the block has reached an invariant
// subspace) is replaced by a random vector orthogonal to V (n x m) and to the earlier columns,
// with R(j, j) = 0 (ARPACK's dgetv0 does the same for a single vector).
static void bk_mgs(int64_t n, int64_t m, int64_t p, const double *V, double *W, double *R,
                   const double *ref, uint64_t *seed, double *T) {
  memset(R, 0, (size_t)(p * p) * sizeof(double));
  for (int64_t j = 0; j < p; j++) {
    double *w = W + j * n;
    for (int rep = 0;; rep++) {
      for (int pass = 0; pass < 2; pass++) {
        for (int64_t i = 0; i < j; i++) {
          const double *q = W + i * n;
          double r = bk_dot(n, q, w);
          for (int64_t k = 0; k < n; k++) w[k] -= r * q[k];
          if (rep == 0) R[i + j * p] += r;
        }
      }
      double nrm = sqrt(bk_dot(n, w, w));
      if (nrm > 1e-13 * ref[j] && nrm > 0.0) {
        for (int64_t k = 0; k < n; k++) w[k] /= nrm;
        if (rep == 0) R[j + j * p] = nrm;
        break;
      }
      if (rep >= 3) break;  // cannot happen while m + p < n; keeps the loop finite
      // deflated: a random direction, projected twice against V, then the loop above
      for (int64_t k = 0; k < n; k++) w[k] = lcg_next(seed);
      for (int pass = 0; pass < 2 && m > 0; pass++) {
        fmbd_dense_gemm('T', 'N', m, 1, n, 1.0, V, n, w, n, 0.0, T, m);
        fmbd_dense_gemm('N', 'N', n, 1, m, -1.0, V, n, T, m, 1.0, w, n);
      }
    }
  }
}

// W (= C Q) -> the next block: W_in = V C + W_out R with W_out orthonormal and orthogonal to
// V (n x m). Block Gram-Schmidt in up to three passes, each a pair of matrix-matrix products:
//  1. a local pass against columns lo..m-1 of V, the part of the basis that C Q has large
//     components on (the block Q and the one before it; after a restart every active kept
//     Ritz vector and Q). Against every other column the components of C Q are small: in exact
//     arithmetic zero (Lanczos' three-term recurrence), in floating point of the order of the
//     basis' loss of orthogonality times ||C|| (Paige's analysis of the Lanczos process).
//  2. a global pass against all of V: it removes those small components and the round-off of
//     the local pass, eps ||W_in|| spread over every direction, without cancellation.
//  3. only when the global pass has cancelled: Kahan's and Parlett's "twice is enough" test
//     (B. N. Parlett, The Symmetric Eigenvalue Problem, SIAM 1998, section 6.9), in block form.
//     Column j of the block, Gram-Schmidt-orthogonalised against V and the earlier columns,
//     keeps R(j, j) of its norm before the global pass, nloc_j (R from Cholesky-QR); when
//     R(j, j) >= nloc_j / sqrt(2) for every j, one global pass has left the block orthogonal
//     to V to the round-off of that pass, a few eps nloc_j / R(j, j) <= a few sqrt(2) eps,
//     and a second pass cannot improve it; otherwise (a column has lost more than 1 - 1/sqrt(2)
//     of its norm to V or to the block: cancellation) the global pass and the Cholesky-QR are
//     repeated (BCGS2: Barlow and Smoktunowicz, Numer. Math. 123 (2013) 395-423).
// After one global pass the block is made orthonormal by Cholesky-QR twice (CholQR2: the first
// leaves eps cond(W)^2 of non-orthogonality inside the block, the second removes it at the
// cost of a p x p Gram matrix, n p^2 flops against the n m p of a global pass).
// With m = 0 (the start block) only the Cholesky-QR passes run. Returns the number of global
// passes (1 or 2). C (m x p, ldc) is overwritten. Work: T (m x p), C2 (m x p), R2, G (p x p),
// ref, nloc (p), work (p x p + rb x p).
static int bk_orth(int64_t n, int64_t m, int64_t lo, int64_t p, const double *V, double *W,
                   double *C, int64_t ldc, double *R, double *R2, double *G, double *C2, double *T,
                   double *ref, double *nloc, uint64_t *seed, double *work, int64_t rb) {
  for (int64_t j = 0; j < p; j++) {
    memset(C + j * ldc, 0, (size_t)m * sizeof(double));
    ref[j] = sqrt(bk_dot(n, W + j * n, W + j * n));
  }
  if (m > 0 && lo < m) bk_project(n, m - lo, p, V + lo * n, W, C + lo, ldc, T);
  for (int64_t j = 0; j < p; j++) nloc[j] = sqrt(bk_dot(n, W + j * n, W + j * n));
  bk_project(n, m, p, V, W, C, ldc, T);
  bool one = false;
  if (bk_cholqr(n, p, W, R, G, work, rb)) {
    one = true;
    for (int64_t j = 0; j < p; j++) one = one && R[j + j * p] * sqrt(2.0) >= nloc[j];
  } else {
    bk_mgs(n, m, p, V, W, R, ref, seed, T);
  }
  for (int64_t j = 0; j < p; j++) ref[j] = 1.0;
  int passes = 1;
  if (one) {
    if (!bk_cholqr(n, p, W, R2, G, work, rb)) bk_mgs(n, m, p, V, W, R2, ref, seed, T);
  } else {
    passes = 2;
    memset(C2, 0, (size_t)((m ? m : 1) * p) * sizeof(double));
    bk_project(n, m, p, V, W, C2, m ? m : 1, T);
    if (!bk_cholqr(n, p, W, R2, G, work, rb)) bk_mgs(n, m, p, V, W, R2, ref, seed, T);
    if (m > 0) fmbd_dense_gemm('N', 'N', m, p, p, 1.0, C2, m, R, p, 1.0, C, ldc);
  }
  fmbd_dense_gemm('N', 'N', p, p, p, 1.0, R2, p, R, p, 0.0, G, p);
  memcpy(R, G, (size_t)(p * p) * sizeof(double));
  return m > 0 ? passes : 0;
}

// the least basis of a block run is nreq + bk_min_blocks(p) p (block_run)
static int64_t bk_min_blocks(int64_t p) {
  return p < 16 ? 8 : 6;
}

static int block_run(const fmbd_csr *M, fmbd_chol *F, int64_t nreq, int64_t nstrict, int64_t ncv,
                     int64_t p, double tol, int maxit, const fmbd_eig_opts *o, const double *v0,
                     int64_t solves0, run_out *out) {
  int rc = FMBD_OK;
  int64_t n = M->nrows;
  double sigma = fmbd_chol_sigma(F);
  memset(out, 0, sizeof *out);
  out->orth_loss = NAN;
  // basis: at most mmax columns with H known, plus the block Q; mmax >= nreq + 6p, so that a
  // restart keeps the wanted Ritz vectors and still adds several blocks (with nreq + 2p, one
  // block per restart: 60 modes of the 51 k-dof rod took 4856 solves instead of 274)
  // (narrow blocks, below 16: nreq + 8p; 20 modes of that rod: 88 -> 84 solves, 40 modes 156
  // -> 148, 50 modes 200 either way, for 8 n doubles more)
  int64_t mmax = ncv;
  if (mmax < nreq + bk_min_blocks(p) * p) mmax = nreq + bk_min_blocks(p) * p;
  // the margin pairs (ranks nstrict..nreq-1: fmbd_eig_solve's extra wanted pairs beyond the
  // caller's count) only place the Sturm shift and give next_lambda: located to a relative
  // 1e-8 (a Ritz value theta with ||B s|| <= 1e-8 theta has an eigenvalue within 1e-8 theta:
  // the residual bound of symmetric matrices, Parlett, The Symmetric Eigenvalue Problem,
  // chapter 4), far inside the 1e-6 relative gap the shift needs on either side (fmbd_eig_solve,
  // fmbd_eig_sturm_check), so a shift midway cannot pass over them; a missed eigenvalue is the
  // Sturm count's to find, as before. The last of 23 pairs to 1e-12 took 104 solves at 20 modes of
  // the 51 k-dof rod, with the 3 margin pairs to 1e-8 88 (bench/README.md "Fewer and cheaper
  // Lanczos solves").
  double tol_x = fmax(tol, 1e-8);
  // Rayleigh-Ritz (and the convergence test) after every block, not only when the basis is
  // full, where it costs little against the block's solve: 9 ma^3 flops for the eigenvectors
  // of the ma x ma projected matrix against 4 p nnz(L) for the two half solves with p columns
  // (at most 2 %); the run then stops at the first block at which every wanted pair has
  // converged instead of at the end of the restart cycle (20 modes of the 51 k-dof rod: 92 ->
  // 88 solves). Deterministic (counts, not times), so the results do not vary run to run.
  fmbd_chol_stats cst;
  fmbd_chol_get_stats(F, &cst);
  const double rr_budget = 0.02 * 4.0 * (double)p * cst.nnz_l;
  FMBD_CHECK(p >= 1 && nreq >= 1 && mmax + p <= n, FMBD_ERR_INTERNAL,
             "bad block Lanczos sizes nev %lld basis %lld block %lld n %lld", (long long)nreq,
             (long long)mmax, (long long)p, (long long)n);
  int64_t cap = mmax + p, ldh = mmax + 2 * p;
  const int64_t rb = 2048;  // row chunk of the in-place products
  double *V = NULL, *H = NULL, *S = NULL, *th = NULL, *C = NULL, *T = NULL, *R = NULL, *R2 = NULL,
         *G = NULL, *C2 = NULL, *ref = NULL, *B = NULL, *tmp = NULL, *Y = NULL, *thl = NULL,
         *nloc = NULL;
  int64_t *ord = NULL;
  FMBD_GALLOC(V = fmbd_malloc((size_t)n * (size_t)cap * sizeof(double)));
  FMBD_GALLOC(Y = fmbd_malloc((size_t)n * (size_t)p * sizeof(double)));
  FMBD_GALLOC(H = fmbd_calloc((size_t)(ldh * ldh), sizeof(double)));
  FMBD_GALLOC(S = fmbd_malloc((size_t)(mmax * mmax) * sizeof(double)));
  FMBD_GALLOC(th = fmbd_malloc((size_t)mmax * sizeof(double)));
  FMBD_GALLOC(thl = fmbd_malloc((size_t)mmax * sizeof(double)));
  FMBD_GALLOC(C = fmbd_malloc((size_t)(ldh * p) * sizeof(double)));
  FMBD_GALLOC(T = fmbd_malloc((size_t)(ldh * p) * sizeof(double)));
  FMBD_GALLOC(C2 = fmbd_malloc((size_t)(ldh * p) * sizeof(double)));
  FMBD_GALLOC(R = fmbd_malloc((size_t)(p * p) * sizeof(double)));
  FMBD_GALLOC(R2 = fmbd_malloc((size_t)(p * p) * sizeof(double)));
  FMBD_GALLOC(G = fmbd_malloc((size_t)(p * p) * sizeof(double)));
  FMBD_GALLOC(ref = fmbd_malloc((size_t)p * sizeof(double)));
  FMBD_GALLOC(nloc = fmbd_malloc((size_t)p * sizeof(double)));
  FMBD_GALLOC(B = fmbd_malloc((size_t)(p * mmax) * sizeof(double)));
  FMBD_GALLOC(ord = fmbd_malloc((size_t)mmax * sizeof(int64_t)));
  FMBD_GALLOC(tmp = fmbd_malloc(((size_t)rb * (size_t)mmax + (size_t)(p * p)) * sizeof(double)));
  uint64_t seed = 0x9e3779b97f4a7c15ULL;
  // start: Q = a random orthonormal block at columns 0..p-1
  int64_t m = 0;
  for (int64_t i = 0; i < n * p; i++) V[i] = lcg_next(&seed);
  if (v0) {
    // the caller's start vector as the first column: z = L^-1 P M v0, i.e. x = OP v0 (in the
    // range of OP, as ARPACK's dgetv0 makes its start vector)
    fmbd_csr_matvec(M, v0, V);
    FMBD_GCALL(fmbd_chol_solve_half(F, FMBD_CHOL_FWD, 1, V, n));
  }
  bk_orth(n, 0, 0, p, V, V, C, 1, R, R2, G, C2, T, ref, nloc, &seed, tmp, rb);
  int64_t solves = 0, restarts = 0, nconv = 0, nl = 0;  // nl: locked columns 0..nl-1 of V
  int64_t m_rs = 0;                                     // m after the last restart (0: none yet)
  int64_t n_orth1 = 0, n_orth2 = 0;  // blocks orthogonalised with one / two global passes
  double t_op = 0.0, t_mprod = 0.0, t_orth = 0.0, t_rr = 0.0, t_restart = 0.0;
  for (;;) {
    // --- expand by one block ---
    {
      double *W = V + (m + p) * n;
      double ta = fmbd_wall_s();
      // W = C Q = L^-1 P M P' L^-T Q; narrow blocks solve on one BLAS thread, as the
      // single-vector path does (their triangular solves are memory-bound: a second thread
      // only spins; 51 k dofs, 20 modes, blocks of 4: 3.0 s CPU on 2 threads, see bench/README.md)
      // (fmbd_chol_apply_op: the halves and the M product in one call)
      int th1 = p < 16 ? fmbd_blas_set_threads(1) : -1;
      rc = fmbd_chol_apply_op(F, M, p, V + m * n, n, W, n, Y, &t_mprod);
      if (th1 > 1) fmbd_blas_set_threads(th1);
      FMBD_GCALL(rc);
      solves += p;
      double tb = fmbd_wall_s();
      t_op += tb - ta;
      if (o->progress) o->progress(o->progress_ctx, "Lanczos", solves0 + solves, nreq);
      // coefficients against the whole basis [V_m Q] -> column block m..m+p-1 of H; the local
      // pass runs against Q and the block before it, or after a restart against every active
      // column (C Q couples to all kept Ritz vectors through B)
      int64_t mq = m + p, lo = m == m_rs ? nl : m - p;
      int np = bk_orth(n, mq, lo, p, V, W, C, mq, R, R2, G, C2, T, ref, nloc, &seed, tmp, rb);
      if (np == 1) n_orth1++;
      if (np == 2) n_orth2++;
      t_orth += fmbd_wall_s() - tb;
      for (int64_t j = 0; j < p; j++) {
        for (int64_t i = 0; i < mq; i++) H[i + (m + j) * ldh] = C[i + j * mq];
        for (int64_t i = 0; i < p; i++) H[mq + i + (m + j) * ldh] = i <= j ? R[i + j * p] : 0.0;
      }
      m += p;
    }
    bool full = m + p > mmax;
    int64_t ma = m - nl;
    if (!full && !(ma >= nreq - nl && 9.0 * (double)ma * (double)ma * (double)ma <= rr_budget))
      continue;
    // --- Rayleigh-Ritz on the symmetric part of the active block H[nl.., nl..] ---
    double tc = fmbd_wall_s();
    for (int64_t j = 0; j < ma; j++) {
      for (int64_t i = 0; i < ma; i++) {
        S[i + j * ma] = 0.5 * (H[nl + i + (nl + j) * ldh] + H[nl + j + (nl + i) * ldh]);
      }
    }
    FMBD_GCALL(fmbd_dense_syev(ma, S, th));
    // descending theta (lowest lambda first): reverse the column order
    for (int64_t j = 0; j < ma / 2; j++) {
      double t = th[j];
      th[j] = th[ma - 1 - j];
      th[ma - 1 - j] = t;
      for (int64_t i = 0; i < ma; i++) {
        double u = S[i + j * ma];
        S[i + j * ma] = S[i + (ma - 1 - j) * ma];
        S[i + (ma - 1 - j) * ma] = u;
      }
    }
    // B S: the residual coupling of each active Ritz vector; B = H[m..m+p-1, nl..m-1]
    for (int64_t j = 0; j < ma; j++) {
      for (int64_t i = 0; i < p; i++) tmp[i + j * p] = H[m + i + (nl + j) * ldh];
    }
    fmbd_dense_gemm('N', 'N', p, ma, ma, 1.0, tmp, p, S, ma, 0.0, B, p);
    int64_t nwa = nreq - nl < ma ? nreq - nl : ma;  // wanted among the active
    nconv = 0;
    for (int64_t j = 0; j < nwa; j++) {
      double r = 0.0;
      for (int64_t i = 0; i < p; i++) r += B[i + j * p] * B[i + j * p];
      if (sqrt(r) <= (nl + j < nstrict ? tol : tol_x) * fabs(th[j])) ord[nconv++] = j;
    }
    if (!full && nl + nconv < nreq) {
      t_rr += fmbd_wall_s() - tc;
      continue;
    }
    restarts++;
    double td = fmbd_wall_s();
    t_rr += td - tc;
    fmbd_log(FMBD_LOG_DEBUG,
             "eig: block Lanczos restart %lld: %lld locked + %lld converged of %lld (%lld solves)",
             (long long)restarts, (long long)nl, (long long)nconv, (long long)nreq,
             (long long)solves);
    if (nl + nconv >= nreq || restarts > maxit) break;
    // --- locking: the leading converged active Ritz pairs (largest theta, contiguous) stay in
    // the basis as columns nl.. and leave the Rayleigh-Ritz and restart products (their
    // coupling to the rest, ||B s_i|| <= tol theta_i, is dropped: the usual deflation of
    // converged Ritz pairs; Stewart 2001, section 3; ARPACK's dsaupd locks the same way).
    // The orthogonalisation still runs against them, so no pair is found twice.
    int64_t nlock = 0;
    while (nlock < nconv && ord[nlock] == nlock) nlock++;
    // --- thick restart: keep k columns in all (the locked, the wanted active Ritz vectors and
    // half the rest) and Q ---
    int64_t k = nreq + (mmax - nreq - p) / 2;
    if (k > m - p) k = m - p;
    if (k < nreq) k = nreq;
    int64_t ka = k - nl;  // active Ritz vectors kept: V[:, nl..k-1] = V[:, nl..m-1] S[:, 0..ka-1]
    for (int64_t r0 = 0; r0 < n; r0 += rb) {
      int64_t nr = n - r0 < rb ? n - r0 : rb;
      fmbd_dense_gemm('N', 'N', nr, ka, ma, 1.0, V + nl * n + r0, n, S, ma, 0.0, tmp, nr);
      for (int64_t j = 0; j < ka; j++)
        memcpy(V + (nl + j) * n + r0, tmp + j * nr, (size_t)nr * sizeof(double));
    }
    memmove(V + k * n, V + m * n, (size_t)(n * p) * sizeof(double));
    memset(H, 0, (size_t)(ldh * ldh) * sizeof(double));
    for (int64_t j = 0; j < ka; j++) {
      int64_t c = nl + j;
      H[c + c * ldh] = th[j];
      if (j >= nlock) {
        for (int64_t i = 0; i < p; i++) H[k + i + c * ldh] = B[i + j * p];
      }
    }
    for (int64_t j = 0; j < nlock; j++) thl[nl + j] = th[j];
    nl += nlock;
    m = k;
    m_rs = k;
    t_restart += fmbd_wall_s() - td;
  }
  fmbd_log(FMBD_LOG_DEBUG,
           "eig: block Lanczos (block %lld, basis %lld): %lld solves, %lld restarts, %lld locked, "
           "operator %.3g s (M products %.3g s), orthogonalisation %.3g s (%lld blocks with one "
           "global pass, %lld with two), Rayleigh-Ritz %.3g s, restarts %.3g s",
           (long long)p, (long long)mmax, (long long)solves, (long long)restarts, (long long)nl,
           t_op, t_mprod, t_orth, (long long)n_orth1, (long long)n_orth2, t_rr, t_restart);
  if (fmbd_log_level() >= FMBD_LOG_DEBUG || o->orth_check) {
    // loss of orthogonality of the final basis [V_m Q]: max |(V' V - I)_ij| (m^2 n flops: a
    // few percent of the run, so only on request)
    int64_t mq = m + p;
    double *Gm = fmbd_malloc((size_t)(mq * mq) * sizeof(double));
    FMBD_GCHECK(Gm, FMBD_ERR_NOMEM, "out of memory");
    fmbd_dense_gemm('T', 'N', mq, mq, n, 1.0, V, n, V, n, 0.0, Gm, mq);
    double w = 0.0;
    for (int64_t j = 0; j < mq; j++) {
      for (int64_t i = 0; i < mq; i++) w = fmax(w, fabs(Gm[i + j * mq] - (i == j ? 1.0 : 0.0)));
    }
    fmbd_free(Gm);
    out->orth_loss = w;
    fmbd_log(FMBD_LOG_DEBUG, "eig: block Lanczos basis of %lld vectors: max |V'V - I| = %.2g",
             (long long)mq, w);
  }
  // --- the locked and the converged active pairs: x = P' L^-T V_l, P' L^-T V_a s, made in
  // the basis' own storage (the locked vectors are its leading columns; V_a s by row chunks
  // into the columns after them, as the restart does), which then shrinks to the nout modes:
  // no second copy of the modes beside the basis (1,000 modes of 188 k dofs: 1.5 GB)
  out->solves = solves;
  out->restarts = restarts;
  int64_t nout = nl + nconv;
  double te = fmbd_wall_s();
  if (nout > 0) {
    int64_t ma = m - nl;
    FMBD_GALLOC(out->lam = fmbd_malloc((size_t)(nout + 1) * sizeof(double)));
    for (int64_t j = 0; j < nl; j++) out->lam[j] = sigma + 1.0 / thl[j];
    for (int64_t j = 0; j < nconv; j++) {
      out->lam[nl + j] = sigma + 1.0 / th[ord[j]];
      if (ord[j] != j) memcpy(S + j * ma, S + ord[j] * ma, (size_t)ma * sizeof(double));
    }
    for (int64_t r0 = 0; r0 < n && nconv > 0; r0 += rb) {
      int64_t nr = n - r0 < rb ? n - r0 : rb;
      fmbd_dense_gemm('N', 'N', nr, nconv, ma, 1.0, V + nl * n + r0, n, S, ma, 0.0, tmp, nr);
      for (int64_t j = 0; j < nconv; j++)
        memcpy(V + (nl + j) * n + r0, tmp + j * nr, (size_t)nr * sizeof(double));
    }
    double *X = fmbd_realloc(V, (size_t)n * (size_t)nout * sizeof(double));
    FMBD_GCHECK(X, FMBD_ERR_NOMEM, "out of memory");
    V = NULL;
    out->X = X;
    double tb = fmbd_wall_s();
    // the basis has shrunk from cap to nout columns: CHOLMOD's two n x w solve workspaces may
    // take half the difference without raising the run's peak, where the caller asked for
    // narrower calls (fe2cb below 60 modes: 8); in the fewest calls, of equal widths (23
    // vectors: 12 + 11 instead of 8 + 8 + 7, backward half of the 51 k-dof rod 58 against
    // 73 ms; each column's result may change at round-off with the width)
    // (given back right after: the residual check follows, with its own blocks). The own
    // solve's one n x w workspace takes all of them in one pass where it can (AVX-512: up to
    // 24 columns) and where the freed columns hold it: the factor streamed once (23 vectors at
    // 51 k dofs: one pass instead of 12 + 11, the same bits: bench/README.md "The Ritz
    // vectors' back solve in one pass")
    int64_t w0 = fmbd_chol_solve_width(F), wb = (cap - nout) / 2;
    int64_t wo = fmbd_chol_own_width(F);
    bool one = w0 > 0 && nout > w0 && nout <= wo && nout + 3 <= cap - nout;
    bool wide = w0 > 0 && (one || wb > w0) && nout > w0;
    if (one) {
      fmbd_chol_set_solve_width(F, nout);
    } else if (wide) {
      int64_t calls = (nout + wb - 1) / wb;
      fmbd_chol_set_solve_width(F, (nout + calls - 1) / calls);
    }
    rc = fmbd_chol_solve_half(F, FMBD_CHOL_BWD, nout, out->X, n);
    if (wide) {
      fmbd_chol_set_solve_width(F, w0);
      fmbd_chol_release_workspace(F);
    }
    FMBD_GCALL(rc);
    out->nconv = nout;
    fmbd_log(FMBD_LOG_DEBUG, "eig: %lld Ritz vectors %.3g s (of it the back solve %.3g s)",
             (long long)nout, fmbd_wall_s() - te, fmbd_wall_s() - tb);
  }
done:
  if (rc != 0) run_out_free(out);
  fmbd_free(V);
  fmbd_free(Y);
  fmbd_free(H);
  fmbd_free(S);
  fmbd_free(th);
  fmbd_free(thl);
  fmbd_free(C);
  fmbd_free(T);
  fmbd_free(C2);
  fmbd_free(R);
  fmbd_free(R2);
  fmbd_free(G);
  fmbd_free(ref);
  fmbd_free(nloc);
  fmbd_free(B);
  fmbd_free(ord);
  fmbd_free(tmp);
  return rc;
}

// sort the pairs ascending, moving the columns of X in place (cycles of the permutation, one
// spare vector: no second copy of the modes); check_normalise M-normalises the kept ones
typedef struct idx_val {
  double v;
  int64_t i;
} idx_val;
static int cmp_idx_val(const void *a, const void *b) {
  double x = ((const idx_val *)a)->v, y = ((const idx_val *)b)->v;
  return (x > y) - (x < y);
}

static int sort_pairs(int64_t n, run_out *r) {
  int rc = FMBD_OK;
  int64_t k = r->nconv;
  idx_val *iv = NULL;
  double *lam2 = NULL, *t = NULL;
  FMBD_GALLOC(iv = fmbd_malloc((size_t)(k ? k : 1) * sizeof *iv));
  FMBD_GALLOC(lam2 = fmbd_malloc((size_t)(k + 1) * sizeof(double)));
  for (int64_t j = 0; j < k; j++) iv[j] = (idx_val){r->lam[j], j};
  qsort(iv, (size_t)k, sizeof *iv, cmp_idx_val);
  for (int64_t j = 0; j < k; j++) lam2[j] = iv[j].v;
  FMBD_GALLOC(t = fmbd_malloc((size_t)(n ? n : 1) * sizeof(double)));
  for (int64_t j = 0; j < k; j++) {
    // column j receives old column iv[j].i; done entries are marked with i = -1
    if (iv[j].i < 0 || iv[j].i == j) continue;
    memcpy(t, r->X + j * n, (size_t)n * sizeof(double));
    int64_t c = j;
    while (iv[c].i != j) {
      int64_t src = iv[c].i;
      memcpy(r->X + c * n, r->X + src * n, (size_t)n * sizeof(double));
      iv[c].i = -1;
      c = src;
    }
    memcpy(r->X + c * n, t, (size_t)n * sizeof(double));
    iv[c].i = -1;
  }
  fmbd_free(r->lam);
  r->lam = lam2;
  lam2 = NULL;
done:
  fmbd_free(iv);
  fmbd_free(lam2);
  fmbd_free(t);
  return rc;
}

// --- dense path -----------------------------------------------------------------------------
static int csr_to_dense(const fmbd_csr *A, double *D) {
  int64_t n = A->nrows;
  memset(D, 0, (size_t)n * (size_t)n * sizeof(double));
  for (int64_t i = 0; i < n; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      D[i + A->indices[p] * n] = A->data[p];
      if (A->lower) D[A->indices[p] + i * n] = A->data[p];  // fmbd_csr_keep_lower storage
    }
  }
  return FMBD_OK;
}

static int solve_dense(const fmbd_csr *K, const fmbd_csr *M, run_out *out) {
  int rc = FMBD_OK;
  int64_t n = K->nrows;
  double *A = NULL, *B = NULL, *w = NULL;
  memset(out, 0, sizeof *out);
  FMBD_GALLOC(A = fmbd_malloc((size_t)n * (size_t)n * sizeof(double)));
  FMBD_GALLOC(B = fmbd_malloc((size_t)n * (size_t)n * sizeof(double)));
  FMBD_GALLOC(w = fmbd_malloc((size_t)(n + 1) * sizeof(double)));
  csr_to_dense(K, A);
  csr_to_dense(M, B);
  FMBD_GCALL(fmbd_dense_sygv(n, A, B, w));
  out->nconv = n;
  out->lam = w;
  out->X = A;
  w = A = NULL;
done:
  fmbd_free(A);
  fmbd_free(B);
  fmbd_free(w);
  return rc;
}

static int64_t auto_ncv(int64_t n, int64_t nreq) {
  // nev + max(20, nev/2): on the 51 k-dof rod with 100 modes, 351 solves against 350 with
  // 2 nev + 1 (ARPACK's usual advice), and 20 MB less; beyond 2 GB of basis use nev + nev/4
  int64_t ncv = nreq + (nreq / 2 > 20 ? nreq / 2 : 20);
  if ((double)n * (double)ncv * 8.0 > 2e9) {
    int64_t lean = nreq + (nreq / 4 > 20 ? nreq / 4 : 20);
    if (lean < ncv) ncv = lean;
  }
  if (ncv > n) ncv = n;
  return ncv;
}

// block size of a Lanczos pass (0: ARPACK, single vector). Auto (o->block == 0): blocks of 16
// from 60 wanted pairs on; below that blocks of 4 on bodies of 10,000 dofs and more, ARPACK on
// smaller ones (bench/README.md, fe2cb section: at 20 modes blocks of 4 need 104 solves against
// ARPACK's 100 but read the factor a quarter as often: Lanczos CPU -25 to -35 % at 12.7 k,
// 51 k and 188 k dofs; blocks of 16 need twice the solves and lose below 60 pairs)
static int64_t block_size(const fmbd_eig_opts *o, int64_t n, int64_t nreq, int64_t ncv) {
  int64_t p = o->block;
  if (p == 0) p = nreq >= 60 ? 16 : (n >= 10000 ? 4 : 1);
  if (p <= 1) return 0;
  int64_t mb = nreq + bk_min_blocks(p) * p, mmax = ncv > mb ? ncv : mb;  // as in block_run
  return mmax + p <= n ? p : 0;  // nearly all of a small problem: ARPACK
}

double fmbd_eig_spectrum_scale(const fmbd_csr *K, const fmbd_csr *M) {
  double s = 0.0;
  for (int64_t i = 0; i < K->nrows; i++) {
    double k = fmbd_csr_get(K, i, i), m = fmbd_csr_get(M, i, i);
    if (m > 0.0 && k / m > s) s = k / m;
  }
  return s;
}

int fmbd_eig_solve(const fmbd_csr *K, const fmbd_csr *M, fmbd_chol *F, const fmbd_eig_opts *oin,
                   fmbd_eig_result *res) {
  int rc = FMBD_OK;
  fmbd_eig_opts o;
  if (oin) {
    o = *oin;
  } else {
    fmbd_eig_opts_defaults(&o);
  }
  memset(res, 0, sizeof *res);
  res->next_lambda = NAN;
  res->sturm_shift = NAN;
  res->sturm_count = -1;
  res->orth_loss = NAN;
  int64_t n = K->nrows;
  res->n = n;
  fmbd_chol *own = NULL, *ldl = NULL;
  run_out r = {0};
  double *work = NULL;
  bool bound = o.lambda_max > 0.0;
  FMBD_CHECK(K->ncols == n && M->nrows == n && M->ncols == n, FMBD_ERR_VALUE,
             "K (%lld x %lld) and M (%lld x %lld) are not square of one size", (long long)K->nrows,
             (long long)K->ncols, (long long)M->nrows, (long long)M->ncols);
  FMBD_CHECK(n >= 1, FMBD_ERR_VALUE, "empty eigenproblem");
  if (!bound) {
    FMBD_CHECK(o.nev >= 1, FMBD_ERR_VALUE, "number of modes %lld must be at least 1",
               (long long)o.nev);
    FMBD_CHECK(o.nev <= n, FMBD_ERR_VALUE,
               "%lld modes asked for, but the problem has only %lld dofs", (long long)o.nev,
               (long long)n);
  }
  if (o.nev < 1) o.nev = 20;
  FMBD_CHECK(o.tol > 0.0, FMBD_ERR_VALUE,
             "ARPACK tol must be positive (docs/TOOLCHAIN.md gotcha 11)");
  FMBD_CHECK(K->data || (o.need_k && F && !o.sturm && !o.free_body && n > o.dense_max &&
                         (bound || o.nev + 2 < n)),
             FMBD_ERR_INTERNAL, "K's values released, but the path reads them before need_k");
  FMBD_GALLOC(work = fmbd_malloc(2 * (size_t)n * sizeof(double)));
  // --- small problems: dense LAPACK, complete by construction ---------------------------------
  if (n <= o.dense_max || (!bound && o.nev + 2 >= n)) {
    double t0 = fmbd_wall_s();
    rc = solve_dense(K, M, &r);
    if (rc == FMBD_ERR_SINGULAR && n > o.dense_max) {
      // M only semi-definite (massless dofs): LAPACK cannot, and nev is too close to n for
      // Lanczos
      FMBD_GFAIL(FMBD_ERR_VALUE,
                 "%lld modes asked for, but the problem has %lld dofs and a "
                 "singular mass matrix",
                 (long long)o.nev, (long long)n);
    }
    FMBD_GCALL(rc);
    res->dense = true;
    res->t_lanczos_s = fmbd_wall_s() - t0;
    int64_t keep = 0;
    if (bound) {
      while (keep < r.nconv && r.lam[keep] <= o.lambda_max) keep++;
    } else {
      keep = o.nev;
    }
    res->next_lambda = keep < r.nconv ? r.lam[keep] : NAN;
    // sign convention as the sparse path
    for (int64_t j = 0; j < keep; j++) {
      double *x = r.X + j * n;
      int64_t imax = 0;
      for (int64_t i = 1; i < n; i++) {
        if (fabs(x[i]) > fabs(x[imax])) imax = i;
      }
      if (x[imax] < 0.0) {
        for (int64_t i = 0; i < n; i++) x[i] = -x[i];
      }
    }
    res->nev = keep;
    FMBD_GALLOC(res->resid = fmbd_malloc((size_t)(keep ? keep : 1) * sizeof(double)));
    double t1 = fmbd_wall_s();
    double top = fabs(fmbd_eig_spectrum_scale(K, M)), scale = top * 1e-12;
    for (int64_t j = 0; j < keep; j++) {
      double sj = fmax(fabs(r.lam[j]), scale);
      res->resid[j] = fmbd_eig_residual(K, M, r.lam[j], r.X + j * n, sj, work);
      // enforced as on the sparse path: the accepted residual, or the attainable one of a
      // backward-stable solver, 1e3 eps lambda_top / lambda (relative to ||K x||)
      double lim = fmax(o.resid_tol, 1e3 * 2.2e-16 * top / sj);
      FMBD_GCHECK(res->resid[j] <= lim, FMBD_ERR_CONVERGE,
                  "dense eigensolution (LAPACK dsygvd, %lld dofs): pair %lld (lambda %.6g) has "
                  "relative residual %.2g > %.1g",
                  (long long)n, (long long)j + 1, r.lam[j], res->resid[j], lim);
    }
    res->t_check_s = fmbd_wall_s() - t1;
    res->lambda = r.lam;
    res->X = r.X;
    r.lam = r.X = NULL;
    goto done;
  }

  // --- the factor and its shift (docs/THEORY.md section 8)
  // -------------------------------------------
  fmbd_chol *op = F;
  if (o.free_body || !F) {
    double t0 = fmbd_wall_s();
    FMBD_GCALL(fmbd_chol_analyze(K, M, FMBD_CHOL_LLT, &own));
    if (!o.free_body) {
      FMBD_GCALL(fmbd_chol_factor(own, 0.0));
      res->sigma = 0.0;
    } else {
      double scale = fmbd_eig_spectrum_scale(K, M);
      FMBD_GCHECK(scale > 0.0, FMBD_ERR_VALUE, "stiffness or mass matrix has no positive diagonal");
      double sigma0 = -1e-6 * scale;
      FMBD_GCALL(fmbd_chol_factor(own, sigma0));
      res->t_factor_s += fmbd_wall_s() - t0;
      // cheap estimate pass: 12 pairs (6 rigid + 6 flexible), loose tolerance
      int64_t ne = n - 2 < 12 ? n - 2 : 12;
      double t1 = fmbd_wall_s();
      FMBD_GCALL(arpack_run(M, own, ne, auto_ncv(n, ne), 1e-8, o.maxit, &o, NULL, 0, &r));
      res->t_lanczos_s += fmbd_wall_s() - t1;
      res->passes++;
      res->n_solves += r.solves;
      res->n_restarts += r.restarts;
      double top = 0.0, lf = 0.0;
      for (int64_t j = 0; j < r.nconv; j++) top = fmax(top, r.lam[j]);
      for (int64_t j = 0; j < r.nconv; j++) {
        if (r.lam[j] > 1e-6 * top && (lf == 0.0 || r.lam[j] < lf)) lf = r.lam[j];
      }
      run_out_free(&r);
      double sigma = lf > 0.0 ? -0.5 * lf : sigma0;
      fmbd_log(FMBD_LOG_DEBUG,
               "eig: shift estimate pass at %.3g: first flexible eigenvalue "
               "~%.6g, shift %.6g",
               sigma0, lf, sigma);
      t0 = fmbd_wall_s();
      FMBD_GCALL(fmbd_chol_factor(own, sigma));
      res->sigma = sigma;
    }
    res->t_factor_s += fmbd_wall_s() - t0;
    op = own;
  } else {
    res->sigma = fmbd_chol_sigma(F);
  }

  // --- Lanczos passes with checks ------------------------------------------------------------
  double top = -1.0;  // fmbd_eig_spectrum_scale, at the first residual check (need_k)
  int64_t want = bound ? 0 : o.nev;
  int64_t nreq = bound ? o.nev : o.nev + (o.nev / 10 > 3 ? o.nev / 10 : 3);
  int64_t ncv_extra = 0;
  int failed = 0;
  double tol = o.tol;
  const double *v0 = o.v0;
  for (;;) {
    if (nreq > n - 2) nreq = n - 2;
    int64_t ncv = o.ncv > nreq ? o.ncv : auto_ncv(n, nreq);
    ncv += ncv_extra;
    if (ncv > n) ncv = n;
    run_out_free(&r);
    double t1 = fmbd_wall_s();
    int64_t bs = block_size(&o, n, nreq, ncv);
    if (bs > 0) {
      FMBD_GCALL(block_run(M, op, nreq, bound ? nreq : want, ncv, bs, tol, o.maxit, &o, v0,
                           res->n_solves, &r));
      res->block = bs;
      res->orth_loss = r.orth_loss;
    } else {
      FMBD_GCALL(arpack_run(M, op, nreq, ncv, tol, o.maxit, &o, v0, res->n_solves, &r));
      res->block = 1;
    }
    res->passes++;
    res->n_solves += r.solves;
    res->n_restarts += r.restarts;
    v0 = NULL;  // the caller's start vector serves the first pass; a repeated one starts afresh
    FMBD_GCALL(sort_pairs(n, &r));
    res->t_lanczos_s += fmbd_wall_s() - t1;
    // fewer converged than needed: more vectors
    int64_t need = bound ? 1 : want;
    if (r.nconv < need) {
      if (++failed > o.max_passes) {
        FMBD_GFAIL(FMBD_ERR_CONVERGE,
                   "Lanczos did not converge: %lld of %lld eigenpairs converged after %d runs "
                   "(last with %lld vectors, %d restarts)",
                   (long long)r.nconv, (long long)nreq, res->passes, (long long)ncv, o.maxit);
      }
      fmbd_log(FMBD_LOG_INFO, "eig: %lld of %lld pairs converged; again with more vectors",
               (long long)r.nconv, (long long)nreq);
      ncv_extra += nreq;
      continue;
    }
    // bound mode: grow the count until the highest converged exceeds the bound
    if (bound && r.lam[r.nconv - 1] <= o.lambda_max) {
      FMBD_GCHECK(nreq < n - 2, FMBD_ERR_VALUE,
                  "every one of the %lld computable eigenvalues lies below the bound %.6g",
                  (long long)r.nconv, o.lambda_max);
      double lt = r.lam[r.nconv - 1];
      double grow = lt > 0.0 ? 1.2 * (double)nreq * pow(o.lambda_max / lt, 1.5) + 5.0 : 2.0 * nreq;
      int64_t nn = (int64_t)ceil(grow);
      if (nn < nreq + 10) nn = nreq + 10;
      if (nn > 4 * nreq + 10) nn = 4 * nreq + 10;
      fmbd_log(FMBD_LOG_INFO, "eig: %lld pairs reach %.6g, below the bound %.6g: again with %lld",
               (long long)r.nconv, lt, o.lambda_max, (long long)nn);
      nreq = nn;
      continue;
    }
    int64_t keep = want;
    if (bound) {
      keep = 0;
      while (keep < r.nconv && r.lam[keep] <= o.lambda_max) keep++;
    }
    // residual of every kept pair, and its M-normalisation
    double t2 = fmbd_wall_s();
    int64_t bad = -1;
    double worst = 0.0;
    double *rs = NULL;
    FMBD_GALLOC(rs = fmbd_malloc((size_t)(keep ? keep : 1) * sizeof(double)));
    fmbd_free(res->resid);
    res->resid = rs;  // owned by the result from here (a failure below frees it with it)
    if (!K->data) FMBD_GCALL(o.need_k(o.need_k_ctx));
    if (top < 0.0) top = fmbd_eig_spectrum_scale(K, M);
    FMBD_GCALL(check_normalise(K, M, keep, r.lam, r.X, res->sigma, rs));
    for (int64_t j = 0; j < keep; j++) {
      // attainable accuracy: a backward-stable solve leaves a residual of order
      // eps ||K|| ||x|| ~ eps lambda_top / lambda relative to ||K x|| (slender beams: 1e-7)
      double lim = fmax(o.resid_tol, 1e3 * 2.2e-16 * top / fmax(fabs(r.lam[j]), fabs(res->sigma)));
      if (!(rs[j] <= lim) && bad < 0) bad = j;
      if (rs[j] > worst) worst = rs[j];
    }
    res->t_check_s += fmbd_wall_s() - t2;
    if (bad >= 0) {
      if (++failed > o.max_passes) {
        FMBD_GFAIL(FMBD_ERR_CONVERGE,
                   "eigenpair %lld (lambda %.6g) has relative residual %.2g > %.1g after %d runs "
                   "(%lld of %lld pairs pass)",
                   (long long)bad + 1, r.lam[bad], rs[bad], o.resid_tol, res->passes,
                   (long long)bad, (long long)keep);
      }
      fmbd_log(FMBD_LOG_INFO, "eig: pair %lld has residual %.2g; again with more vectors",
               (long long)bad + 1, rs[bad]);
      ncv_extra += nreq;
      tol = tol * 1e-2 > 1e-15 ? tol * 1e-2 : 1e-15;
      continue;
    }
    // Sturm check: s in the first clear gap at or above the last kept pair
    if (o.sturm) {
      int64_t j = keep;  // candidate count below s: lam[0..j-1]
      double s = NAN;
      for (; j < r.nconv; j++) {
        // below the first returned pair the shift itself is a lower end (sigma < every
        // eigenvalue, else the LL' factor would have failed)
        double hi = r.lam[j];
        double lo = j > 0 ? r.lam[j - 1] : (res->sigma < hi ? res->sigma : hi - fabs(hi));
        double ref = fmax(fmax(fabs(hi), fabs(lo)), fabs(res->sigma));
        if (hi - lo > 1e-6 * ref) {
          s = 0.5 * (lo + hi);
          break;
        }
      }
      if (isnan(s)) {
        // the returned pairs end inside a cluster: ask for more
        if (++failed > o.max_passes) {
          FMBD_GFAIL(FMBD_ERR_CONVERGE,
                     "no gap above the last of %lld eigenvalues for the "
                     "Sturm check after %d runs",
                     (long long)r.nconv, res->passes);
        }
        nreq = r.nconv + 5;
        continue;
      }
      double t3 = fmbd_wall_s();
      if (!ldl) {
        int64_t *pm = fmbd_malloc((size_t)n * sizeof(int64_t));
        FMBD_GCHECK(pm, FMBD_ERR_NOMEM, "out of memory");
        rc = fmbd_chol_get_perm(op, pm);
        if (rc == 0) rc = fmbd_chol_analyze_perm(K, M, FMBD_CHOL_LDLT, pm, &ldl);
        fmbd_free(pm);
        FMBD_GCALL(rc);
      }
      if (o.progress) o.progress(o.progress_ctx, "Sturm check", res->n_solves, keep);
      FMBD_GCALL(fmbd_chol_factor(ldl, s));
      int64_t cnt = fmbd_chol_negative_pivots(ldl);
      res->t_sturm_s += fmbd_wall_s() - t3;
      res->sturm_shift = s;
      res->sturm_count = cnt;
      fmbd_log(FMBD_LOG_DEBUG, "eig: Sturm count below %.9g: %lld, returned %lld", s,
               (long long)cnt, (long long)j);
      if (cnt != j) {
        if (++failed > o.max_passes) {
          FMBD_GFAIL(FMBD_ERR_CONVERGE,
                     "Sturm check failed: %lld eigenvalues below %.9g, Lanczos found %lld "
                     "(after %d runs)",
                     (long long)cnt, s, (long long)j, res->passes);
        }
        fmbd_log(FMBD_LOG_INFO,
                 "eig: Sturm count %lld below %.9g, Lanczos found %lld: again "
                 "with more vectors",
                 (long long)cnt, s, (long long)j);
        if (cnt > j) nreq += cnt - j + 2;
        ncv_extra += nreq / 2 + 10;
        continue;
      }
    }
    // success
    res->nev = keep;
    res->next_lambda = keep < r.nconv ? r.lam[keep] : NAN;
    res->lambda = r.lam;
    res->X = r.X;
    r.lam = r.X = NULL;
    break;
  }
done:
  fmbd_chol_destroy(&own);
  fmbd_chol_destroy(&ldl);
  run_out_free(&r);
  fmbd_free(work);
  return rc;
}

int fmbd_eig_sturm_check(const fmbd_csr *K, const fmbd_csr *M, fmbd_chol *like,
                         fmbd_eig_result *res, bool *ok) {
  int rc = FMBD_OK;
  fmbd_chol *ldl = NULL;
  *ok = false;
  if (res->nev < 1 || !isfinite(res->next_lambda)) return FMBD_OK;
  double lo = res->lambda[res->nev - 1], hi = res->next_lambda;
  double ref = fmax(fmax(fabs(hi), fabs(lo)), fabs(res->sigma));
  if (!(hi - lo > 1e-6 * ref)) return FMBD_OK;  // inside a cluster: inconclusive
  double s = 0.5 * (lo + hi);
  double t0 = fmbd_wall_s();
  if (like)
    FMBD_GCALL(fmbd_chol_analyze_like(like, K, M, FMBD_CHOL_LDLT, &ldl));
  else
    FMBD_GCALL(fmbd_chol_analyze(K, M, FMBD_CHOL_LDLT, &ldl));
  FMBD_GCALL(fmbd_chol_factor(ldl, s));
  res->sturm_shift = s;
  res->sturm_count = fmbd_chol_negative_pivots(ldl);
  res->t_sturm_s += fmbd_wall_s() - t0;
  *ok = res->sturm_count == res->nev;
  fmbd_log(FMBD_LOG_DEBUG, "eig: Sturm count below %.9g: %lld, returned %lld", s,
           (long long)res->sturm_count, (long long)res->nev);
done:
  fmbd_chol_destroy(&ldl);
  return rc;
}
