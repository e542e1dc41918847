// common/fmbd_mbs_impl.h: INTERNAL header of the multibody core (not installed, not an API):
// the struct definitions and the prototypes shared by the translation units of fmbd_mbs:
//   fmbd_mbs.c            model building (create, add bodies, points, joints, drivers, loads)
//   fmbd_mbs_fn.c         functions of time
//   fmbd_mbs_body.c       the equations of motion of one body (residual and iteration block)
//   fmbd_mbs_constraint.c joint, driver and normalisation equations, their Jacobians
//   fmbd_mbs_system.c     system evaluation, the sparse iteration matrix, its LU (fmbd_klu)
//   fmbd_mbs_schur.c      the same matrix solved by eliminating the modal bodies' blocks
//   fmbd_mbs_init.c       fmbd_mbs_init: redundancy, consistent initial conditions
//   fmbd_mbs_step.c       generalized-alpha steps, Newton, step-size control
//   fmbd_mbs_query.c      queries of the state
//   fmbd_mbs_linear.c     fmbd_mbs_linearise (the equations outside the integrator)
// The API, the equations and the choices are documented in fmbd_mbs.h. Internal functions
// carry the prefix mbs_ (they are extern in libfmbd.a, never called from outside common/).
// SPDX-License-Identifier: MIT
#ifndef FMBD_MBS_IMPL_H
#define FMBD_MBS_IMPL_H

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "fmbd_klu.h"
#include "fmbd_mbs.h"

// --- small 3-vector and 3x3 (row-major) helpers, quaternions -------------------------------
static inline double dot3(const double *a, const double *b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
static inline void cross3(const double *a, const double *b, double *c) {
  double t0 = a[1] * b[2] - a[2] * b[1], t1 = a[2] * b[0] - a[0] * b[2],
         t2 = a[0] * b[1] - a[1] * b[0];
  c[0] = t0, c[1] = t1, c[2] = t2;
}
static inline double norm3(const double *a) {
  return sqrt(dot3(a, a));
}
// y = A x (row-major 3x3)
static inline void mv3(const double *A, const double *x, double *y) {
  double t0 = A[0] * x[0] + A[1] * x[1] + A[2] * x[2];
  double t1 = A[3] * x[0] + A[4] * x[1] + A[5] * x[2];
  double t2 = A[6] * x[0] + A[7] * x[1] + A[8] * x[2];
  y[0] = t0, y[1] = t1, y[2] = t2;
}
// y = A' x
static inline void mtv3(const double *A, const double *x, double *y) {
  double t0 = A[0] * x[0] + A[3] * x[1] + A[6] * x[2];
  double t1 = A[1] * x[0] + A[4] * x[1] + A[7] * x[2];
  double t2 = A[2] * x[0] + A[5] * x[1] + A[8] * x[2];
  y[0] = t0, y[1] = t1, y[2] = t2;
}
// skew matrix v~ (row-major): v~ x = v x x
static inline void skew3(const double *v, double *S) {
  S[0] = 0, S[1] = -v[2], S[2] = v[1];
  S[3] = v[2], S[4] = 0, S[5] = -v[0];
  S[6] = -v[1], S[7] = v[0], S[8] = 0;
}
// C = A B (row-major 3x3)
static inline void mm3(const double *A, const double *B, double *C) {
  double T[9];
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      T[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    }
  }
  memcpy(C, T, sizeof T);
}

// Quaternion p = (e0, e1, e2, e3). A(p/|p|) row-major.
static inline void quat_to_A(const double *p, double *A) {
  double n2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3];
  double s = n2 > 0 ? 1.0 / n2 : 0.0;
  double e0 = p[0], e1 = p[1], e2 = p[2], e3 = p[3];
  A[0] = s * (e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3);
  A[1] = s * 2 * (e1 * e2 - e0 * e3);
  A[2] = s * 2 * (e1 * e3 + e0 * e2);
  A[3] = s * 2 * (e1 * e2 + e0 * e3);
  A[4] = s * (e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3);
  A[5] = s * 2 * (e2 * e3 - e0 * e1);
  A[6] = s * 2 * (e1 * e3 - e0 * e2);
  A[7] = s * 2 * (e2 * e3 + e0 * e1);
  A[8] = s * (e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3);
}
// G(p) = [-e, -e~ + e0 1] (3x4 row-major): body angular velocity wb = 2 G p'
static inline void quat_G(const double *p, double *G) {
  double e0 = p[0], e1 = p[1], e2 = p[2], e3 = p[3];
  G[0] = -e1, G[1] = e0, G[2] = e3, G[3] = -e2;
  G[4] = -e2, G[5] = -e3, G[6] = e0, G[7] = e1;
  G[8] = -e3, G[9] = e2, G[10] = -e1, G[11] = e0;
}
// Shepperd's method: unit quaternion of a rotation matrix (row-major), e0 >= 0.
static inline void A_to_quat(const double *A, double *p) {
  double tr = A[0] + A[4] + A[8];
  double v[4] = {tr, A[0], A[4], A[8]};
  int k = 0;
  for (int i = 1; i < 4; i++) {
    if (v[i] > v[k]) k = i;
  }
  double q[4];
  if (k == 0) {
    double s = sqrt(1 + tr) * 2;
    q[0] = 0.25 * s, q[1] = (A[7] - A[5]) / s, q[2] = (A[2] - A[6]) / s, q[3] = (A[3] - A[1]) / s;
  } else if (k == 1) {
    double s = sqrt(1 + A[0] - A[4] - A[8]) * 2;
    q[0] = (A[7] - A[5]) / s, q[1] = 0.25 * s, q[2] = (A[1] + A[3]) / s, q[3] = (A[2] + A[6]) / s;
  } else if (k == 2) {
    double s = sqrt(1 - A[0] + A[4] - A[8]) * 2;
    q[0] = (A[2] - A[6]) / s, q[1] = (A[1] + A[3]) / s, q[2] = 0.25 * s, q[3] = (A[5] + A[7]) / s;
  } else {
    double s = sqrt(1 - A[0] - A[4] + A[8]) * 2;
    q[0] = (A[3] - A[1]) / s, q[1] = (A[2] + A[6]) / s, q[2] = (A[5] + A[7]) / s, q[3] = 0.25 * s;
  }
  double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  double sg = q[0] < 0 ? -1.0 : 1.0;
  for (int i = 0; i < 4; i++) p[i] = sg * q[i] / n;
}

// --- the system ----------------------------------------------------------------------------
// A full FE body's data (fmbd_mbs_fe.c; docs/THEORY.md section 4b). Nodal fields are nn x 3
// column-major (u[p + nn a]); E maps the n coordinates to them.
typedef struct mbs_fe {
  int64_t nn;             // nodes
  fmbd_csr *E, *Et, *Mn;  // (3 nn) x n, its transpose, nn x nn scalar nodal mass
  double *x, *m1, *mx;    // nn x 3 positions; Mn 1 (nn); Mn x (nn x 3)
  double *S1;             // 3 x n: S1[a + 3k] = (E_a' Mn 1)_k, or T_a' M S_k (fe_data S1)
  double *dv;   // 3 x n or NULL: Mw0 - (E'(e_a x Mn x))_k, the consistent rotational coupling
                // at q = 0 less Mn's (beams: the antisymmetric part of H_k, docs/THEORY.md 4b)
  fmbd_csr *P;  // n x n pattern of M + K + D; values in Mv, Kv, Dv
  double *Mv, *Kv, *Dv;  // on P's entries
  double *Gv;     // 3 nnz: Gv[e + nnz a] = (sum_bc eps_abc E_c' Mn E_b)(entry e): the gyroscopic
                  // tangent 2 w . int rho S_l x S_k of the flexible rows = 2 sum_a w_a G_a
  int64_t *dofs;  // 2 x n (node, direction) or NULL
  double *U, *Ud, *Udd, *W, *Vd, *Y, *z;  // nn x 3 workspace
  double *v1, *h;                         // (n), (10 n) workspace
  double *cu, *cl;                        // 6 x n coupling blocks (upper [i + 6k], lower)
  int64_t pos7[49];                       // Ax positions of the 7 x 7 block (i + 7 j)
  int64_t *pu, *pl, *pff;  // of (i, 7 + k) at pu[i + 7k], (7 + k, i) at pl[i + 7k], P
} mbs_fe;

typedef struct mbody {
  char *name;
  int nm, n;    // modes; coordinates 7 + nm
  int64_t off;  // first coordinate in x
  double m, c0[3], J0[9];
  double *S1, *XS, *SS, *Mff, *Kff, *Dff;  // layouts of fmbd_mbs.h; Dff nm x nm; SS freed
                                           // after load (packed in pk, and SSx)
  double *XSx;                             // 3 x nm: int rho x0 x S_k
  double *SSx;                 // 3 x nm x nm: SSx[a + 3 l + 3 nm k] = (int rho S_l x S_k)_a
  double snorm;                // scale of the normalisation equation
  double gyr;                  // radius of gyration about the origin (m)
  double x0[7], v0[3], w0[3];  // initial R, p; velocity, angular velocity (world)
  double *q0, *qd0;
  // --- evaluation workspace (filled by mbs_body_eval) ---
  double A[9], G[12], pn, wb[3], c[3], J[9], I[9];
  double *Hk;    // 9 nm: H_k[a + 3b] = int rho S_k,a u_b
  double *Mwf;   // 3 x nm
  double *XX;    // 9 nm: XS_k + XS_k' (+ 0 if partial; mbs_body_consts): a partial body's J
  double *XT;    // 9 nm: XS_k' (mbs_body_consts): H_k = XS_k' + P_k with full coupling
  double *pk;    // constant arrays of mbs_body_consts (NULL without modes): partial coupling
                 // PK_SIZE x nm; full coupling SS's upper triangle (mbs_ss_pack), then
                 // mbs_ssq's P (9 nmp) and padded q (nmp) as the evaluation's workspace
  double *cor;   // 3 x nm: sum_l q'_l int rho S_l x S_k
  bool kdiag;    // Kff and Dff diagonal (the usual modal body): O(nm) elastic forces
  bool mdiag;    // Mff diagonal (M-orthonormal modes, the usual modal body): O(nm) Mff products
  bool partial;  // partial inertia coupling: SSx is zero and cor stays zero (not formed)
  double wB[3];  // wb at the last block evaluation (mbs_body_eval with B; mbs_body_ff)
  bool elim;     // modal block eliminated (fmbd_mbs_schur.c): mbs_eval_system leaves it out of Ax
  mbs_fe *fe;    // a full FE body (nm = n FE dofs, no dense modal arrays), else NULL
  double spin_lam;   // lowest elastic eigenvalue held as its joints hold it (fmbd_mbs_spin.c)
  bool spin_warned;  // mbs_spin_check warned
  bool rate_warned;  // mbs_spin_check warned of h Omega > 1 - rho_inf
  // shared modal coordinates (GMs, fmbd_mbs_share_modal): the bodies of a set use one block of
  // nm coordinates, stored after the frame of the set's first body (its owner)
  int share;           // owner body of the set, or -1 (the body's own coordinates)
  int64_t qoff;        // first elastic coordinate in x (off + 7 unless shared)
  int64_t gn;          // coordinates of x stored at off: n, or 7 for a non-owner of a shared set
  double qunit;        // unit of the elastic coordinates in the scales (fmbd_mbs_init: QUNIT)
  bool mff_unchecked;  // added for a shared set: Mff's definiteness is checked by fmbd_mbs_init
} mbody;
// unit of a body's flexible coordinates in the scales: sqrt(m) for mass-normalised modal
// coordinates, 1 for FE dofs (m, rad); shared coordinates: sqrt of the set's total mass (set by
// fmbd_mbs_init in qunit)
#define QUNIT(b) ((b)->qunit)
// the global coordinate of a body's local coordinate i (0..6 frame, 7.. elastic)
static inline int64_t mbs_col(const mbody *b, int64_t i) {
  return i < 7 ? b->off + i : b->qoff + (i - 7);
}

typedef struct mpoint {
  int body;
  double x0[3];
  double *T, *Rr;  // 3 x nm each or NULL (modal); 3 x nsup on an FE body
  int nsup;        // FE body: the flexible coordinates that move the point (sup, increasing)
  int64_t *sup;    // NULL: all nm (modal bodies)
} mpoint;

typedef struct mjoint {
  char *name;
  int kind, neq;
  int pt[2], body[2];
  double e[2][3][3];  // local frame vectors (x, y, z) of each side (ground: world)
  double a2[3];       // universal: cross axis of side 2 (local to body 2)
} mjoint;

typedef struct mdriver {
  char *name;
  int joint, body, coord;
  fmbd_mbs_fn f;
} mdriver;

typedef struct mload {
  char *name;
  int kind, pt;
  bool body_frame;
  double dir[3];
  fmbd_mbs_fn f;
} mload;

enum { EQ_JOINT = 0, EQ_DRIVER, EQ_NORM };
typedef struct meq {
  int kind, owner, sub;  // joint/driver/body id, equation index within the joint
  int b[2];              // bodies whose coordinates appear (-1 none)
  int nj;                // entries of jac: n(b0) + n(b1)
  bool kept;
  int64_t row;       // index among kept equations (-1 removed)
  double phi;        // value
  double sc;         // scale of phi (m for positions, 1 for direction products)
  double *jac;       // nj
  int64_t *cols;     // nj coordinates of the jac entries (side 1's body, then side 2's)
  int64_t *pr, *pc;  // positions in Ax of (row, col) and (col, row) per jac entry
  double *jw;        // nj: A_ii / |jac| at the last matrix (fmbd_mbs_step.c, mult_tol)
  char *text;        // description (redundant ones)
} meq;

typedef struct mbs_schur mbs_schur;  // fmbd_mbs_schur.c

// the predictor's orders (fmbd_mbs_step.c, pred_order); x'' and lambda of PRED_NH accepted
// steps before t_n are kept for it, as many as its highest order reads
#define PRED_MIN 2
#define PRED_MAX 4
#define PRED_NH PRED_MAX
struct fmbd_mbs {
  int nb, nbcap;
  mbody *b;
  int np, npcap;
  mpoint *p;
  int nj, njcap;
  mjoint *j;
  int nd, ndcap;
  mdriver *d;
  int nl, nlcap;
  mload *l;
  double g[3];
  bool ready;
  bool spin_ready;  // the bodies' spin_lam computed (fmbd_mbs_spin.c)
  fmbd_mbs_settings set;
  // --- dimensions and state ---
  int64_t n, neq, m, N;  // coordinates, all equations, kept, matrix size
  meq *eq;
  double t;
  double *x, *xd, *xdd, *a, *lam;       // lam: physical multipliers (m)
  double *xn, *xdn, *xddn, *an, *lamn;  // state at the start of the step
  // x'' and lam of the accepted steps before t_n (the predictor, fmbd_mbs_step.c): [k] is
  // k + 1 steps before, hh[k] the step that ended there (t_n-k - t_n-k-1 for k = 0), nh of
  // them held
  double *xddh[PRED_NH], *lamh[PRED_NH], hh[PRED_NH];
  int nh;
  // the predictor's orders PRED_MIN..PRED_MAX: average log error for x'' [0] and lambda [1]
  // over the last accepted steps, and how many steps were scored (fmbd_mbs_step.c)
  double pred_lerr[2][PRED_MAX - PRED_MIN + 1];
  int64_t pred_n;
  bool pred_rigid;  // rigid bodies only: the order is chosen (else quadratic, fmbd_mbs_step.c)
  double *itx;      // 1 / Newton tolerance of each coordinate in this attempt (fmbd_mbs_step.c)
  double *ity;      // 1 / Newton tolerance of each kept multiplier's increment (fmbd_mbs_step.c)
  double *tx;       // Newton tolerance of each coordinate in this attempt (1 / itx)
  double *dyp;      // the multipliers' increments of the last Newton iteration
  bool jw_ok;       // the equations' jw formed from the last evaluated matrix
  int64_t *dpos;    // position of each coordinate's diagonal entry in Ax (-1: not formed there)
  unsigned char *qpar;  // 1: an elastic coordinate of a modal body (the predictor's parity rule)
  double *res, *rhs, *scale, *nscale, *ascale, *floor_;
  double *rscale;  // round-off scale of each coordinate's Newton increment (fmbd_mbs_init.c)
  double Lref;
  int maxn;             // largest dense body block (modal bodies) or joint side (7 + point support)
  int64_t maxb;         // largest body (coordinates)
  double *wk;           // side kinematics workspace
  double *bres, *bblk;  // per-body residual (n) and block (n^2), max size
  double *bwork;        // per-body workspace
  // --- generalized alpha ---
  double am, af, beta, gamma;
  double h_next, h_fact, h_prop;
  double err_prev[2];  // scaled local errors of the last two accepted steps (0: none yet)
  int64_t k_out;
  int64_t worst_i;  // largest scaled residual of the last iterate
  double worst_v;
  int64_t worst_dx;  // coordinate of the largest Newton correction
  int64_t worst_dy;  // kept equation of the largest multiplier correction (debug output)
  bool need_factor, after_reject;
  // the refresh by age (fmbd_mbs_step.c, refresh_age): m->st.steps when the current factor was
  // formed in a step, and the age at which it is refreshed at a step's start (0: not decided
  // yet, -1: never)
  int64_t fact_steps;
  int refresh_age;
  // --- sparse matrix and KLU ---
  int64_t nnz;
  double *Ax;       // values in the pattern analysed by klu (compressed columns)
  int64_t **bpos;   // per body n^2 positions
  fmbd_klu *klu;    // symbolic analysis once (fmbd_mbs_init), numeric factor kept
  double mcoef[3];  // (cm, cc, ck) of the matrix in Ax (mbs_eval_system)
  mbs_schur *sc;    // the modal blocks' elimination (fmbd_mbs_schur.c) or NULL
  // --- results ---
  fmbd_mbs_stats st;
  // the Newton iterations' factorisations, solves and the rest: wall time (s) since the last
  // window's end, CPU time (s) of the windows before, the wall and process CPU clocks at the
  // last window's end (a window: 8 steps; fmbd_mbs_step, mbs_cpu_share, fmbd_mbs_get_stats)
  double tm_phase[3], tm_cpu[3], tm_wall0, tm_cpu0;
  int nred;
  int *red;  // equation indices removed
  double qmax_init;
};

// mass given to the direction p of the Euler parameters (relative to the normalisation
// scale): makes the dynamics block regular (the mass-weighted projections of fmbd_mbs_init
// and the conditioning of the iteration matrix); physics unchanged since G p = 0
#define PMASS 0.25

// refresh the iteration matrix when the Newton contraction rate exceeds THETA_REFACTOR
// (measured on t500-t502: 0.1 with extrapolation halves the iterations of 0.5 at a few more
// factorisations); the predictor's extrapolation: fmbd_mbs_step.c, pred_order
#ifndef THETA_REFACTOR
#define THETA_REFACTOR 0.1
#endif
// step-size controller: safety factor, and the dead band [DEAD_LOW, 1.25] of proposed step
// ratios that keep h (and the factorised matrix) unchanged. Modal error floor: deformations
// below MODAL_FLOOR L_ref (physical, via sqrt(m) for mass-normalised modes) do not tighten
// the error test. Chosen on the quadruple pendulum with 30 modes (3 rigid + 1 flexible body,
// 1 s, tolerance 1e-4): floor 1e-6 / 1e-5 / 1e-4 gave 10434 / 3914 / 1415 steps; dead band
// 0.85 cut the CPU time by 25 % against 1.0; safety 0.9 vs 0.8 vs 0.7 within 15 %.
#define SAFETY 0.9
#define DEAD_LOW 0.85
#define MODAL_FLOOR 1e-5
// a failed step at the smallest step size is reported as a singular position when the
// smallest singular value of the kept constraint rows (unit-normalised, coordinates in their
// scales: L_ref for translations) is below SINGULAR_TOL. Measured on the spatial slider-crank
// (docs/STABILITY.md, Constraints): 0.03 to 0.09 at regular positions (metre and millimetre
// scale alike), 3e-5 to 1e-4 where Newton fails at its dead point; the value falls as the square
// root of the distance to the fold (2.8e-2 at 0.01 s before it), so 1e-3 is reached about 1.4e-5 s
// (2.7e-6 m of travel) before the fold.
#define SINGULAR_TOL 1e-3
// the modal blocks are eliminated (fmbd_mbs_schur.c) for bodies with at least SCHUR_NM_MIN
// modes (bench/README.md, "Schur complement of the modal blocks")
#ifndef SCHUR_NM_MIN
#define SCHUR_NM_MIN 10
#endif

// --- constraints ---------------------------------------------------------------------------
// Kinematics of one joint side: position r and up to 4 attached directions g[i], with their
// derivatives with respect to the side body's coordinates (3 x n, column-major, ld 3).
typedef struct side {
  int body, n;
  double r[3], g[4][3];
  double *dr, *dg[4];
  // the body's rotation A, A G (3 x 4 row-major), -2/|p| and A u (the point from the frame's
  // origin, world axes): what the generalized forces of the side need (fmbd_mbs_constraint.c)
  double A[9], AG[12], f, Au[3];
} side;

// --- internal functions ----------------------------------------------------------------------
// fmbd_mbs.c
bool mbs_finite_n(const double *v, int64_t n);
int mbs_spd(const double *A, int64_t n);
const char *mbs_joint_kind_name(int kind);
// fmbd_mbs_fn.c: copy a function (table arrays owned by the copy; `what` names it in messages)
int mbs_fn_copy(const fmbd_mbs_fn *src, fmbd_mbs_fn *dst, const char *what);
void mbs_fn_free(fmbd_mbs_fn *f);
// After each accepted step: warn once per flexible body spinning fast enough for the missing
// geometric stiffening to matter (fmbd_mbs_spin.c, docs/STABILITY.md).
void mbs_spin_check(fmbd_mbs *m);
// fmbd_mbs_init.c: the kept constraint rows (nearly) dependent at the current positions
bool mbs_constraints_singular(fmbd_mbs *m, double tol, double *smin, char *buf, size_t len);
// fmbd_mbs_body.c: the residual r (n = 7 + nm) of body ib at (xg, xdg, xddg; xddg may be
// NULL: zero accelerations) and optionally its block B = cm M + cc C + ck K (n x n, column
// major; without ff its modal-modal part is left out); see the comment at the definition
void mbs_body_eval(fmbd_mbs *m, int ib, double t, const double *xg, const double *xdg,
                   const double *xddg, double *r, double *B, double cm, double cc, double ck,
                   bool ff);
// the modal-modal part of body ib's block written into Ax (after mbs_body_eval without ff)
void mbs_body_ff(fmbd_mbs *m, int ib);
// a modal body's constant inertia terms at load (b->XX; H_k, Mwf with partial coupling)
int mbs_body_consts(mbody *b);
// y += alpha A x, A m x n column-major (leading dimension lda), for the small dense products of
// the multibody core (fmbd_mbs_body.c: vectorised; AVX2 where the processor has it, the same bits);
// A and x must not overlap y
void mbs_matvec_add(int m, int n, const double *A, int lda, const double *x, double alpha,
                    double *y);
// the same by the portable form only (what processors without AVX2 run; the AVX2 form gives the
// same bits: tests/unit/t513)
void mbs_matvec_add_portable(int m, int n, const double *A, int lda, const double *x, double alpha,
                             double *y);
// SS (layout of fmbd_mbs.h) as one symmetric matrix of order 3 nm, its upper triangle packed
// into St (mbs_ss_size(nm) doubles; blocks padded to nmp = nm rounded up to 4; the mean of the
// two copies of each entry; below 40 modes SS whole, re-laid), and P = SS q from it (P[k + nmp (a +
// 3b)] = sum_l SS_ab,kl q_l, 9 nmp doubles; qp: nmp doubles of workspace): AVX2 where the processor
// has it, the same bits as the portable form (tests/unit/t513); see fmbd_mbs_body.c
size_t mbs_ss_size(int nm);
void mbs_ss_pack(int nm, const double *SS, double *St);
void mbs_ssq(int nm, const double *St, const double *q, double *P, double *qp);
void mbs_ssq_portable(int nm, const double *St, const double *q, double *P, double *qp);
// the second-order inertia sums of a modal body's energy and momentum (fmbd_mbs_query.c):
// J += sum_kl q_k q_l SS_kl (J_ab += q_k q_l SS[a + 3b + 9k + 9 nm l]; none for a partial body),
// Mwfqd += sum_k q'_k (sum_l q_l SSx_lk + XSx_k); full coupling: in the evaluation's workspace
void mbs_body_inert2(const mbody *b, const double *q, const double *qd, double *J, double *Mwfqd);
// b->pk of a partial body: [S1_k; J's upper XX_k] (9 x nm), [S1_k; H_k] (12 x nm), [S1_k; Mwf_k]
// (6 x nm), the modal rows' inertia terms (nm x 12); see mbs_body_consts
#define PK_SIZE (9 + 12 + 6 + 12)
// parts shared by modal and FE bodies (fmbd_mbs_body.c; see there)
void mbs_frame_kin(mbody *b, const double *p, const double *pd, const double *pdd, double *w,
                   double *wd);
void mbs_rigid_rows(const mbody *b, const double *rb, const double *p, const double *pdd,
                    double *r);
void mbs_rigid_qv(const double *A, const double *w, const double *c, const double *s1qd,
                  const double *I, const double *H, double trH, double *rb, double *Iw);
void mbs_rigid_vel_tangent(const double *A, const double *w, const double *c, const double *Sc,
                           const double *s1qd, const double *I, const double *Iw, const double *H,
                           double trH, double *AM, double *WW);
void mbs_body_loads(const fmbd_mbs *m, int ib, double t, const double *A, const double *q,
                    double *rb, double *rf);
// fmbd_mbs_constraint.c
void mbs_eq_describe(const fmbd_mbs *m, const meq *e, char *buf, size_t len);
void mbs_joint_sides(fmbd_mbs *m, const mjoint *j, const double *x, side *s1, side *s2);
double mbs_joint_coord(const mjoint *j, const side *s1, const side *s2, double *jac);
void mbs_eval_constraints(fmbd_mbs *m, const double *x, double t, bool want_jac);
// every equation's value at (x, t) and, with res, Phi_x' lambda of the kept ones added into res
// (the joints' without forming their Jacobians, which are left stale; see there)
void mbs_eval_constraints_res(fmbd_mbs *m, const double *x, double t, double *res);
void mbs_eq_time_derivs(const fmbd_mbs *m, double t, int64_t e, double *ft, double *ftt);
double mbs_eq_jv(const fmbd_mbs *m, const meq *q, const double *v);
void mbs_eq_jtv(const fmbd_mbs *m, const meq *q, double f, double *v);
// fmbd_mbs_system.c
void mbs_coord_describe(const fmbd_mbs *m, int64_t i, char *buf, size_t len);
// The CPU share of the wall time since the last window's end (1 before the first), at the
// clocks' readings wall and cpu: the factor that makes the phases' wall time CPU time.
double mbs_cpu_share(const fmbd_mbs *m, double wall, double cpu);
void mbs_eval_system(fmbd_mbs *m, double t, const double *xdd, bool matrix, double cm, double cc,
                     double ck, bool add_lam);
int mbs_build_pattern(fmbd_mbs *m);
int mbs_factor(fmbd_mbs *m);
int mbs_solve(fmbd_mbs *m, double *rhs);
// the eliminated bodies' modal blocks (b->elim), which mbs_eval_system leaves out of Ax, written
// into it (for the whole matrix's KLU and other readers of Ax's body blocks)
void mbs_fill_modal_blocks(fmbd_mbs *m);
// fmbd_mbs_schur.c: the iteration matrix with the modal coordinates of the modal bodies
// eliminated (Schur complement on their constant blocks cm Mff + cc Dff + ck Kff; see there).
// Chosen at mbs_build_pattern for the bodies with at least SCHUR_NM_MIN modes (environment
// FMBD_MBS_SCHUR = 0 / off: never, 1 / on: every modal body); mbs_factor and mbs_solve use it
// when set, and the whole matrix's KLU when its factorisation fails (not positive definite,
// singular S: the messages name the unknown as before).
int mbs_schur_setup(fmbd_mbs *m, const int64_t *Ap, const int64_t *Ai);
// Ax zeroed except the eliminated modal blocks (which mbs_eval_system does not write)
void mbs_schur_clear(fmbd_mbs *m);
int mbs_schur_factor(fmbd_mbs *m);
int mbs_schur_solve(fmbd_mbs *m, double *rhs);
bool mbs_schur_active(const fmbd_mbs *m);
void mbs_schur_free(mbs_schur **s);
// fmbd_mbs_fe.c: full FE bodies. mbs_fe_eval: the residual r (7 + n) as mbs_body_eval, and
// with Ax the block cm M + cc C + ck K added into Ax at the body's positions
void mbs_fe_eval(fmbd_mbs *m, int ib, double t, const double *xg, const double *xdg,
                 const double *xddg, double *r, double *Ax, double cm, double cc, double ck);
void mbs_fe_free(mbs_fe **fe);
int mbs_fe_create(const fmbd_mbs_fe_data *d, mbs_fe **out);
int64_t mbs_fe_nnz(const mbody *b);  // entries of its block
// enumerate the block's entries (row, col within the body) in a fixed order: k-th entry
void mbs_fe_entries(const mbody *b, int64_t *rows, int64_t *cols);
// store the Ax positions of the entries, in the order of mbs_fe_entries
void mbs_fe_set_positions(mbody *b, const int64_t *pos);
// y += B v for the body's block as stored in Ax (v, y: the body's coordinates)
void mbs_fe_block_mul(const mbody *b, const double *Ax, const double *v, double *y);
// kinetic energy, c, I, S1 q', Mwf q' of an FE body at the state (queries)
void mbs_fe_inert(const fmbd_mbs *m, int ib, double *c, double *I, double *S1qd, double *Mwfqd,
                  double *Tq, double *strain);
// fmbd_mbs_init.c
double mbs_eq_scaled(const fmbd_mbs *m, const meq *q);
void mbs_update_scales(fmbd_mbs *m);

#endif
