// common/fmbd_mbs.c: multibody dynamics core: floating-frame bodies, joints, index-3
// generalized-alpha with KLU (the equations and choices are documented in fmbd_mbs.h)
// SPDX-License-Identifier: MIT
#include "fmbd_mbs.h"

#include <float.h>
#include <klu.h>
#include <lapacke.h>
#include <math.h>
#undef I  // <complex.h> through lapacke.h; I is an inertia tensor here
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

// ============================================================================================
// small 3-vector and 3x3 (row-major) helpers
// ============================================================================================
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
static void mm3(const double *A, const double *B, double *C) {
  double T[9];
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      T[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    }
  }
  memcpy(C, T, sizeof T);
}

// Quaternion p = (e0, e1, e2, e3). A(p/|p|) row-major.
static void quat_to_A(const double *p, double *A) {
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
static void quat_G(const double *p, double *G) {
  double e0 = p[0], e1 = p[1], e2 = p[2], e3 = p[3];
  G[0] = -e1, G[1] = e0, G[2] = e3, G[3] = -e2;
  G[4] = -e2, G[5] = -e3, G[6] = e0, G[7] = e1;
  G[8] = -e3, G[9] = e2, G[10] = -e1, G[11] = e0;
}
// Shepperd's method: unit quaternion of a rotation matrix (row-major), e0 >= 0.
static void A_to_quat(const double *A, double *p) {
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

void fmbd_mbs_rotation_axis_angle(const double axis[3], double angle, double A[9]) {
  double n = norm3(axis);
  double u[3] = {0, 0, 1};
  if (n > 0) {
    u[0] = axis[0] / n, u[1] = axis[1] / n, u[2] = axis[2] / n;
  }
  double c = cos(angle), s = sin(angle), C = 1 - c;
  A[0] = c + u[0] * u[0] * C, A[1] = u[0] * u[1] * C - u[2] * s, A[2] = u[0] * u[2] * C + u[1] * s;
  A[3] = u[1] * u[0] * C + u[2] * s, A[4] = c + u[1] * u[1] * C, A[5] = u[1] * u[2] * C - u[0] * s;
  A[6] = u[2] * u[0] * C - u[1] * s, A[7] = u[2] * u[1] * C + u[0] * s, A[8] = c + u[2] * u[2] * C;
}

// ============================================================================================
// functions of time
// ============================================================================================
double fmbd_mbs_fn_eval(const fmbd_mbs_fn *f, double t, double *dfdt, double *d2fdt2) {
  double v = 0, d = 0, dd = 0;
  switch (f->kind) {
    case FMBD_MBS_FN_CONSTANT:
      v = f->value;
      break;
    case FMBD_MBS_FN_LINEAR:
      v = f->v0 + f->rate * (t - f->t0);
      d = f->rate;
      break;
    case FMBD_MBS_FN_RAMP: {
      double T = f->t1 - f->t0;
      if (t < f->t0 || T <= 0) {
        v = t < f->t0 ? f->v0 : f->v1;
      } else if (t >= f->t1) {
        v = f->v1;
      } else {
        double s = (t - f->t0) / T, dv = f->v1 - f->v0;
        if (f->smooth) {
          v = f->v0 + dv * s * s * (3 - 2 * s);
          d = dv * 6 * s * (1 - s) / T;
          dd = dv * (6 - 12 * s) / (T * T);
        } else {
          v = f->v0 + dv * s;
          d = dv / T;
        }
      }
      break;
    }
    case FMBD_MBS_FN_SINE: {
      double w = 2 * M_PI * f->frequency_hz, arg = w * t + f->phase;
      v = f->offset + f->amplitude * sin(arg);
      d = f->amplitude * w * cos(arg);
      dd = -f->amplitude * w * w * sin(arg);
      break;
    }
    case FMBD_MBS_FN_TABLE: {
      int64_t n = f->n;
      if (n <= 0 || !f->t || !f->v) break;
      if (t < f->t[0]) {
        v = f->v[0];
      } else if (t >= f->t[n - 1]) {
        v = f->v[n - 1];
      } else {
        int64_t lo = 0, hi = n - 1;  // t[lo] <= t < t[hi]
        while (hi - lo > 1) {
          int64_t mid = (lo + hi) / 2;
          if (f->t[mid] <= t)
            lo = mid;
          else
            hi = mid;
        }
        double sl = (f->v[hi] - f->v[lo]) / (f->t[hi] - f->t[lo]);
        v = f->v[lo] + sl * (t - f->t[lo]);
        d = sl;
      }
      break;
    }
    default:
      break;
  }
  if (dfdt) *dfdt = d;
  if (d2fdt2) *d2fdt2 = dd;
  return v;
}

fmbd_mbs_fn fmbd_mbs_fn_constant(double value) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_CONSTANT, f.value = value;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_linear(double t0, double v0, double rate) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_LINEAR, f.t0 = t0, f.v0 = v0, f.rate = rate;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_ramp(double t0, double v0, double t1, double v1, bool smooth) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_RAMP, f.t0 = t0, f.v0 = v0, f.t1 = t1, f.v1 = v1, f.smooth = smooth;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_sine(double offset, double amplitude, double frequency_hz, double phase) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_SINE, f.offset = offset, f.amplitude = amplitude;
  f.frequency_hz = frequency_hz, f.phase = phase;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_table(int64_t n, const double *t, const double *v) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_TABLE, f.n = n, f.t = t, f.v = v;
  return f;
}

// copy a function (table arrays owned by the copy)
static int fn_copy(const fmbd_mbs_fn *src, fmbd_mbs_fn *dst, const char *what) {
  *dst = *src;
  dst->t = dst->v = NULL;
  FMBD_CHECK(src->kind >= FMBD_MBS_FN_CONSTANT && src->kind <= FMBD_MBS_FN_LINEAR, FMBD_ERR_VALUE,
             "%s: unknown function kind %d", what, src->kind);
  if (src->kind == FMBD_MBS_FN_RAMP) {
    FMBD_CHECK(src->t1 > src->t0, FMBD_ERR_VALUE, "%s: ramp needs t1 > t0", what);
  }
  if (src->kind == FMBD_MBS_FN_TABLE) {
    FMBD_CHECK(src->n >= 1 && src->t && src->v, FMBD_ERR_VALUE, "%s: empty table", what);
    for (int64_t i = 1; i < src->n; i++) {
      FMBD_CHECK(src->t[i] > src->t[i - 1], FMBD_ERR_VALUE,
                 "%s: table times not increasing at point %lld", what, (long long)i);
    }
    double *t = fmbd_malloc(sizeof(double) * (size_t)src->n);
    double *v = fmbd_malloc(sizeof(double) * (size_t)src->n);
    if (!t || !v) {
      fmbd_free(t), fmbd_free(v);
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    memcpy(t, src->t, sizeof(double) * (size_t)src->n);
    memcpy(v, src->v, sizeof(double) * (size_t)src->n);
    dst->t = t, dst->v = v;
  }
  return FMBD_OK;
}
static void fn_free(fmbd_mbs_fn *f) {
  if (f->kind == FMBD_MBS_FN_TABLE) {
    fmbd_free((void *)f->t), fmbd_free((void *)f->v);
  }
  f->t = f->v = NULL;
}

// ============================================================================================
// the system
// ============================================================================================
typedef struct mbody {
  char *name;
  int nm, n;    // modes; coordinates 7 + nm
  int64_t off;  // first coordinate in x
  double m, c0[3], J0[9];
  double *S1, *XS, *SS, *Mff, *Kff, *Dff;  // layouts of fmbd_mbs.h; Dff nm x nm
  double *XSx;                             // 3 x nm: int rho x0 x S_k
  double *SSx;                 // 3 x nm x nm: SSx[a + 3 l + 3 nm k] = (int rho S_l x S_k)_a
  double snorm;                // scale of the normalisation equation
  double gyr;                  // radius of gyration about the origin (m)
  double x0[7], v0[3], w0[3];  // initial R, p; velocity, angular velocity (world)
  double *q0, *qd0;
  // --- evaluation workspace (filled by body_eval) ---
  double A[9], G[12], pn, wb[3], c[3], J[9], I[9];
  double *P;    // 9 nm: P_k[a + 3b] = sum_l q_l SS[a + 3b + 9k + 9 nm l]
  double *Hk;   // 9 nm: H_k[a + 3b] = int rho S_k,a u_b
  double *Mwf;  // 3 x nm
  double *cor;  // 3 x nm: sum_l q'_l int rho S_l x S_k
  bool kdiag;   // Kff and Dff diagonal (the usual modal body): O(nm) elastic forces
} mbody;

typedef struct mpoint {
  int body;
  double x0[3];
  double *T, *Rr;  // 3 x nm each or NULL
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
  int64_t *pr, *pc;  // positions in Ax of (row, col) and (col, row) per jac entry
  char *text;        // description (redundant ones)
} meq;

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
  fmbd_mbs_settings set;
  // --- dimensions and state ---
  int64_t n, neq, m, N;  // coordinates, all equations, kept, matrix size
  meq *eq;
  double t;
  double *x, *xd, *xdd, *a, *lam;       // lam: physical multipliers (m)
  double *xn, *xdn, *xddn, *an, *lamn;  // state at the start of the step
  double *xddp;                         // x'' one step before
  double *res, *rhs, *scale, *nscale, *ascale, *floor_;
  double Lref;
  int maxn;
  double *wk;           // side kinematics workspace
  double *bres, *bblk;  // per-body residual (n) and block (n^2), max size
  double *bwork;        // per-body workspace
  // --- generalized alpha ---
  double am, af, beta, gamma;
  double h_next, h_fact, h_prop, h_prev;
  int64_t k_out;
  int64_t worst_i;  // largest scaled residual of the last iterate
  double worst_v;
  int64_t worst_dx;  // coordinate of the largest Newton correction
  bool need_factor, after_reject;
  // --- sparse matrix and KLU ---
  int64_t nnz;
  SuiteSparse_long *Ap, *Ai;
  double *Ax;
  int64_t **bpos;  // per body n^2 positions
  klu_l_common kc;
  klu_l_symbolic *sym;
  klu_l_numeric *num;
  // --- results ---
  fmbd_mbs_stats st;
  int nred;
  int *red;  // equation indices removed
  double qmax_init;
};

#define GROW(arr, cnt, cap, T)                                   \
  do {                                                           \
    if ((cnt) == (cap)) {                                        \
      int nc_ = (cap) ? 2 * (cap) : 8;                           \
      T *np_ = fmbd_realloc((arr), sizeof(T) * (size_t)nc_);     \
      if (!np_) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");      \
      memset(np_ + (cap), 0, sizeof(T) * (size_t)(nc_ - (cap))); \
      (arr) = np_, (cap) = nc_;                                  \
    }                                                            \
  } while (0)

void fmbd_mbs_settings_defaults(fmbd_mbs_settings *s) {
  memset(s, 0, sizeof *s);
  s->t_end = 1;
  s->rho_inf = 0.9;
  s->fixed = false;
  s->step = 1e-3;
  s->first_step = 1e-6;
  s->min_step = 1e-12;
  s->max_step = 1e-2;
  s->tolerance = 1e-4;
  s->newton_tol = 1e-8;
  s->newton_max = 10;
  s->output_every = 0;
  s->reactions = false;
  s->max_steps = 0;
}

fmbd_mbs_state0 fmbd_mbs_state0_default(void) {
  fmbd_mbs_state0 s;
  memset(&s, 0, sizeof s);
  s.rotation[0] = s.rotation[4] = s.rotation[8] = 1;
  return s;
}

int fmbd_mbs_create(fmbd_mbs **out) {
  *out = NULL;
  fmbd_mbs *m = fmbd_calloc(1, sizeof *m);
  FMBD_CHECK(m, FMBD_ERR_NOMEM, "out of memory");
  fmbd_mbs_settings_defaults(&m->set);
  *out = m;
  return FMBD_OK;
}

static void body_free(mbody *b) {
  fmbd_free(b->name);
  fmbd_free(b->S1), fmbd_free(b->XS), fmbd_free(b->SS), fmbd_free(b->Mff), fmbd_free(b->Kff);
  fmbd_free(b->Dff), fmbd_free(b->XSx), fmbd_free(b->SSx), fmbd_free(b->q0), fmbd_free(b->qd0);
  fmbd_free(b->P), fmbd_free(b->Hk), fmbd_free(b->Mwf), fmbd_free(b->cor);
}

void fmbd_mbs_destroy(fmbd_mbs **mp) {
  if (!mp || !*mp) return;
  fmbd_mbs *m = *mp;
  for (int i = 0; i < m->nb; i++) body_free(&m->b[i]);
  fmbd_free(m->b);
  for (int i = 0; i < m->np; i++) fmbd_free(m->p[i].T), fmbd_free(m->p[i].Rr);
  fmbd_free(m->p);
  for (int i = 0; i < m->nj; i++) fmbd_free(m->j[i].name);
  fmbd_free(m->j);
  for (int i = 0; i < m->nd; i++) fmbd_free(m->d[i].name), fn_free(&m->d[i].f);
  fmbd_free(m->d);
  for (int i = 0; i < m->nl; i++) fmbd_free(m->l[i].name), fn_free(&m->l[i].f);
  fmbd_free(m->l);
  if (m->eq) {
    for (int64_t e = 0; e < m->neq; e++) {
      fmbd_free(m->eq[e].jac), fmbd_free(m->eq[e].pr), fmbd_free(m->eq[e].pc),
          fmbd_free(m->eq[e].text);
    }
    fmbd_free(m->eq);
  }
  double *arrs[] = {m->x,      m->xd,   m->xdd,  m->a,    m->lam,   m->xn,    m->xdn,    m->xddn,
                    m->an,     m->lamn, m->xddp, m->res,  m->rhs,   m->scale, m->nscale, m->ascale,
                    m->floor_, m->wk,   m->bres, m->bblk, m->bwork, m->Ax};
  for (size_t i = 0; i < sizeof arrs / sizeof arrs[0]; i++) fmbd_free(arrs[i]);
  fmbd_free(m->Ap), fmbd_free(m->Ai);
  if (m->bpos) {
    for (int i = 0; i < m->nb; i++) fmbd_free(m->bpos[i]);
    fmbd_free(m->bpos);
  }
  if (m->num) klu_l_free_numeric(&m->num, &m->kc);
  if (m->sym) klu_l_free_symbolic(&m->sym, &m->kc);
  fmbd_free(m->red);
  fmbd_free(m);
  *mp = NULL;
}

static bool finite_n(const double *v, int64_t n) {
  for (int64_t i = 0; i < n; i++) {
    if (!isfinite(v[i])) return false;
  }
  return true;
}

static int check_name(const fmbd_mbs *m, const char *name, const char *what) {
  FMBD_CHECK(name && name[0], FMBD_ERR_VALUE, "%s without a name", what);
  return FMBD_OK;
}

static int check_state0(const char *name, const fmbd_mbs_state0 *s) {
  FMBD_CHECK(finite_n(s->position, 3) && finite_n(s->rotation, 9) && finite_n(s->velocity, 3) &&
                 finite_n(s->angular_velocity, 3),
             FMBD_ERR_VALUE, "body '%s': non-finite initial state", name);
  const double *A = s->rotation;
  double err = 0;
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      double v = A[i] * A[j] + A[3 + i] * A[3 + j] + A[6 + i] * A[6 + j] - (i == j ? 1 : 0);
      err = fmax(err, fabs(v));
    }
  }
  double det = A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) +
               A[2] * (A[3] * A[7] - A[4] * A[6]);
  FMBD_CHECK(
      err < 1e-6 && det > 0, FMBD_ERR_VALUE,
      "body '%s': initial rotation is not a proper orthonormal matrix (|A'A - 1| = %.3g, det %.6g)",
      name, err, det);
  return FMBD_OK;
}

// common part of rigid and flexible bodies
static int add_body(fmbd_mbs *m, const char *name, int nm, const fmbd_mbs_state0 *s0, mbody **out) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "body '%s' added after fmbd_mbs_init", name ? name : "?");
  FMBD_CALL(check_name(m, name, "body"));
  for (int i = 0; i < m->nb; i++) {
    FMBD_CHECK(strcmp(m->b[i].name, name) != 0, FMBD_ERR_VALUE, "duplicate body name '%s'", name);
  }
  FMBD_CHECK(s0, FMBD_ERR_VALUE, "body '%s': no initial state", name);
  FMBD_CALL(check_state0(name, s0));
  GROW(m->b, m->nb, m->nbcap, mbody);
  mbody *b = &m->b[m->nb];
  memset(b, 0, sizeof *b);
  b->name = fmbd_strdup(name);
  FMBD_CHECK(b->name, FMBD_ERR_NOMEM, "out of memory");
  b->nm = nm, b->n = 7 + nm;
  memcpy(b->x0, s0->position, sizeof(double) * 3);
  A_to_quat(s0->rotation, b->x0 + 3);
  memcpy(b->v0, s0->velocity, sizeof(double) * 3);
  memcpy(b->w0, s0->angular_velocity, sizeof(double) * 3);
  m->nb++;
  *out = b;
  return FMBD_OK;
}

// scale of the normalisation equation and gyration radius from J0
static void body_scales(mbody *b) {
  double trJ = b->J0[0] + b->J0[4] + b->J0[8];
  // inertia about the origin: tr(J) 1 - J; mean principal value = 2 tr(J) / 3
  double imean = 2 * trJ / 3;
  b->snorm = 4 * imean > 0 ? 4 * imean : b->m;
  b->gyr = sqrt(fmax(trJ / b->m, 0));
}

int fmbd_mbs_add_rigid(fmbd_mbs *m, const char *name, double mass, const double com[3],
                       const double inertia[9], const fmbd_mbs_state0 *s0, int *id) {
  FMBD_CHECK(isfinite(mass) && mass > 0, FMBD_ERR_VALUE, "body '%s': mass %g must be positive",
             name ? name : "?", mass);
  FMBD_CHECK(com && inertia && finite_n(com, 3) && finite_n(inertia, 9), FMBD_ERR_VALUE,
             "body '%s': missing or non-finite centre of mass or inertia", name ? name : "?");
  // symmetric positive definite inertia (Sylvester) and triangle inequality
  const double *I = inertia;
  double asym = fmax(fabs(I[1] - I[3]), fmax(fabs(I[2] - I[6]), fabs(I[5] - I[7])));
  double sc = fabs(I[0]) + fabs(I[4]) + fabs(I[8]);
  double d1 = I[0], d2 = I[0] * I[4] - I[1] * I[3];
  double d3 = I[0] * (I[4] * I[8] - I[5] * I[7]) - I[1] * (I[3] * I[8] - I[5] * I[6]) +
              I[2] * (I[3] * I[7] - I[4] * I[6]);
  FMBD_CHECK(asym <= 1e-9 * sc && d1 > 0 && d2 > 0 && d3 > 0, FMBD_ERR_VALUE,
             "body '%s': inertia tensor is not symmetric positive definite", name ? name : "?");
  mbody *b;
  FMBD_CALL(add_body(m, name, 0, s0, &b));
  b->m = mass;
  for (int a = 0; a < 3; a++) b->c0[a] = mass * com[a];
  // J_c = tr(Ic)/2 1 - Ic; J0 = J_c + m com com'
  double tr = I[0] + I[4] + I[8];
  for (int a = 0; a < 3; a++) {
    for (int c = 0; c < 3; c++) {
      b->J0[3 * a + c] =
          (a == c ? tr / 2 : 0) - 0.5 * (I[3 * a + c] + I[3 * c + a]) + mass * com[a] * com[c];
    }
  }
  body_scales(b);
  if (id) *id = m->nb - 1;
  return FMBD_OK;
}

int fmbd_mbs_add_flex(fmbd_mbs *m, const char *name, const fmbd_mbs_flex_data *d,
                      const fmbd_mbs_state0 *s0, int *id) {
  const char *nm_ = name ? name : "?";
  FMBD_CHECK(d, FMBD_ERR_VALUE, "body '%s': no flexible data", nm_);
  FMBD_CHECK(d->nm >= 0 && d->nm <= 10000, FMBD_ERR_VALUE, "body '%s': bad number of modes %lld",
             nm_, (long long)d->nm);
  FMBD_CHECK(isfinite(d->mass) && d->mass > 0, FMBD_ERR_VALUE,
             "body '%s': mass %g must be positive", nm_, d->mass);
  FMBD_CHECK(finite_n(d->first_moment, 3) && finite_n(d->second_moment, 9), FMBD_ERR_VALUE,
             "body '%s': non-finite first or second moment", nm_);
  int64_t nm = d->nm;
  if (nm > 0) {
    FMBD_CHECK(d->S1 && d->XS && d->SS && d->Mff && d->Kff, FMBD_ERR_VALUE,
               "body '%s': missing modal invariants (S1, XS, SS, Mff, Kff)", nm_);
    FMBD_CHECK(finite_n(d->S1, 3 * nm) && finite_n(d->XS, 9 * nm) && finite_n(d->SS, 9 * nm * nm) &&
                   finite_n(d->Mff, nm * nm) && finite_n(d->Kff, nm * nm),
               FMBD_ERR_VALUE, "body '%s': non-finite modal invariants", nm_);
    FMBD_CHECK(isfinite(d->damping_ratio) && d->damping_ratio >= 0, FMBD_ERR_VALUE,
               "body '%s': damping ratio %g must be >= 0", nm_, d->damping_ratio);
    // Mff positive definite (Cholesky, plain loops: nm is small)
    double *L = fmbd_malloc(sizeof(double) * (size_t)(nm * nm));
    FMBD_CHECK(L, FMBD_ERR_NOMEM, "out of memory");
    memcpy(L, d->Mff, sizeof(double) * (size_t)(nm * nm));
    bool pd = true;
    for (int64_t j = 0; j < nm && pd; j++) {
      double s = L[j + nm * j];
      for (int64_t k = 0; k < j; k++) s -= L[j + nm * k] * L[j + nm * k];
      if (!(s > 0)) {
        pd = false;
        break;
      }
      s = sqrt(s);
      L[j + nm * j] = s;
      for (int64_t i = j + 1; i < nm; i++) {
        double t = L[i + nm * j];
        for (int64_t k = 0; k < j; k++) t -= L[i + nm * k] * L[j + nm * k];
        L[i + nm * j] = t / s;
      }
    }
    fmbd_free(L);
    FMBD_CHECK(pd, FMBD_ERR_SINGULAR, "body '%s': modal mass matrix Mff is not positive definite",
               nm_);
  }
  {
    // the rigid part of the mass matrix is regular iff the inertia about the centre of mass,
    // Ic = tr(Jc) 1 - Jc with Jc = J0 - c0 c0'/m, is positive definite (mass not on a line,
    // e.g. lumped beam nodes); the iteration matrix may still be regular when joints hold the
    // rotation without inertia, so this is only noted (fmbd_mbs_init names what is singular)
    double Jc[9], Ic[9];
    for (int a = 0; a < 3; a++)
      for (int c = 0; c < 3; c++)
        Jc[3 * a + c] = 0.5 * (d->second_moment[3 * a + c] + d->second_moment[3 * c + a]) -
                        d->first_moment[a] * d->first_moment[c] / d->mass;
    double tr = Jc[0] + Jc[4] + Jc[8];
    for (int i = 0; i < 9; i++) Ic[i] = -Jc[i];
    Ic[0] += tr, Ic[4] += tr, Ic[8] += tr;
    double d1 = Ic[0], d2 = Ic[0] * Ic[4] - Ic[1] * Ic[3];
    double d3 = Ic[0] * (Ic[4] * Ic[8] - Ic[5] * Ic[7]) - Ic[1] * (Ic[3] * Ic[8] - Ic[5] * Ic[6]) +
                Ic[2] * (Ic[3] * Ic[7] - Ic[4] * Ic[6]);
    double sc = fabs(tr) > 0 ? fabs(tr) : 1;
    if (!(d1 > 1e-12 * sc && d2 > 1e-12 * sc * sc && d3 > 1e-12 * sc * sc * sc)) {
      fmbd_log(FMBD_LOG_INFO,
               "body '%s': singular mass matrix: the inertia about the centre of mass (%.3g %.3g "
               "%.3g on the "
               "diagonal) is not positive definite; joints must hold the rotation it leaves free",
               nm_, Ic[0], Ic[4], Ic[8]);
    }
  }
  mbody *b;
  FMBD_CALL(add_body(m, name, (int)nm, s0, &b));
  b->m = d->mass;
  memcpy(b->c0, d->first_moment, sizeof b->c0);
  for (int a = 0; a < 3; a++) {
    for (int c = 0; c < 3; c++)
      b->J0[3 * a + c] = 0.5 * (d->second_moment[3 * a + c] + d->second_moment[3 * c + a]);
  }
  body_scales(b);
  if (nm > 0) {
    size_t n1 = (size_t)nm;
    b->S1 = fmbd_malloc(sizeof(double) * 3 * n1);
    b->XS = fmbd_malloc(sizeof(double) * 9 * n1);
    b->SS = fmbd_malloc(sizeof(double) * 9 * n1 * n1);
    b->Mff = fmbd_malloc(sizeof(double) * n1 * n1);
    b->Kff = fmbd_malloc(sizeof(double) * n1 * n1);
    b->Dff = fmbd_calloc(n1 * n1, sizeof(double));
    b->XSx = fmbd_calloc(3 * n1, sizeof(double));
    b->SSx = fmbd_calloc(3 * n1 * n1, sizeof(double));
    b->q0 = fmbd_calloc(n1, sizeof(double));
    b->qd0 = fmbd_calloc(n1, sizeof(double));
    b->P = fmbd_calloc(9 * n1, sizeof(double));
    b->Hk = fmbd_calloc(9 * n1, sizeof(double));
    b->Mwf = fmbd_calloc(3 * n1, sizeof(double));
    b->cor = fmbd_calloc(3 * n1, sizeof(double));
    FMBD_CHECK(b->S1 && b->XS && b->SS && b->Mff && b->Kff && b->Dff && b->XSx && b->SSx && b->q0 &&
                   b->qd0 && b->P && b->Hk && b->Mwf && b->cor,
               FMBD_ERR_NOMEM, "out of memory");
    memcpy(b->S1, d->S1, sizeof(double) * 3 * n1);
    memcpy(b->XS, d->XS, sizeof(double) * 9 * n1);
    memcpy(b->SS, d->SS, sizeof(double) * 9 * n1 * n1);
    for (size_t i = 0; i < n1; i++) {
      for (size_t k = 0; k < n1; k++) {
        b->Mff[i + n1 * k] = 0.5 * (d->Mff[i + n1 * k] + d->Mff[k + n1 * i]);
        b->Kff[i + n1 * k] = 0.5 * (d->Kff[i + n1 * k] + d->Kff[k + n1 * i]);
      }
    }
    // modal damping: D = 2 zeta sqrt(K_kk M_kk) on the diagonal (modes are K- and
    // M-orthogonal, so this is the classical modal damping)
    for (size_t k = 0; k < n1; k++) {
      double kk = b->Kff[k + n1 * k], mk = b->Mff[k + n1 * k];
      b->Dff[k + n1 * k] = 2 * d->damping_ratio * sqrt(fmax(kk, 0) * mk);
    }
    b->kdiag = true;
    for (size_t i = 0; i < n1 && b->kdiag; i++) {
      for (size_t k = 0; k < n1; k++) {
        if (i != k && b->Kff[i + n1 * k] != 0) {
          b->kdiag = false;
          break;
        }
      }
    }
    if (d->q0) memcpy(b->q0, d->q0, sizeof(double) * n1);
    if (d->qd0) memcpy(b->qd0, d->qd0, sizeof(double) * n1);
    FMBD_CHECK(finite_n(b->q0, nm) && finite_n(b->qd0, nm), FMBD_ERR_VALUE,
               "body '%s': non-finite q0 or qd0", nm_);
    // XSx_k = int rho x0 x S_k: a-component eps_abc XS[b + 3c + 9k]
    for (size_t k = 0; k < n1; k++) {
      const double *X = b->XS + 9 * k;
      double *o = b->XSx + 3 * k;
      o[0] = X[1 + 3 * 2] - X[2 + 3 * 1];
      o[1] = X[2 + 3 * 0] - X[0 + 3 * 2];
      o[2] = X[0 + 3 * 1] - X[1 + 3 * 0];
    }
    // SSx[l,k] = int rho S_l x S_k: a-component eps_abc SS[b + 3c + 9l + 9nm k]
    for (size_t k = 0; k < n1; k++) {
      for (size_t l = 0; l < n1; l++) {
        const double *S = b->SS + 9 * l + 9 * n1 * k;
        double *o = b->SSx + 3 * l + 3 * n1 * k;
        o[0] = S[1 + 3 * 2] - S[2 + 3 * 1];
        o[1] = S[2 + 3 * 0] - S[0 + 3 * 2];
        o[2] = S[0 + 3 * 1] - S[1 + 3 * 0];
      }
    }
  }
  if (id) *id = m->nb - 1;
  return FMBD_OK;
}

int fmbd_mbs_add_point(fmbd_mbs *m, int body, const double x0[3], const double *T,
                       const double *Rot, int *pid) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "point added after fmbd_mbs_init");
  FMBD_CHECK(body == FMBD_MBS_GROUND || (body >= 0 && body < m->nb), FMBD_ERR_VALUE,
             "point on unknown body %d", body);
  FMBD_CHECK(x0 && finite_n(x0, 3), FMBD_ERR_VALUE, "point: missing or non-finite position");
  int nm = body >= 0 ? m->b[body].nm : 0;
  if (nm > 0) {
    FMBD_CHECK((!T || finite_n(T, 3 * nm)) && (!Rot || finite_n(Rot, 3 * nm)), FMBD_ERR_VALUE,
               "point on body '%s': non-finite modal translation or rotation", m->b[body].name);
  }
  GROW(m->p, m->np, m->npcap, mpoint);
  mpoint *p = &m->p[m->np];
  memset(p, 0, sizeof *p);
  p->body = body;
  memcpy(p->x0, x0, sizeof p->x0);
  if (nm > 0) {
    p->T = fmbd_calloc(3 * (size_t)nm, sizeof(double));
    p->Rr = fmbd_calloc(3 * (size_t)nm, sizeof(double));
    if (!p->T || !p->Rr) {
      fmbd_free(p->T), fmbd_free(p->Rr);
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    if (T) memcpy(p->T, T, sizeof(double) * 3 * (size_t)nm);
    if (Rot) memcpy(p->Rr, Rot, sizeof(double) * 3 * (size_t)nm);
  }
  m->np++;
  if (pid) *pid = m->np - 1;
  return FMBD_OK;
}

int fmbd_mbs_add_point_world(fmbd_mbs *m, int body, const double xw[3], int *pid) {
  FMBD_CHECK(body == FMBD_MBS_GROUND || (body >= 0 && body < m->nb), FMBD_ERR_VALUE,
             "point on unknown body %d", body);
  FMBD_CHECK(xw && finite_n(xw, 3), FMBD_ERR_VALUE, "point: missing or non-finite position");
  double x0[3];
  if (body == FMBD_MBS_GROUND) {
    memcpy(x0, xw, sizeof x0);
  } else {
    const mbody *b = &m->b[body];
    double A[9], d[3] = {xw[0] - b->x0[0], xw[1] - b->x0[1], xw[2] - b->x0[2]};
    quat_to_A(b->x0 + 3, A);
    mtv3(A, d, x0);
  }
  return fmbd_mbs_add_point(m, body, x0, NULL, NULL, pid);
}

int fmbd_mbs_joint_equations(int kind) {
  switch (kind) {
    case FMBD_MBS_SPHERICAL:
      return 3;
    case FMBD_MBS_REVOLUTE:
      return 5;
    case FMBD_MBS_UNIVERSAL:
      return 4;
    case FMBD_MBS_PRISMATIC:
      return 5;
    case FMBD_MBS_CYLINDRICAL:
      return 4;
    case FMBD_MBS_FIXED:
      return 6;
    default:
      return -1;
  }
}
static const char *joint_kind_name(int kind) {
  static const char *names[] = {"spherical", "revolute",    "universal",
                                "prismatic", "cylindrical", "fixed"};
  return kind >= 0 && kind <= FMBD_MBS_FIXED ? names[kind] : "?";
}

// world -> local direction of a side (ground: world)
static void to_local(const fmbd_mbs *m, int body, const double *w, double *l) {
  if (body < 0) {
    memcpy(l, w, 3 * sizeof(double));
    return;
  }
  double A[9];
  quat_to_A(m->b[body].x0 + 3, A);
  mtv3(A, w, l);
}

int fmbd_mbs_add_joint(fmbd_mbs *m, const fmbd_mbs_joint_desc *jd, int *jid) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "joint added after fmbd_mbs_init");
  FMBD_CHECK(jd, FMBD_ERR_VALUE, "joint: no description");
  FMBD_CALL(check_name(m, jd->name, "joint"));
  const char *nm = jd->name;
  for (int i = 0; i < m->nj; i++) {
    FMBD_CHECK(strcmp(m->j[i].name, nm) != 0, FMBD_ERR_VALUE, "duplicate joint name '%s'", nm);
  }
  int neq = fmbd_mbs_joint_equations(jd->kind);
  FMBD_CHECK(neq > 0, FMBD_ERR_VALUE, "joint '%s': unknown kind %d", nm, jd->kind);
  int body[2];
  for (int s = 0; s < 2; s++) {
    FMBD_CHECK(jd->point[s] >= 0 && jd->point[s] < m->np, FMBD_ERR_VALUE,
               "joint '%s': unknown point %d", nm, jd->point[s]);
    body[s] = m->p[jd->point[s]].body;
  }
  FMBD_CHECK(body[0] != body[1], FMBD_ERR_VALUE, "joint '%s': both sides on the same %s", nm,
             body[0] < 0 ? "ground" : "body");
  FMBD_CHECK(finite_n(jd->axis, 3) && finite_n(jd->axis2, 3) && finite_n(jd->ref, 3),
             FMBD_ERR_VALUE, "joint '%s': non-finite axis", nm);
  // world frame of the joint: z = axis, x = ref (projected) or any normal
  double z[3] = {0, 0, 1}, x[3], y[3];
  double na = norm3(jd->axis);
  bool needs_axis = jd->kind != FMBD_MBS_SPHERICAL && jd->kind != FMBD_MBS_FIXED;
  FMBD_CHECK(!needs_axis || na > 0, FMBD_ERR_VALUE, "joint '%s' (%s): zero axis", nm,
             joint_kind_name(jd->kind));
  if (na > 0) {
    for (int a = 0; a < 3; a++) z[a] = jd->axis[a] / na;
  }
  double r[3];
  memcpy(r, jd->ref, sizeof r);
  double rz = dot3(r, z);
  for (int a = 0; a < 3; a++) r[a] -= rz * z[a];
  if (norm3(r) < 1e-9 * fmax(1, norm3(jd->ref))) {
    // choose: the world axis least aligned with z
    int k = 0;
    for (int a = 1; a < 3; a++) {
      if (fabs(z[a]) < fabs(z[k])) k = a;
    }
    double e[3] = {0, 0, 0};
    e[k] = 1;
    double ez = dot3(e, z);
    for (int a = 0; a < 3; a++) r[a] = e[a] - ez * z[a];
  }
  double nr = norm3(r);
  for (int a = 0; a < 3; a++) x[a] = r[a] / nr;
  cross3(z, x, y);
  GROW(m->j, m->nj, m->njcap, mjoint);
  mjoint *j = &m->j[m->nj];
  memset(j, 0, sizeof *j);
  j->kind = jd->kind, j->neq = neq;
  j->pt[0] = jd->point[0], j->pt[1] = jd->point[1];
  j->body[0] = body[0], j->body[1] = body[1];
  for (int s = 0; s < 2; s++) {
    to_local(m, body[s], x, j->e[s][0]);
    to_local(m, body[s], y, j->e[s][1]);
    to_local(m, body[s], z, j->e[s][2]);
  }
  if (jd->kind == FMBD_MBS_UNIVERSAL) {
    double n2 = norm3(jd->axis2);
    FMBD_CHECK(n2 > 0, FMBD_ERR_VALUE, "joint '%s' (universal): zero axis2", nm);
    double a2[3] = {jd->axis2[0] / n2, jd->axis2[1] / n2, jd->axis2[2] / n2};
    FMBD_CHECK(fabs(dot3(a2, z)) < 1e-6, FMBD_ERR_VALUE,
               "joint '%s' (universal): axis and axis2 are not orthogonal (cos = %.3g)", nm,
               dot3(a2, z));
    to_local(m, body[1], a2, j->a2);
  }
  j->name = fmbd_strdup(nm);
  FMBD_CHECK(j->name, FMBD_ERR_NOMEM, "out of memory");
  m->nj++;
  if (jid) *jid = m->nj - 1;
  return FMBD_OK;
}

static int add_driver(fmbd_mbs *m, const char *name, int joint, int body, int coord,
                      const fmbd_mbs_fn *f, int *did) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "driver added after fmbd_mbs_init");
  FMBD_CALL(check_name(m, name, "driver"));
  FMBD_CHECK(f, FMBD_ERR_VALUE, "driver '%s': no function", name);
  GROW(m->d, m->nd, m->ndcap, mdriver);
  mdriver *d = &m->d[m->nd];
  memset(d, 0, sizeof *d);
  char what[300];
  snprintf(what, sizeof what, "driver '%s'", name);
  FMBD_CALL(fn_copy(f, &d->f, what));
  d->name = fmbd_strdup(name);
  if (!d->name) {
    fn_free(&d->f);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  d->joint = joint, d->body = body, d->coord = coord;
  m->nd++;
  if (did) *did = m->nd - 1;
  return FMBD_OK;
}

int fmbd_mbs_add_driver_joint(fmbd_mbs *m, const char *name, int joint, const fmbd_mbs_fn *f,
                              int *did) {
  FMBD_CHECK(joint >= 0 && joint < m->nj, FMBD_ERR_VALUE, "driver '%s': unknown joint %d",
             name ? name : "?", joint);
  int k = m->j[joint].kind;
  FMBD_CHECK(k == FMBD_MBS_REVOLUTE || k == FMBD_MBS_PRISMATIC || k == FMBD_MBS_CYLINDRICAL,
             FMBD_ERR_VALUE,
             "driver '%s': joint '%s' is %s; only revolute, prismatic and cylindrical joints have "
             "a driven coordinate",
             name ? name : "?", m->j[joint].name, joint_kind_name(k));
  return add_driver(m, name, joint, -1, 0, f, did);
}

int fmbd_mbs_add_driver_body(fmbd_mbs *m, const char *name, int body, int coordinate,
                             const fmbd_mbs_fn *f, int *did) {
  FMBD_CHECK(body >= 0 && body < m->nb, FMBD_ERR_VALUE, "driver '%s': unknown body %d",
             name ? name : "?", body);
  FMBD_CHECK(coordinate >= 0 && coordinate < 3 + m->b[body].nm, FMBD_ERR_VALUE,
             "driver '%s': body '%s' has no coordinate %d (0..2 position, 3.. modal)",
             name ? name : "?", m->b[body].name, coordinate);
  return add_driver(m, name, -1, body, coordinate, f, did);
}

int fmbd_mbs_add_load(fmbd_mbs *m, const char *name, int kind, int point, bool body_frame,
                      const double direction[3], const fmbd_mbs_fn *f, int *lid) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "load added after fmbd_mbs_init");
  FMBD_CALL(check_name(m, name, "load"));
  FMBD_CHECK(kind == FMBD_MBS_FORCE || kind == FMBD_MBS_TORQUE, FMBD_ERR_VALUE,
             "load '%s': unknown kind %d", name, kind);
  FMBD_CHECK(point >= 0 && point < m->np, FMBD_ERR_VALUE, "load '%s': unknown point %d", name,
             point);
  FMBD_CHECK(m->p[point].body >= 0, FMBD_ERR_VALUE, "load '%s': a load on ground does nothing",
             name);
  FMBD_CHECK(direction && finite_n(direction, 3), FMBD_ERR_VALUE,
             "load '%s': missing or non-finite direction", name);
  FMBD_CHECK(f, FMBD_ERR_VALUE, "load '%s': no function", name);
  GROW(m->l, m->nl, m->nlcap, mload);
  mload *l = &m->l[m->nl];
  memset(l, 0, sizeof *l);
  char what[300];
  snprintf(what, sizeof what, "load '%s'", name);
  FMBD_CALL(fn_copy(f, &l->f, what));
  l->name = fmbd_strdup(name);
  if (!l->name) {
    fn_free(&l->f);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  l->kind = kind, l->pt = point, l->body_frame = body_frame;
  memcpy(l->dir, direction, sizeof l->dir);
  m->nl++;
  if (lid) *lid = m->nl - 1;
  return FMBD_OK;
}

void fmbd_mbs_set_gravity(fmbd_mbs *m, const double g[3]) {
  memcpy(m->g, g, sizeof m->g);
}

// ============================================================================================
// body equations (fmbd_mbs.h, EQUATIONS)
// ============================================================================================
// mass given to the direction p of the Euler parameters (relative to the normalisation
// scale): makes the dynamics block regular (the mass-weighted projections of fmbd_mbs_init
// and the conditioning of the iteration matrix); physics unchanged since G p = 0
#define PMASS 0.25

// y = alpha A x, A m x n column-major: column-wise axpy loops that the compiler vectorises;
// BLAS dgemv was slower here (OpenBLAS threads and packs even these small products)
static void matvec(int m, int n, const double *restrict A, const double *restrict x, double alpha,
                   double *restrict y) {
  for (int i = 0; i < m; i++) y[i] = 0;
  for (int j = 0; j < n; j++) {
    double xj = alpha * x[j];
    if (xj == 0) continue;
    const double *restrict a = A + (size_t)m * j;
    for (int i = 0; i < m; i++) y[i] += xj * a[i];
  }
}
// predictor x''_{n+1} by linear extrapolation (1) or constant (0); refresh the iteration
// matrix when the Newton contraction rate exceeds THETA_REFACTOR (measured on t500-t502:
// 0.1 with extrapolation halves the iterations of 0.5 at a few more factorisations)
#define PRED_EXTRAP 1
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
// body_eval: the body's residual r (n = 7 + nm) in x coordinates, r = T'(Mb acc + v - f) (+ Kq
// + Dq' in the modal rows), and optionally the block B = T'(cm Mb + cc Cb)T + ck Kx (n x n,
// column-major), T = diag(1, 2G, 1) mapping x' to [R'; wb; q'].
// xdd may be NULL (zero accelerations).
static void body_eval(fmbd_mbs *m, int ib, double t, const double *xg, const double *xdg,
                      const double *xddg, double *r, double *B, double cm, double cc, double ck) {
  mbody *b = &m->b[ib];
  const int nm = b->nm, n6 = 6 + nm, n = b->n;
  const double *x = xg + b->off, *xd = xdg + b->off, *xdd = xddg ? xddg + b->off : NULL;
  const double *p = x + 3, *q = x + 7, *pd = xd + 3, *qd = xd + 7;
  double *A = b->A, *G = b->G;
  quat_to_A(p, A);
  quat_G(p, G);
  b->pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
  double w[3], wd[3] = {0, 0, 0};
  for (int a = 0; a < 3; a++) {
    w[a] =
        2 * (G[4 * a] * pd[0] + G[4 * a + 1] * pd[1] + G[4 * a + 2] * pd[2] + G[4 * a + 3] * pd[3]);
    if (xdd) {
      const double *pdd = xdd + 3;
      wd[a] = 2 * (G[4 * a] * pdd[0] + G[4 * a + 1] * pdd[1] + G[4 * a + 2] * pdd[2] +
                   G[4 * a + 3] * pdd[3]);
    }
  }
  memcpy(b->wb, w, sizeof w);
  // --- inertia at q: c, J, H_k, Mwf, H ---
  double *c = b->c, *J = b->J, *I = b->I, H[9] = {0};
  memcpy(c, b->c0, sizeof b->c);
  memcpy(J, b->J0, sizeof b->J);
  double s1qd[3] = {0, 0, 0};
  if (nm > 0) {
    double *P = b->P;  // P = SS q, SS as a (9 nm) x nm column-major matrix
    matvec(9 * nm, nm, b->SS, q, 1.0, P);
    for (int k = 0; k < nm; k++) {
      const double *X = b->XS + 9 * k, *Pk = P + 9 * k;
      double *Hk = b->Hk + 9 * k;
      for (int a = 0; a < 3; a++) {
        c[a] += b->S1[a + 3 * k] * q[k];
        s1qd[a] += b->S1[a + 3 * k] * qd[k];
        for (int bb = 0; bb < 3; bb++) {
          // J_ab += q_k (XS_abk + XS_bak) + q_k P_k,ab; H_k,ab = XS_bak + P_k,ab
          J[3 * a + bb] += q[k] * (X[a + 3 * bb] + X[bb + 3 * a] + Pk[a + 3 * bb]);
          Hk[a + 3 * bb] = X[bb + 3 * a] + Pk[a + 3 * bb];
        }
      }
      double *Mw = b->Mwf + 3 * k;
      Mw[0] = Hk[5] - Hk[7], Mw[1] = Hk[6] - Hk[2], Mw[2] = Hk[1] - Hk[3];
      for (int i = 0; i < 9; i++) H[i] += qd[k] * Hk[i];
    }
    // symmetrise J (round-off)
    for (int a = 0; a < 3; a++) {
      for (int bb = a + 1; bb < 3; bb++) {
        double s = 0.5 * (J[3 * a + bb] + J[3 * bb + a]);
        J[3 * a + bb] = J[3 * bb + a] = s;
      }
    }
  }
  double trJ = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) I[i] = -J[i];
  I[0] += trJ, I[4] += trJ, I[8] += trJ;
  double trH = H[0] + H[4] + H[8];
  // --- Mb (n6 x n6, column-major) in bwork ---
  double *Mb = m->bwork, *Cb = m->bwork + (size_t)n6 * n6, *rb = m->bwork + 2 * (size_t)n6 * n6;
#define MB(i, j) Mb[(i) + (size_t)n6 * (j)]
#define CB(i, j) Cb[(i) + (size_t)n6 * (j)]
  memset(Mb, 0, sizeof(double) * (size_t)n6 * n6);
  double Sc[9], Ac[9];
  skew3(c, Sc);
  mm3(A, Sc, Ac);  // A c~
  for (int a = 0; a < 3; a++) {
    MB(a, a) = b->m;
    for (int bb = 0; bb < 3; bb++) {
      MB(a, 3 + bb) = -Ac[3 * a + bb];
      MB(3 + bb, a) = -Ac[3 * a + bb];
      MB(3 + a, 3 + bb) = I[3 * a + bb];
    }
  }
  for (int k = 0; k < nm; k++) {
    double as[3];
    mv3(A, b->S1 + 3 * k, as);
    for (int a = 0; a < 3; a++) {
      MB(a, 6 + k) = MB(6 + k, a) = as[a];
      MB(3 + a, 6 + k) = MB(6 + k, 3 + a) = b->Mwf[a + 3 * k];
    }
    for (int l = 0; l < nm; l++) MB(6 + k, 6 + l) = b->Mff[k + (size_t)nm * l];
  }
  // --- quadratic velocity vector v and forces f: rb = v - f (+ K q + D q') ---
  double t1[3], t2[3], Iw[3];
  cross3(w, c, t1);
  cross3(w, t1, t2);  // w x (w x c)
  double t3[3];
  cross3(w, s1qd, t3);
  for (int a = 0; a < 3; a++) t2[a] += 2 * t3[a];
  mv3(A, t2, rb);
  mv3(I, w, Iw);
  cross3(w, Iw, rb + 3);
  double Hw[3];  // (H w)_a = sum_b H[a + 3b] w_b
  for (int a = 0; a < 3; a++) Hw[a] = H[a] * w[0] + H[a + 3] * w[1] + H[a + 6] * w[2];
  for (int a = 0; a < 3; a++) rb[3 + a] += 2 * (trH * w[a] - Hw[a]);
  double ww = dot3(w, w);
  double *cor = b->cor;  // cor_k = sum_l q'_l SSx[l,k] = -sum_l SSx[k,l] q'_l (antisymmetry)
  if (nm > 0) {
    matvec(3 * nm, nm, b->SSx, qd, -1.0, cor);
  }
  for (int k = 0; k < nm; k++) {
    const double *Hk = b->Hk + 9 * k;
    double wHw = 0;
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) wHw += w[a] * Hk[a + 3 * bb] * w[bb];
    }
    double v = wHw - ww * (Hk[0] + Hk[4] + Hk[8]);
    v += 2 * dot3(w, cor + 3 * k);
    if (b->kdiag) {
      v += b->Kff[k + (size_t)nm * k] * q[k] + b->Dff[k + (size_t)nm * k] * qd[k];
    } else {
      for (int l = 0; l < nm; l++)
        v += b->Kff[k + (size_t)nm * l] * q[l] + b->Dff[k + (size_t)nm * l] * qd[l];
    }
    rb[6 + k] = v;
  }
  // gravity
  double gl[3];
  mtv3(A, m->g, gl);
  double cg[3];
  cross3(c, gl, cg);
  for (int a = 0; a < 3; a++) rb[a] -= b->m * m->g[a], rb[3 + a] -= cg[a];
  for (int k = 0; k < nm; k++) rb[6 + k] -= dot3(b->S1 + 3 * k, gl);
  // loads
  for (int il = 0; il < m->nl; il++) {
    const mload *L = &m->l[il];
    const mpoint *P = &m->p[L->pt];
    if (P->body != ib) continue;
    double fv = fmbd_mbs_fn_eval(&L->f, t, NULL, NULL);
    double Fw[3], Fl[3];
    if (L->body_frame) {
      for (int a = 0; a < 3; a++) Fl[a] = fv * L->dir[a];
      mv3(A, Fl, Fw);
    } else {
      for (int a = 0; a < 3; a++) Fw[a] = fv * L->dir[a];
      mtv3(A, Fw, Fl);
    }
    if (L->kind == FMBD_MBS_FORCE) {
      double u[3];
      memcpy(u, P->x0, sizeof u);
      for (int k = 0; k < nm; k++) {
        for (int a = 0; a < 3; a++) u[a] += P->T[a + 3 * k] * q[k];
      }
      double nn[3];
      cross3(u, Fl, nn);
      for (int a = 0; a < 3; a++) rb[a] -= Fw[a], rb[3 + a] -= nn[a];
      for (int k = 0; k < nm; k++) rb[6 + k] -= dot3(P->T + 3 * k, Fl);
    } else {
      for (int a = 0; a < 3; a++) rb[3 + a] -= Fl[a];
      for (int k = 0; k < nm; k++) rb[6 + k] -= dot3(P->Rr + 3 * k, Fl);
    }
  }
  // rb += Mb acc_b
  if (xdd) {
    for (int j = 0; j < n6; j++) {
      double aj = j < 3 ? xdd[j] : (j < 6 ? wd[j - 3] : xdd[7 + (j - 6)]);
      if (aj == 0) continue;
      const double *col = Mb + (size_t)n6 * j;
      for (int i = 0; i < n6; i++) rb[i] += col[i] * aj;
    }
  }
  // r = T' rb
  r[0] = rb[0], r[1] = rb[1], r[2] = rb[2];
  for (int c4 = 0; c4 < 4; c4++)
    r[3 + c4] = 2 * (G[c4] * rb[3] + G[4 + c4] * rb[4] + G[8 + c4] * rb[5]);
  for (int k = 0; k < nm; k++) r[7 + k] = rb[6 + k];
  // mass mu p p' on the Euler parameters (see fmbd_mbs.h): G p = 0, so the physical
  // equations are unchanged; the normalisation multiplier absorbs mu p (p . p'')
  const double mu = PMASS * b->snorm;
  if (xdd) {
    const double *pdd = xdd + 3;
    double ppdd = p[0] * pdd[0] + p[1] * pdd[1] + p[2] * pdd[2] + p[3] * pdd[3];
    for (int c4 = 0; c4 < 4; c4++) r[3 + c4] += mu * p[c4] * ppdd;
  }
  if (!B) return;
  // --- velocity tangent Cb (d v / d [R', wb, q']) ---
  memset(Cb, 0, sizeof(double) * (size_t)n6 * n6);
  if (cc != 0) {
    double S1[9], S2[9], S3[9], M1[9];
    double wc[3];
    cross3(w, c, wc);
    skew3(wc, S1);
    double Sw[9];
    skew3(w, Sw);
    mm3(Sw, Sc, S2);
    skew3(s1qd, S3);
    for (int i = 0; i < 9; i++) M1[i] = -(S1[i] + S2[i] + 2 * S3[i]);
    double AM[9];
    mm3(A, M1, AM);
    double IwS[9], SwI[9];
    skew3(Iw, IwS);
    mm3(Sw, I, SwI);
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        CB(a, 3 + bb) = AM[3 * a + bb];
        CB(3 + a, 3 + bb) =
            SwI[3 * a + bb] - IwS[3 * a + bb] + 2 * ((a == bb ? trH : 0) - H[a + 3 * bb]);
      }
    }
    for (int k = 0; k < nm; k++) {
      const double *Hk = b->Hk + 9 * k;
      double ws[3], aws[3];
      cross3(w, b->S1 + 3 * k, ws);
      mv3(A, ws, aws);
      double trk = Hk[0] + Hk[4] + Hk[8];
      double hkw[3], hktw[3];
      for (int a = 0; a < 3; a++) {
        hkw[a] = Hk[a] * w[0] + Hk[a + 3] * w[1] + Hk[a + 6] * w[2];
        hktw[a] = Hk[3 * a] * w[0] + Hk[3 * a + 1] * w[1] + Hk[3 * a + 2] * w[2];
      }
      const double *cor = b->cor + 3 * k;
      for (int l = 0; l < nm; l++) {
        const double *sx = b->SSx + 3 * l + 3 * (size_t)nm * k;
        CB(6 + k, 6 + l) = 2 * dot3(w, sx) + b->Dff[k + (size_t)nm * l];
      }
      for (int a = 0; a < 3; a++) {
        CB(a, 6 + k) = 2 * aws[a];
        CB(3 + a, 6 + k) = 2 * (trk * w[a] - hkw[a]);
        CB(6 + k, 3 + a) = hkw[a] + hktw[a] - 2 * trk * w[a] + 2 * cor[a];
      }
    }
  }
  // Z = cm Mb + cc Cb (into Mb)
  for (size_t i = 0; i < (size_t)n6 * n6; i++) Mb[i] = cm * Mb[i] + cc * Cb[i];
  // B = T' Z T
  // rows/cols map: x index i -> b index (R: i; p: via 2G; q: i - 1)
  // first Y = Z T (n6 x n), stored in Cb
  double *Y = Cb;
  for (int j = 0; j < n; j++) {
    double *yc = Y + (size_t)n6 * j;
    if (j < 3 || j >= 7) {
      int jb = j < 3 ? j : j - 1;
      memcpy(yc, Mb + (size_t)n6 * jb, sizeof(double) * (size_t)n6);
    } else {
      int c4 = j - 3;
      double g0 = 2 * G[c4], g1 = 2 * G[4 + c4], g2 = 2 * G[8 + c4];
      const double *z3 = Mb + (size_t)n6 * 3, *z4 = Mb + (size_t)n6 * 4, *z5 = Mb + (size_t)n6 * 5;
      for (int i = 0; i < n6; i++) yc[i] = z3[i] * g0 + z4[i] * g1 + z5[i] * g2;
    }
  }
  for (int j = 0; j < n; j++) {
    const double *yc = Y + (size_t)n6 * j;
    double *bc = B + (size_t)n * j;
    bc[0] = yc[0], bc[1] = yc[1], bc[2] = yc[2];
    for (int c4 = 0; c4 < 4; c4++)
      bc[3 + c4] = 2 * (G[c4] * yc[3] + G[4 + c4] * yc[4] + G[8 + c4] * yc[5]);
    for (int k = 0; k < nm; k++) bc[7 + k] = yc[6 + k];
  }
  for (int i = 0; i < 4; i++) {
    for (int j = 0; j < 4; j++) B[(3 + i) + (size_t)n * (3 + j)] += cm * mu * p[i] * p[j];
  }
  if (ck != 0) {
    for (int k = 0; k < nm; k++) {
      for (int l = 0; l < nm; l++)
        B[(7 + k) + (size_t)n * (7 + l)] += ck * b->Kff[k + (size_t)nm * l];
    }
  }
#undef MB
#undef CB
}

// ============================================================================================
// constraints
// ============================================================================================
// Kinematics of one joint side: position r and up to 4 attached directions g[i], with their
// derivatives with respect to the side body's coordinates (3 x n, column-major, ld 3).
typedef struct side {
  int body, n;
  double r[3], g[4][3];
  double *dr, *dg[4];
} side;

// -2/|p| A v~ G (3x4 row-major) into out
static void dA_dp(const mbody *b, const double *A, const double *G, double pn, const double *v,
                  double *out) {
  double S[9], AS[9];
  skew3(v, S);
  mm3(A, S, AS);
  double f = -2.0 / pn;
  for (int i = 0; i < 3; i++) {
    for (int c = 0; c < 4; c++) {
      out[4 * i + c] = f * (AS[3 * i] * G[c] + AS[3 * i + 1] * G[4 + c] + AS[3 * i + 2] * G[8 + c]);
    }
  }
  (void)b;
}

// e: nv local direction vectors (3 each)
static void side_eval(const fmbd_mbs *m, int pt, const double (*e)[3], int nv, const double *xg,
                      side *s) {
  const mpoint *P = &m->p[pt];
  s->body = P->body;
  if (P->body < 0) {
    s->n = 0;
    memcpy(s->r, P->x0, sizeof s->r);
    for (int i = 0; i < nv; i++) memcpy(s->g[i], e[i], sizeof s->g[i]);
    return;
  }
  const mbody *b = &m->b[P->body];
  const int nm = b->nm, n = b->n;
  s->n = n;
  const double *x = xg + b->off, *p = x + 3, *q = x + 7;
  double A[9], G[12], pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
  quat_to_A(p, A);
  quat_G(p, G);
  double u[3];
  memcpy(u, P->x0, sizeof u);
  double th[3] = {0, 0, 0};
  for (int k = 0; k < nm; k++) {
    for (int a = 0; a < 3; a++) u[a] += P->T[a + 3 * k] * q[k], th[a] += P->Rr[a + 3 * k] * q[k];
  }
  double Au[3];
  mv3(A, u, Au);
  for (int a = 0; a < 3; a++) s->r[a] = x[a] + Au[a];
  double D[12];
  memset(s->dr, 0, sizeof(double) * 3 * (size_t)n);
  for (int a = 0; a < 3; a++) s->dr[a + 3 * a] = 1;
  dA_dp(b, A, G, pn, u, D);
  for (int a = 0; a < 3; a++) {
    for (int c4 = 0; c4 < 4; c4++) s->dr[a + 3 * (3 + c4)] = D[4 * a + c4];
  }
  for (int k = 0; k < nm; k++) mv3(A, P->T + 3 * k, s->dr + 3 * (7 + k));
  for (int i = 0; i < nv; i++) {
    double wv[3], tc[3];
    cross3(th, e[i], tc);
    for (int a = 0; a < 3; a++) wv[a] = e[i][a] + tc[a];
    mv3(A, wv, s->g[i]);
    double *dg = s->dg[i];
    memset(dg, 0, sizeof(double) * 3 * (size_t)n);
    dA_dp(b, A, G, pn, wv, D);
    for (int a = 0; a < 3; a++) {
      for (int c4 = 0; c4 < 4; c4++) dg[a + 3 * (3 + c4)] = D[4 * a + c4];
    }
    for (int k = 0; k < nm; k++) {
      double rc[3];
      cross3(P->Rr + 3 * k, e[i], rc);
      mv3(A, rc, dg + 3 * (7 + k));
    }
  }
}

// jac[0..n1) += sum_a v_a d[a + 3 i]  (v' d for a 3 x n derivative)
static void vtd(const double *v, const double *d, int n, double f, double *jac) {
  for (int i = 0; i < n; i++)
    jac[i] += f * (v[0] * d[3 * i] + v[1] * d[3 * i + 1] + v[2] * d[3 * i + 2]);
}

// equation primitives; jac has s1->n + s2->n entries (side 1 first)
static double eq_pos(const side *s1, const side *s2, int a, double *jac) {
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    for (int i = 0; i < s1->n; i++) jac[i] = s1->dr[a + 3 * i];
    for (int i = 0; i < s2->n; i++) jac[s1->n + i] = -s2->dr[a + 3 * i];
  }
  return s1->r[a] - s2->r[a];
}
static double eq_dot(const side *s1, int i1, const side *s2, int i2, double *jac) {
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    vtd(s2->g[i2], s1->dg[i1], s1->n, 1, jac);
    vtd(s1->g[i1], s2->dg[i2], s2->n, 1, jac + s1->n);
  }
  return dot3(s1->g[i1], s2->g[i2]);
}
// (r2 - r1) . g1[i1]
static double eq_dd(const side *s1, int i1, const side *s2, double *jac) {
  double d[3] = {s2->r[0] - s1->r[0], s2->r[1] - s1->r[1], s2->r[2] - s1->r[2]};
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    vtd(d, s1->dg[i1], s1->n, 1, jac);
    vtd(s1->g[i1], s1->dr, s1->n, -1, jac);
    vtd(s1->g[i1], s2->dr, s2->n, 1, jac + s1->n);
  }
  return dot3(d, s1->g[i1]);
}

// the meaning of joint equation k (0-based)
static const char *joint_eq_meaning(int kind, int k) {
  static const char *sph[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2"};
  static const char *rev[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2", "axis z1 . x2",
                              "axis z1 . y2"};
  static const char *uni[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2", "cross axes a1 . a2"};
  static const char *cyl[] = {"axis z1 . x2", "axis z1 . y2", "offset d . x1", "offset d . y1"};
  static const char *pri[] = {"axis z1 . x2", "axis z1 . y2", "offset d . x1", "offset d . y1",
                              "twist x1 . y2"};
  static const char *fix[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2",
                              "z1 . x2",      "z1 . y2",      "x1 . y2"};
  switch (kind) {
    case FMBD_MBS_SPHERICAL:
      return k < 3 ? sph[k] : "?";
    case FMBD_MBS_REVOLUTE:
      return k < 5 ? rev[k] : "?";
    case FMBD_MBS_UNIVERSAL:
      return k < 4 ? uni[k] : "?";
    case FMBD_MBS_CYLINDRICAL:
      return k < 4 ? cyl[k] : "?";
    case FMBD_MBS_PRISMATIC:
      return k < 5 ? pri[k] : "?";
    case FMBD_MBS_FIXED:
      return k < 6 ? fix[k] : "?";
    default:
      return "?";
  }
}

static void eq_describe(const fmbd_mbs *m, const meq *e, char *buf, size_t len) {
  if (e->kind == EQ_JOINT) {
    const mjoint *j = &m->j[e->owner];
    snprintf(buf, len, "joint '%s' equation %d (%s %s)", j->name, e->sub + 1,
             joint_kind_name(j->kind), joint_eq_meaning(j->kind, e->sub));
  } else if (e->kind == EQ_DRIVER) {
    const mdriver *d = &m->d[e->owner];
    if (d->joint >= 0) {
      snprintf(buf, len, "driver '%s' (coordinate of joint '%s')", d->name, m->j[d->joint].name);
    } else {
      snprintf(buf, len, "driver '%s' (coordinate %d of body '%s')", d->name, d->coord,
               m->b[d->body].name);
    }
  } else {
    snprintf(buf, len, "Euler-parameter normalisation of body '%s'", m->b[e->owner].name);
  }
}

static void side_bind(fmbd_mbs *m, side *s, int which) {
  double *w = m->wk + (size_t)which * 15 * (size_t)m->maxn;
  s->dr = w;
  for (int i = 0; i < 4; i++) s->dg[i] = w + (size_t)(3 + 3 * i) * (size_t)m->maxn;
}

// the joint's two sides
static void joint_sides(fmbd_mbs *m, const mjoint *j, const double *x, side *s1, side *s2) {
  side_bind(m, s1, 0);
  side_bind(m, s2, 1);
  double e2[4][3];
  memcpy(e2, j->e[1], sizeof(double) * 9);
  memcpy(e2[3], j->a2, sizeof(double) * 3);
  side_eval(m, j->pt[0], (const double(*)[3])j->e[0], 3, x, s1);
  side_eval(m, j->pt[1], (const double(*)[3])e2, j->kind == FMBD_MBS_UNIVERSAL ? 4 : 3, x, s2);
}

// joint coordinate (revolute angle or slide) and its jacobian (may be NULL)
static double joint_coord(const mjoint *j, const side *s1, const side *s2, double *jac) {
  if (j->kind == FMBD_MBS_REVOLUTE) {
    // theta = atan2(y1 . x2, x1 . x2)
    double sn = dot3(s1->g[1], s2->g[0]), cs = dot3(s1->g[0], s2->g[0]);
    double th = atan2(sn, cs);
    if (jac) {
      int nt = s1->n + s2->n;
      memset(jac, 0, sizeof(double) * (size_t)nt);
      double r2 = sn * sn + cs * cs;
      double fs = cs / r2, fc = -sn / r2;
      vtd(s2->g[0], s1->dg[1], s1->n, fs, jac);
      vtd(s1->g[1], s2->dg[0], s2->n, fs, jac + s1->n);
      vtd(s2->g[0], s1->dg[0], s1->n, fc, jac);
      vtd(s1->g[0], s2->dg[0], s2->n, fc, jac + s1->n);
    }
    return th;
  }
  return eq_dd(s1, 2, s2, jac);
}

// Evaluate every equation (value and, with want_jac, jacobian) at (x, t).
static void eval_constraints(fmbd_mbs *m, const double *x, double t, bool want_jac) {
  side s1, s2;
  int64_t e = 0;
  for (int ij = 0; ij < m->nj; ij++) {
    const mjoint *j = &m->j[ij];
    joint_sides(m, j, x, &s1, &s2);
    for (int k = 0; k < j->neq; k++, e++) {
      meq *q = &m->eq[e];
      double *jac = want_jac ? q->jac : NULL;
      double v = 0;
      switch (j->kind) {
        case FMBD_MBS_SPHERICAL:
          v = eq_pos(&s1, &s2, k, jac);
          break;
        case FMBD_MBS_REVOLUTE:
          v = k < 3 ? eq_pos(&s1, &s2, k, jac) : eq_dot(&s1, 2, &s2, k - 3, jac);
          break;
        case FMBD_MBS_UNIVERSAL:
          v = k < 3 ? eq_pos(&s1, &s2, k, jac) : eq_dot(&s1, 2, &s2, 3, jac);
          break;
        case FMBD_MBS_CYLINDRICAL:
        case FMBD_MBS_PRISMATIC:
          if (k < 2)
            v = eq_dot(&s1, 2, &s2, k, jac);
          else if (k < 4)
            v = eq_dd(&s1, k - 2, &s2, jac);
          else
            v = eq_dot(&s1, 0, &s2, 1, jac);
          break;
        case FMBD_MBS_FIXED:
          if (k < 3)
            v = eq_pos(&s1, &s2, k, jac);
          else if (k < 5)
            v = eq_dot(&s1, 2, &s2, k - 3, jac);
          else
            v = eq_dot(&s1, 0, &s2, 1, jac);
          break;
        default:
          break;
      }
      q->phi = v;
    }
  }
  for (int id = 0; id < m->nd; id++, e++) {
    const mdriver *d = &m->d[id];
    meq *q = &m->eq[e];
    double f = fmbd_mbs_fn_eval(&d->f, t, NULL, NULL);
    if (d->joint >= 0) {
      const mjoint *j = &m->j[d->joint];
      joint_sides(m, j, x, &s1, &s2);
      double v = joint_coord(j, &s1, &s2, want_jac ? q->jac : NULL);
      q->phi = j->kind == FMBD_MBS_REVOLUTE ? remainder(v - f, 2 * M_PI) : v - f;
    } else {
      const mbody *b = &m->b[d->body];
      int c = d->coord < 3 ? d->coord : 7 + (d->coord - 3);
      q->phi = x[b->off + c] - f;
      if (want_jac) {
        memset(q->jac, 0, sizeof(double) * (size_t)q->nj);
        q->jac[c] = 1;
      }
    }
  }
  for (int ib = 0; ib < m->nb; ib++, e++) {
    const mbody *b = &m->b[ib];
    meq *q = &m->eq[e];
    const double *p = x + b->off + 3;
    q->phi = 0.5 * b->snorm * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3] - 1);
    if (want_jac) {
      memset(q->jac, 0, sizeof(double) * (size_t)q->nj);
      for (int c = 0; c < 4; c++) q->jac[3 + c] = b->snorm * p[c];
    }
  }
}

// time derivatives of the prescribed part: Phi_t and Phi_tt of each equation
static void eq_time_derivs(const fmbd_mbs *m, double t, int64_t e, double *ft, double *ftt) {
  const meq *q = &m->eq[e];
  *ft = 0, *ftt = 0;
  if (q->kind == EQ_DRIVER) {
    double d1, d2;
    fmbd_mbs_fn_eval(&m->d[q->owner].f, t, &d1, &d2);
    *ft = -d1, *ftt = -d2;
  }
}

// jac . v over the equation's bodies
static double eq_jv(const fmbd_mbs *m, const meq *q, const double *v) {
  double s = 0;
  int o = 0;
  for (int k = 0; k < 2; k++) {
    if (q->b[k] < 0) continue;
    const mbody *b = &m->b[q->b[k]];
    for (int i = 0; i < b->n; i++) s += q->jac[o + i] * v[b->off + i];
    o += b->n;
  }
  return s;
}
// v[cols] += f * jac
static void eq_jtv(const fmbd_mbs *m, const meq *q, double f, double *v) {
  int o = 0;
  for (int k = 0; k < 2; k++) {
    if (q->b[k] < 0) continue;
    const mbody *b = &m->b[q->b[k]];
    for (int i = 0; i < b->n; i++) v[b->off + i] += f * q->jac[o + i];
    o += b->n;
  }
}

// ============================================================================================
// system evaluation, sparse matrix, KLU
// ============================================================================================
// name of coordinate i of x
static void coord_describe(const fmbd_mbs *m, int64_t i, char *buf, size_t len) {
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (i >= b->off && i < b->off + b->n) {
      int k = (int)(i - b->off);
      static const char *nm[] = {"R_x",
                                 "R_y",
                                 "R_z",
                                 "Euler parameter e0",
                                 "Euler parameter e1",
                                 "Euler parameter e2",
                                 "Euler parameter e3"};
      if (k < 7)
        snprintf(buf, len, "body '%s' coordinate %s", b->name, nm[k]);
      else
        snprintf(buf, len, "body '%s' modal coordinate %d", b->name, k - 7 + 1);
      return;
    }
  }
  snprintf(buf, len, "coordinate %lld", (long long)i);
}
// name of unknown i of the matrix (coordinate or kept equation)
static void unknown_describe(const fmbd_mbs *m, int64_t i, char *buf, size_t len) {
  if (i < m->n) {
    coord_describe(m, i, buf, len);
    return;
  }
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kept && m->eq[e].row == i - m->n) {
      eq_describe(m, &m->eq[e], buf, len);
      return;
    }
  }
  snprintf(buf, len, "unknown %lld", (long long)i);
}

// res = body residuals (+ Phi_x' lam when add_lam), eq phi/jac, and with `matrix` the matrix
// Ax = [cm M + cc C + ck K, Phi_x'; Phi_x, 0] (dynamics block as body_eval).
static void eval_system(fmbd_mbs *m, double t, const double *xdd, bool matrix, double cm, double cc,
                        double ck, bool add_lam) {
  if (matrix) memset(m->Ax, 0, sizeof(double) * (size_t)m->nnz);
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    body_eval(m, ib, t, m->x, m->xd, xdd, m->res + b->off, matrix ? m->bblk : NULL, cm, cc, ck);
    if (matrix) {
      const int64_t *pos = m->bpos[ib];
      for (int i = 0; i < b->n * b->n; i++) m->Ax[pos[i]] += m->bblk[i];
    }
  }
  eval_constraints(m, m->x, t, true);
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    if (add_lam) eq_jtv(m, q, m->lam[q->row], m->res);
    if (matrix) {
      for (int i = 0; i < q->nj; i++) {
        m->Ax[q->pr[i]] += q->jac[i];
        m->Ax[q->pc[i]] += q->jac[i];
      }
    }
  }
}

typedef struct slot {
  int64_t key, id;
} slot;
static int slot_cmp(const void *a, const void *b) {
  int64_t x = ((const slot *)a)->key, y = ((const slot *)b)->key;
  return x < y ? -1 : x > y;
}

// compressed-column pattern of the iteration matrix, maps, KLU symbolic analysis
static int build_pattern(fmbd_mbs *m) {
  int rc = FMBD_OK;
  slot *sl = NULL;
  int64_t N = m->N, cnt = 0;
  for (int ib = 0; ib < m->nb; ib++) cnt += (int64_t)m->b[ib].n * m->b[ib].n;
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kept) cnt += 2 * m->eq[e].nj;
  }
  m->nnz = cnt;
  FMBD_GALLOC(sl = fmbd_malloc(sizeof(slot) * (size_t)(cnt ? cnt : 1)));
  FMBD_GALLOC(m->bpos = fmbd_calloc((size_t)m->nb, sizeof(int64_t *)));
  int64_t s = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    FMBD_GALLOC(m->bpos[ib] = fmbd_malloc(sizeof(int64_t) * (size_t)(b->n * b->n)));
    for (int j = 0; j < b->n; j++) {
      for (int i = 0; i < b->n; i++, s++) {
        sl[s].key = (b->off + j) * N + (b->off + i);
        sl[s].id = s;
      }
    }
  }
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    FMBD_GALLOC(q->pr = fmbd_malloc(sizeof(int64_t) * (size_t)q->nj));
    FMBD_GALLOC(q->pc = fmbd_malloc(sizeof(int64_t) * (size_t)q->nj));
    int64_t row = m->n + q->row;
    int o = 0;
    for (int k = 0; k < 2; k++) {
      if (q->b[k] < 0) continue;
      const mbody *b = &m->b[q->b[k]];
      for (int i = 0; i < b->n; i++) {
        int64_t col = b->off + i;
        sl[s].key = col * N + row, sl[s].id = s, s++;
        sl[s].key = row * N + col, sl[s].id = s, s++;
      }
      o += b->n;
    }
  }
  qsort(sl, (size_t)cnt, sizeof(slot), slot_cmp);
  FMBD_GALLOC(m->Ap = fmbd_calloc((size_t)N + 1, sizeof(SuiteSparse_long)));
  FMBD_GALLOC(m->Ai = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)(cnt ? cnt : 1)));
  FMBD_GALLOC(m->Ax = fmbd_calloc((size_t)(cnt ? cnt : 1), sizeof(double)));
  int64_t *where = NULL;
  FMBD_GALLOC(where = fmbd_malloc(sizeof(int64_t) * (size_t)(cnt ? cnt : 1)));
  for (int64_t k = 0; k < cnt; k++) {
    int64_t col = sl[k].key / N, row = sl[k].key % N;
    FMBD_ASSERT(k == 0 || sl[k].key != sl[k - 1].key);
    m->Ai[k] = row;
    m->Ap[col + 1]++;
    where[sl[k].id] = k;
  }
  for (int64_t c = 0; c < N; c++) m->Ap[c + 1] += m->Ap[c];
  s = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    for (int i = 0; i < b->n * b->n; i++, s++) m->bpos[ib][i] = where[s];
  }
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    for (int i = 0; i < q->nj; i++) {
      q->pr[i] = where[s++];
      q->pc[i] = where[s++];
    }
  }
  fmbd_free(where);
  klu_l_defaults(&m->kc);
  m->kc.halt_if_singular = 1;
  m->sym = klu_l_analyze(N, m->Ap, m->Ai, &m->kc);
  FMBD_GCHECK(m->sym, FMBD_ERR_EXTERNAL, "KLU symbolic analysis failed (status %ld)",
              (long)m->kc.status);
done:
  fmbd_free(sl);
  return rc;
}

// numeric factorisation of Ax: refactor with the old pivoting when possible
static int factor(fmbd_mbs *m) {
  if (m->num) {
    int ok = (int)klu_l_refactor(m->Ap, m->Ai, m->Ax, m->sym, m->num, &m->kc);
    if (ok && m->kc.status == KLU_OK) ok = (int)klu_l_rcond(m->sym, m->num, &m->kc);
    if (!ok || m->kc.status != KLU_OK || !(m->kc.rcond > 1e-13))
      klu_l_free_numeric(&m->num, &m->kc);
  }
  if (!m->num) {
    m->num = klu_l_factor(m->Ap, m->Ai, m->Ax, m->sym, &m->kc);
    if (!m->num || m->kc.status != KLU_OK) {
      char what[400];
      int64_t col = m->kc.singular_col;
      if (col >= 0 && col < m->N)
        unknown_describe(m, col, what, sizeof what);
      else
        snprintf(what, sizeof what, "unknown column");
      if (m->num) klu_l_free_numeric(&m->num, &m->kc);
      if (m->kc.status == KLU_OUT_OF_MEMORY) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory in KLU");
      FMBD_FAIL(FMBD_ERR_SINGULAR,
                "t = %.6g s: singular iteration matrix (mass matrix or constraint Jacobian) at %s",
                m->t, what);
    }
  }
  m->st.factorizations++;
  return FMBD_OK;
}

static int solve(fmbd_mbs *m, double *rhs) {
  int ok = (int)klu_l_solve(m->sym, m->num, m->N, 1, rhs, &m->kc);
  FMBD_CHECK(ok && m->kc.status == KLU_OK, FMBD_ERR_EXTERNAL, "KLU solve failed (status %ld)",
             (long)m->kc.status);
  return FMBD_OK;
}

// ============================================================================================
// initialisation
// ============================================================================================
static double eq_scaled(const fmbd_mbs *m, const meq *q) {
  return fabs(q->phi) / q->sc;
}

// largest scaled residual among kept equations (index in *worst)
static double worst_eq(const fmbd_mbs *m, int64_t *worst) {
  double mx = 0;
  *worst = -1;
  for (int64_t e = 0; e < m->neq; e++) {
    if (!m->eq[e].kept) continue;
    double v = eq_scaled(m, &m->eq[e]);
    if (!(v <= mx)) {
      mx = v, *worst = e;
      if (!isfinite(v)) break;
    }
  }
  return mx;
}

// Whether the joints form a forest (no closed loop, no two joints between the same bodies, ground
// one node) and every driver drives a joint coordinate. Then no equation can depend on the
// others: each joint's equations act on its child body, which no other joint moves relative to
// its parent, and a joint's own equations are independent by construction; a joint coordinate
// of a tree is free. find_redundant's dense O(n nc^2) work is then skipped (a 400-link chain
// spent 17 s there). A driver of a body coordinate can be dependent (a dead point): checked.
static int find_root(int *up, int i) {
  while (up[i] != i) i = up[i] = up[up[i]];
  return i;
}

static bool joints_form_free_tree(const fmbd_mbs *m) {
  for (int i = 0; i < m->nd; i++) {
    if (m->d[i].joint < 0) return false;
  }
  int *up = fmbd_malloc(sizeof(int) * (size_t)(m->nb + 1));
  if (!up) return false;  // the full check then runs
  for (int i = 0; i <= m->nb; i++) up[i] = i;
  bool tree = true;
  for (int k = 0; k < m->nj && tree; k++) {
    int a = m->j[k].body[0] >= 0 ? m->j[k].body[0] : m->nb;
    int b = m->j[k].body[1] >= 0 ? m->j[k].body[1] : m->nb;
    int ra = find_root(up, a), rb = find_root(up, b);
    if (ra == rb) tree = false;
    up[ra] = rb;
  }
  fmbd_free(up);
  return tree;
}

// Redundant equations: QR with column pivoting of the normalised Jacobian rows for the rank,
// then a greedy in-order selection (Gram-Schmidt, twice) so that the equations declared
// redundant are the later ones (the joint closing a loop); if the two disagree, the
// pivoted QR's choice is taken.
static int find_redundant(fmbd_mbs *m) {
  int rc = FMBD_OK;
  int64_t n = m->n, nc = 0;
  double *C = NULL, *Q = NULL, *tau = NULL;
  lapack_int *jp = NULL;
  int64_t *ix = NULL;
  bool *sel = NULL;
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kind != EQ_NORM) nc++;
  }
  if (nc == 0) return FMBD_OK;
  FMBD_GALLOC(C = fmbd_calloc((size_t)(n * nc), sizeof(double)));
  FMBD_GALLOC(Q = fmbd_calloc((size_t)(n * nc), sizeof(double)));
  FMBD_GALLOC(ix = fmbd_malloc(sizeof(int64_t) * (size_t)nc));
  FMBD_GALLOC(sel = fmbd_calloc((size_t)nc, sizeof(bool)));
  FMBD_GALLOC(jp = fmbd_calloc((size_t)nc, sizeof(lapack_int)));
  FMBD_GALLOC(tau = fmbd_calloc((size_t)(nc < n ? nc : n) + 1, sizeof(double)));
  int64_t k = 0;
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (q->kind == EQ_NORM) continue;
    ix[k] = e;
    double *col = C + n * k;
    eq_jtv(m, q, 1.0, col);
    // the Euler-parameter direction is handled by the normalisations: project it out
    for (int ib = 0; ib < m->nb; ib++) {
      const double *p = m->x + m->b[ib].off + 3;
      double *c = col + m->b[ib].off + 3;
      double pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3], cp = 0;
      for (int i = 0; i < 4; i++) cp += c[i] * p[i];
      for (int i = 0; i < 4; i++) c[i] -= cp / pp * p[i];
    }
    double nrm = 0;
    for (int64_t i = 0; i < n; i++) nrm += col[i] * col[i];
    nrm = sqrt(nrm);
    if (nrm > 0) {
      for (int64_t i = 0; i < n; i++) col[i] /= nrm;
    }
    k++;
  }
  memcpy(Q, C, sizeof(double) * (size_t)(n * nc));
  lapack_int info =
      LAPACKE_dgeqp3(LAPACK_COL_MAJOR, (lapack_int)n, (lapack_int)nc, Q, (lapack_int)n, jp, tau);
  FMBD_GCHECK(info == 0, FMBD_ERR_EXTERNAL, "LAPACK dgeqp3 failed (info %d)", (int)info);
  const double tol = 1e-8;
  int64_t kmax = nc < n ? nc : n, rank = 0;
  double r0 = fabs(Q[0]);
  for (int64_t i = 0; i < kmax; i++) {
    if (r0 > 0 && fabs(Q[i + n * i]) > tol * fmax(r0, 1.0)) rank++;
  }
  // greedy in order: basis in Q (reused)
  int64_t nsel = 0;
  for (int64_t c = 0; c < nc; c++) {
    double *v = C + n * c;
    for (int pass = 0; pass < 2; pass++) {
      for (int64_t j = 0; j < nsel; j++) {
        const double *b = Q + n * j;
        double d = 0;
        for (int64_t i = 0; i < n; i++) d += b[i] * v[i];
        for (int64_t i = 0; i < n; i++) v[i] -= d * b[i];
      }
    }
    double nrm = 0;
    for (int64_t i = 0; i < n; i++) nrm += v[i] * v[i];
    nrm = sqrt(nrm);
    if (nrm > tol && nsel < n) {
      double *b = Q + n * nsel;
      for (int64_t i = 0; i < n; i++) b[i] = v[i] / nrm;
      nsel++;
      sel[c] = true;
    }
  }
  if (nsel != rank) {
    fmbd_log(FMBD_LOG_DEBUG,
             "redundancy: greedy rank %lld, pivoted QR rank %lld; using the pivoted QR",
             (long long)nsel, (long long)rank);
    for (int64_t c = 0; c < nc; c++) sel[c] = false;
    for (int64_t i = 0; i < rank; i++) sel[jp[i] - 1] = true;
  }
  // a driver is never dropped: dependent on the joints it is either at a singular position of
  // the mechanism (a slider-crank's dead point) or fights them (a driven pivot of a chain
  // locked to ground); dropped, the run would go on far from the motion it prescribes
  for (int64_t c = 0; c < nc; c++) {
    const meq *q = &m->eq[ix[c]];
    if (sel[c] || q->kind != EQ_DRIVER) continue;
    char buf[512];
    eq_describe(m, q, buf, sizeof buf);
    FMBD_GFAIL(FMBD_ERR_VALUE,
               "t = %.6g s: the %s depends on the joint equations (the mechanism is at a singular "
               "position for it, or the driver fights the joints): it cannot be followed and is "
               "not dropped",
               m->t, buf);
  }
  for (int64_t c = 0; c < nc; c++) {
    if (sel[c]) continue;
    meq *q = &m->eq[ix[c]];
    q->kept = false;
    char buf[512];
    eq_describe(m, q, buf, sizeof buf);
    FMBD_GALLOC(q->text = fmbd_strdup(buf));
    m->nred++;
  }
  if (m->nred > 0) {
    FMBD_GALLOC(m->red = fmbd_malloc(sizeof(int) * (size_t)m->nred));
    int r = 0;
    for (int64_t c = 0; c < nc; c++) {
      if (!sel[c]) m->red[r++] = (int)ix[c];
    }
    for (int i = 0; i < m->nred; i++) {
      fmbd_log(FMBD_LOG_WARN, "redundant constraint removed: %s", m->eq[m->red[i]].text);
    }
  }
done:
  fmbd_free(C), fmbd_free(Q), fmbd_free(tau), fmbd_free(jp), fmbd_free(ix), fmbd_free(sel);
  return rc;
}

// second time derivative of the kept constraints along x' (without the Phi_x x'' part):
// gam_e = (Phi_x x')_x x' + Phi_tt, by a central difference of Phi_x x' along x'.
static void constraint_gamma(fmbd_mbs *m, double *gam) {
  double vmax = 0;
  for (int64_t i = 0; i < m->n; i++) vmax = fmax(vmax, fabs(m->xd[i]) / m->nscale[i]);
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (!q->kept) continue;
    double ft, ftt;
    eq_time_derivs(m, m->t, e, &ft, &ftt);
    gam[q->row] = ftt;
  }
  if (vmax > 0) {
    double eps = 1e-5 / vmax;
    double *xs = m->xn;  // scratch
    memcpy(xs, m->x, sizeof(double) * (size_t)m->n);
    for (int sgn = -1; sgn <= 1; sgn += 2) {
      double *xe = m->xdn;  // scratch
      for (int64_t i = 0; i < m->n; i++) xe[i] = xs[i] + sgn * eps * m->xd[i];
      eval_constraints(m, xe, m->t, true);
      for (int64_t e = 0; e < m->neq; e++) {
        const meq *q = &m->eq[e];
        if (q->kept) gam[q->row] += sgn * eq_jv(m, q, m->xd) / (2 * eps);
      }
    }
    eval_constraints(m, m->x, m->t, true);
  }
}

static void update_scales(fmbd_mbs *m) {
  for (int64_t i = 0; i < m->n; i++) {
    double v = fabs(m->x[i]);
    if (v > m->scale[i]) m->scale[i] = v;
    v = fabs(m->xdd[i]);
    if (v > m->ascale[i]) m->ascale[i] = v;
  }
  // modal coordinates of a body share one scale, the largest modal amplitude seen on the body
  // (mass-normalised coordinates are comparable): errors of weak high modes count against
  // the body's deformation, not against their own tiny amplitude; likewise for accelerations
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    double qm = 0, am = 0;
    for (int k = 0; k < b->nm; k++) {
      qm = fmax(qm, m->scale[b->off + 7 + k]);
      am = fmax(am, m->ascale[b->off + 7 + k]);
    }
    for (int k = 0; k < b->nm; k++) {
      int64_t i = b->off + 7 + k;
      m->scale[i] = qm, m->ascale[i] = am;
      m->nscale[i] = fmax(qm, 1e-3 * m->Lref * sqrt(b->m));
    }
  }
}

int fmbd_mbs_init(fmbd_mbs *m, const fmbd_mbs_settings *s) {
  int rc = FMBD_OK;
  double *gam = NULL;
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "fmbd_mbs_init called twice");
  FMBD_CHECK(m->nb > 0, FMBD_ERR_VALUE, "the system has no bodies");
  FMBD_CHECK(s, FMBD_ERR_VALUE, "no settings");
  FMBD_CHECK(s->rho_inf >= 0 && s->rho_inf <= 1, FMBD_ERR_VALUE, "rho_inf %g outside [0, 1]",
             s->rho_inf);
  if (s->rho_inf > 0.99) {
    // measured (docs/STABILITY.md): a free spinning flexible rod, 1 s at a fixed 2e-4 s step,
    // about doubles its energy at rho_inf = 1, gains 3 % at 0.999, less than 1e-7 at 0.99
    fmbd_log(FMBD_LOG_WARN,
             "rho_inf %g > 0.99 leaves the index-3 scheme without damping of the constraint "
             "forces and the highest modes: energy can grow (it doubled in 1 s on a spinning rod "
             "at rho_inf = 1; docs/STABILITY.md); 0.9 (the default) to 0.99 is safe",
             s->rho_inf);
  }
  FMBD_CHECK(isfinite(s->t_end) && s->t_end > 0, FMBD_ERR_VALUE, "t_end %g must be positive",
             s->t_end);
  FMBD_CHECK(!s->fixed || (s->step > 0 && isfinite(s->step)), FMBD_ERR_VALUE,
             "fixed step %g must be positive", s->step);
  FMBD_CHECK(s->fixed || (s->first_step > 0 && s->min_step > 0 && s->max_step >= s->min_step &&
                          s->first_step >= s->min_step && s->tolerance > 0),
             FMBD_ERR_VALUE,
             "step settings: need 0 < min_step <= first_step, min_step <= max_step, tolerance > 0");
  FMBD_CHECK(s->newton_tol > 0 && s->newton_max >= 1, FMBD_ERR_VALUE,
             "Newton settings: tolerance > 0, iterations >= 1");
  FMBD_CHECK(s->output_every >= 0, FMBD_ERR_VALUE, "output_every %g must be >= 0", s->output_every);
  m->set = *s;
  if (m->set.fixed && !(m->set.min_step > 0)) m->set.min_step = m->set.step * 1e-6;
  double rho = s->rho_inf;
  m->am = (2 * rho - 1) / (rho + 1);
  m->af = rho / (rho + 1);
  m->gamma = 0.5 + m->af - m->am;
  m->beta = 0.25 * (m->gamma + 0.5) * (m->gamma + 0.5);
  // --- dimensions ---
  int64_t n = 0;
  m->maxn = 7;
  for (int ib = 0; ib < m->nb; ib++) {
    m->b[ib].off = n;
    n += m->b[ib].n;
    if (m->b[ib].n > m->maxn) m->maxn = m->b[ib].n;
  }
  m->n = n;
  int64_t neq = 0;
  for (int j = 0; j < m->nj; j++) neq += m->j[j].neq;
  neq += m->nd + m->nb;
  m->neq = neq;
  size_t nn = (size_t)n;
  double **arrs[] = {&m->x,  &m->xd,   &m->xdd, &m->a,     &m->xn,     &m->xdn,    &m->xddn,
                     &m->an, &m->xddp, &m->res, &m->scale, &m->nscale, &m->ascale, &m->floor_};
  for (size_t i = 0; i < sizeof arrs / sizeof arrs[0]; i++)
    FMBD_GALLOC(*arrs[i] = fmbd_calloc(nn, sizeof(double)));
  size_t mx = (size_t)m->maxn, n6 = mx - 1;
  FMBD_GALLOC(m->wk = fmbd_calloc(30 * mx, sizeof(double)));
  FMBD_GALLOC(m->bres = fmbd_calloc(mx, sizeof(double)));
  FMBD_GALLOC(m->bblk = fmbd_calloc(mx * mx, sizeof(double)));
  FMBD_GALLOC(m->bwork = fmbd_calloc(2 * n6 * n6 + n6, sizeof(double)));
  FMBD_GALLOC(m->eq = fmbd_calloc((size_t)neq, sizeof(meq)));
  // --- equations ---
  int64_t e = 0;
  for (int ij = 0; ij < m->nj; ij++) {
    const mjoint *j = &m->j[ij];
    for (int k = 0; k < j->neq; k++, e++) {
      meq *q = &m->eq[e];
      q->kind = EQ_JOINT, q->owner = ij, q->sub = k;
      int kk = 0;
      q->b[0] = q->b[1] = -1;
      for (int sd = 0; sd < 2; sd++) {
        if (j->body[sd] >= 0) q->b[kk++] = j->body[sd];
      }
      bool dotk = false;
      switch (j->kind) {
        case FMBD_MBS_REVOLUTE:
        case FMBD_MBS_UNIVERSAL:
        case FMBD_MBS_FIXED:
          dotk = k >= 3;
          break;
        case FMBD_MBS_CYLINDRICAL:
        case FMBD_MBS_PRISMATIC:
          dotk = k < 2 || k == 4;
          break;
        default:
          break;
      }
      q->sc = dotk ? 1.0 : 0;  // positions: Lref, set below
    }
  }
  for (int id = 0; id < m->nd; id++, e++) {
    meq *q = &m->eq[e];
    const mdriver *d = &m->d[id];
    q->kind = EQ_DRIVER, q->owner = id;
    q->b[0] = q->b[1] = -1;
    if (d->joint >= 0) {
      int kk = 0;
      for (int sd = 0; sd < 2; sd++) {
        if (m->j[d->joint].body[sd] >= 0) q->b[kk++] = m->j[d->joint].body[sd];
      }
      q->sc = m->j[d->joint].kind == FMBD_MBS_REVOLUTE ? 1.0 : 0;
    } else {
      q->b[0] = d->body;
      q->sc = d->coord < 3 ? 0 : -1;  // modal: set below
    }
  }
  for (int ib = 0; ib < m->nb; ib++, e++) {
    meq *q = &m->eq[e];
    q->kind = EQ_NORM, q->owner = ib;
    q->b[0] = ib, q->b[1] = -1;
    q->sc = m->b[ib].snorm;
  }
  for (e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    q->nj = (q->b[0] >= 0 ? m->b[q->b[0]].n : 0) + (q->b[1] >= 0 ? m->b[q->b[1]].n : 0);
    q->kept = true;
    FMBD_GALLOC(q->jac = fmbd_calloc((size_t)(q->nj ? q->nj : 1), sizeof(double)));
  }
  // --- initial state ---
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    double *x = m->x + b->off, *xd = m->xd + b->off;
    memcpy(x, b->x0, sizeof(double) * 7);
    if (b->nm) memcpy(x + 7, b->q0, sizeof(double) * (size_t)b->nm);
    memcpy(xd, b->v0, sizeof(double) * 3);
    double A[9], G[12], wl[3];
    quat_to_A(x + 3, A);
    quat_G(x + 3, G);
    mtv3(A, b->w0, wl);
    for (int c = 0; c < 4; c++)
      xd[3 + c] = 0.5 * (G[c] * wl[0] + G[4 + c] * wl[1] + G[8 + c] * wl[2]);
    if (b->nm) memcpy(xd + 7, b->qd0, sizeof(double) * (size_t)b->nm);
  }
  // --- reference length and scales ---
  double L = 0;
  for (int ib = 0; ib < m->nb; ib++) L = fmax(L, norm3(m->b[ib].x0) + 2 * m->b[ib].gyr);
  for (int ip = 0; ip < m->np; ip++) {
    double xw[3];
    const mpoint *P = &m->p[ip];
    if (P->body < 0) {
      memcpy(xw, P->x0, sizeof xw);
    } else {
      double A[9];
      quat_to_A(m->b[P->body].x0 + 3, A);
      mv3(A, P->x0, xw);
      for (int a = 0; a < 3; a++) xw[a] += m->b[P->body].x0[a];
    }
    L = fmax(L, norm3(xw));
  }
  m->Lref = fmax(L, 1e-3);
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    for (int i = 0; i < b->n; i++) {
      int64_t k = b->off + i;
      if (i < 3)
        m->floor_[k] = 1e-3 * m->Lref, m->nscale[k] = m->Lref;
      else if (i < 7)
        m->floor_[k] = 1e-3, m->nscale[k] = 1;
      else
        m->floor_[k] = MODAL_FLOOR * m->Lref * sqrt(b->m),
        m->nscale[k] = 1e-3 * m->Lref * sqrt(b->m);
      m->scale[k] = m->floor_[k];
    }
  }
  for (e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    if (q->sc == 0) q->sc = m->Lref;
    if (q->sc < 0) q->sc = 1e-3 * m->Lref * sqrt(m->b[q->b[0]].m);
  }
  update_scales(m);
  m->t = 0;
  // --- redundant equations at the initial configuration ---
  eval_constraints(m, m->x, m->t, true);
  if (joints_form_free_tree(m)) {
    fmbd_log(FMBD_LOG_INFO,
             "constraints: the joints form a tree and every driver drives a joint: "
             "no redundant equation possible (check skipped)");
  } else {
    double t_red = fmbd_wall_s();
    if (fmbd_progress_enabled()) fmbd_progress("redundant constraints: %d joints", m->nj);
    FMBD_GCALL(find_redundant(m));
    fmbd_progress(NULL);
    fmbd_log(FMBD_LOG_INFO, "constraints: redundancy check of %lld equations in %.3g s",
             (long long)(m->neq), fmbd_wall_s() - t_red);
  }
  int64_t kept = 0;
  for (e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    q->row = q->kept ? kept++ : -1;
  }
  m->m = kept;
  m->N = m->n + kept;
  FMBD_GALLOC(m->lam = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  FMBD_GALLOC(m->lamn = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  FMBD_GALLOC(m->rhs = fmbd_calloc((size_t)m->N, sizeof(double)));
  FMBD_GALLOC(gam = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  FMBD_GCALL(build_pattern(m));
  // --- position projection: minimum-change (mass metric) Newton onto Phi = 0 ---
  {
    int it;
    double r = 0, rprev = INFINITY;
    int64_t worst = -1;
    for (it = 0; it < 50; it++) {
      eval_system(m, m->t, NULL, true, 1, 0, 0, false);
      r = worst_eq(m, &worst);
      if (r <= 1e-13 || (it > 3 && r >= rprev)) break;
      rprev = r;
      FMBD_GCALL(factor(m));
      memset(m->rhs, 0, sizeof(double) * (size_t)m->N);
      for (e = 0; e < neq; e++) {
        if (m->eq[e].kept) m->rhs[m->n + m->eq[e].row] = -m->eq[e].phi;
      }
      FMBD_GCALL(solve(m, m->rhs));
      for (int64_t i = 0; i < m->n; i++) m->x[i] += m->rhs[i];
    }
    if (r > 1e-10) {
      char buf[512] = "?";
      if (worst >= 0) eq_describe(m, &m->eq[worst], buf, sizeof buf);
      FMBD_GFAIL(
          FMBD_ERR_CONVERGE,
          "initial positions cannot be made consistent with the constraints: largest residual %.3g "
          "(scaled) at %s",
          r, buf);
    }
    if (it > 0)
      fmbd_log(FMBD_LOG_INFO, "initial positions projected onto the constraints (%d iterations)",
               it);
  }
  // equations removed as redundant must hold too (dependent to first order but violated
  // means the assembly is inconsistent, e.g. two ball joints too far apart on one rod)
  eval_constraints(m, m->x, m->t, false);
  for (e = 0; e < neq; e++) {
    const meq *q = &m->eq[e];
    if (q->kept || eq_scaled(m, q) <= 1e-8) continue;
    char buf[512];
    eq_describe(m, q, buf, sizeof buf);
    FMBD_GFAIL(FMBD_ERR_CONVERGE,
               "initial positions cannot be made consistent with the constraints: the redundant %s "
               "is violated "
               "by %.3g (scaled)",
               buf, eq_scaled(m, q));
  }
  // normalise the Euler parameters exactly
  for (int ib = 0; ib < m->nb; ib++) {
    double *p = m->x + m->b[ib].off + 3;
    double pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
    for (int c = 0; c < 4; c++) p[c] /= pn;
  }
  // --- velocity projection: [M Phi_x'; Phi_x 0] [x'; mu] = [M x'0; -Phi_t] ---
  eval_system(m, m->t, NULL, true, 1, 0, 0, false);
  FMBD_GCALL(factor(m));
  {
    memset(m->rhs, 0, sizeof(double) * (size_t)m->N);
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      const int64_t *pos = m->bpos[ib];
      for (int j = 0; j < b->n; j++) {
        for (int i = 0; i < b->n; i++)
          m->rhs[b->off + i] += m->Ax[pos[i + b->n * j]] * m->xd[b->off + j];
      }
    }
    for (e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      double ft, ftt;
      eq_time_derivs(m, m->t, e, &ft, &ftt);
      m->rhs[m->n + q->row] = -ft;
    }
    double vres = 0;
    for (e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      vres = fmax(vres, fabs(eq_jv(m, q, m->xd) - m->rhs[m->n + q->row]) / q->sc);
    }
    FMBD_GCALL(solve(m, m->rhs));
    memcpy(m->xd, m->rhs, sizeof(double) * (size_t)m->n);
    if (vres > 1e-12) fmbd_log(FMBD_LOG_INFO, "initial velocities projected onto the constraints");
  }
  // --- consistent accelerations and multipliers ---
  {
    constraint_gamma(m, gam);
    eval_system(m, m->t, NULL, false, 1, 0, 0, false);  // res = T'(v - f)
    for (int64_t i = 0; i < m->n; i++) m->rhs[i] = -m->res[i];
    for (e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (q->kept) m->rhs[m->n + q->row] = -gam[q->row];
    }
    FMBD_GCALL(solve(m, m->rhs));
    memcpy(m->xdd, m->rhs, sizeof(double) * (size_t)m->n);
    memcpy(m->a, m->xdd, sizeof(double) * (size_t)m->n);
    for (int64_t k = 0; k < kept; k++) m->lam[k] = m->rhs[m->n + k];
  }
  // acceleration scales: the largest |x''_i| seen, at least nscale_i / t_end^2
  for (int64_t i = 0; i < m->n; i++) m->ascale[i] = m->nscale[i] / (m->set.t_end * m->set.t_end);
  update_scales(m);
  m->need_factor = true;
  m->h_next = m->set.fixed ? m->set.step : m->set.first_step;
  m->h_fact = 0;
  m->h_prop = 0;
  m->k_out = 0;
  m->st.coordinates = m->n;
  m->st.equations = m->m;
  m->st.redundant = m->nred;
  m->ready = true;
done:
  fmbd_free(gam);
  return rc;
}

// ============================================================================================
// time stepping
// ============================================================================================
static void save_state(fmbd_mbs *m) {
  size_t nn = sizeof(double) * (size_t)m->n;
  memcpy(m->xn, m->x, nn), memcpy(m->xdn, m->xd, nn), memcpy(m->xddn, m->xdd, nn),
      memcpy(m->an, m->a, nn);
  memcpy(m->lamn, m->lam, sizeof(double) * (size_t)(m->m + 1));
}
static void restore_state(fmbd_mbs *m) {
  size_t nn = sizeof(double) * (size_t)m->n;
  memcpy(m->x, m->xn, nn), memcpy(m->xd, m->xdn, nn), memcpy(m->xdd, m->xddn, nn),
      memcpy(m->a, m->an, nn);
  memcpy(m->lam, m->lamn, sizeof(double) * (size_t)(m->m + 1));
}

// message naming the largest scaled residual of the last Newton iterate
static void worst_residual(const fmbd_mbs *m, char *buf, size_t len) {
  char what[512] = "?";
  int64_t wi = m->worst_i;
  if (wi >= m->n && wi < m->n + m->neq) {
    eq_describe(m, &m->eq[wi - m->n], what, sizeof what);
  } else if (wi >= 0 && wi < m->n) {
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      if (wi < b->off || wi >= b->off + b->n) continue;
      int k = (int)(wi - b->off);
      if (k < 3)
        snprintf(what, sizeof what, "body '%s' translational equation of motion (%c)", b->name,
                 "xyz"[k]);
      else if (k < 7)
        snprintf(what, sizeof what, "body '%s' rotational equation of motion (row e%d)", b->name,
                 k - 3);
      else
        snprintf(what, sizeof what, "body '%s' modal equation %d", b->name, k - 6);
    }
  }
  char dxw[300] = "?";
  if (m->worst_dx >= 0 && m->worst_dx < m->n) coord_describe(m, m->worst_dx, dxw, sizeof dxw);
  snprintf(buf, len, "%s (scaled residual %.3g); largest correction: %s", what, m->worst_v, dxw);
}

// One attempt of a step of size h from the saved state. Returns FMBD_OK with *conv and *err
// (scaled local error, 0 for fixed steps) or an error code (singular matrix, KLU).
static int attempt(fmbd_mbs *m, double h, bool force_fresh, bool *conv, bool *fresh_out,
                   double *err) {
  const double am = m->am, af = m->af, be = m->beta, ga = m->gamma;
  const double bp = (1 - am) / (be * h * h * (1 - af)), gp = ga / (be * h);
  const double t1 = m->t + h;
  const int64_t n = m->n;
  *conv = false, *err = 0;
  // predictor: x''_{n+1} extrapolated linearly from the last two accepted steps (constant
  // at the first step), lambda_{n+1} = lambda_n
  double ex = (PRED_EXTRAP && m->h_prev > 0) ? h / m->h_prev : 0;
  for (int64_t i = 0; i < n; i++) {
    double an = m->an[i], xdd1 = m->xddn[i] + ex * (m->xddn[i] - m->xddp[i]);
    double a1 = ((1 - af) * xdd1 + af * m->xddn[i] - am * an) / (1 - am);
    m->a[i] = a1;
    m->xdd[i] = xdd1;
    m->x[i] = m->xn[i] + h * m->xdn[i] + h * h * ((0.5 - be) * an + be * a1);
    m->xd[i] = m->xdn[i] + h * ((1 - ga) * an + ga * a1);
  }
  memcpy(m->lam, m->lamn, sizeof(double) * (size_t)(m->m + 1));
  if (m->h_fact <= 0 || fabs(h / m->h_fact - 1) > 0.25) m->need_factor = true;
  if (force_fresh) m->need_factor = true;
  bool fresh = false;
  double prev = 0;
  for (int it = 0; it < m->set.newton_max; it++) {
    bool matrix = m->need_factor;
    eval_system(m, t1, m->xdd, matrix, 1, gp / bp, 1 / bp, true);
    for (int64_t i = 0; i < n; i++) m->rhs[i] = -m->res[i] / bp;
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (q->kept) m->rhs[n + q->row] = -q->phi;
    }
    // the largest scaled residual of this iterate (for the failure message)
    m->worst_v = -1;
    for (int64_t i = 0; i < n; i++) {
      double v = fabs(m->rhs[i]) / m->nscale[i];
      if (!(v <= m->worst_v)) m->worst_v = v, m->worst_i = i;
    }
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      double v = eq_scaled(m, q);
      if (!(v <= m->worst_v)) m->worst_v = v, m->worst_i = m->n + e;
    }
    if (matrix) {
      FMBD_CALL(factor(m));
      m->need_factor = false;
      m->h_fact = h;
      fresh = true;
    }
    FMBD_CALL(solve(m, m->rhs));
    m->st.newton_iterations++;
    // increments in units of the per-coordinate tolerance: position accuracy newton_tol *
    // nscale_i and acceleration accuracy newton_tol * ascale_i (an x error dx gives an x''
    // error beta' dx: without this bound the leftover of a modified-Newton iteration acts as
    // a spurious force that breaks momentum conservation at small steps), but never below
    // the round-off of x_i
    double nrm = 0;
    for (int64_t i = 0; i < n; i++) {
      double dx = m->rhs[i];
      m->x[i] += dx;
      m->xd[i] += gp * dx;
      m->xdd[i] += bp * dx;
      double tx = m->set.newton_tol * fmin(m->nscale[i], m->ascale[i] / bp);
      tx = fmax(tx, 1e3 * DBL_EPSILON * fmax(fabs(m->x[i]), m->nscale[i]));
      double v = fabs(dx) / tx;
      if (!(v <= nrm)) nrm = v, m->worst_dx = i;
    }
    for (int64_t k = 0; k < m->m; k++) m->lam[k] += bp * m->rhs[n + k];
    if (!isfinite(nrm)) break;
    // converged when the estimated remaining error theta/(1 - theta) |dx| (Hairer & Wanner II,
    // sec. IV.8) is within tolerance; in the first iteration (theta unknown) only when |dx|
    // is far below it; theta >= 1 with |dx| within tolerance is round-off stagnation
    double theta = it > 0 ? nrm / prev : 0;
    if (nrm <= 1e-3 || (it > 0 && nrm <= 1 && (theta >= 1 || theta / (1 - theta) * nrm <= 1))) {
      *conv = true;
      break;
    }
    if (it > 0 && theta >= 1 && fresh) break;  // diverging with an up-to-date matrix
    if (it > 0 && theta > THETA_REFACTOR && !matrix) m->need_factor = true;
    prev = nrm;
  }
  *fresh_out = fresh;
  if (!*conv) return FMBD_OK;
  // pseudo-accelerations of the converged state
  for (int64_t i = 0; i < n; i++) {
    m->a[i] = ((1 - af) * m->xdd[i] + af * m->xddn[i] - am * m->an[i]) / (1 - am);
  }
  if (!m->set.fixed) {
    // local error estimate of the displacement update (Geradin & Cardona 2001, sec. 11.5):
    // e = h^2 |beta - 1/6| (a_{n+1} - a_n)
    double c = h * h * fabs(be - 1.0 / 6.0), e = 0;
    for (int64_t i = 0; i < n; i++) {
      double sc = fmax(m->scale[i], m->floor_[i]);
      double v = c * fabs(m->a[i] - m->an[i]) / (m->set.tolerance * sc);
      if (!(v <= e)) e = v;
    }
    *err = e;
  }
  return FMBD_OK;
}

int fmbd_mbs_step(fmbd_mbs *m, bool *at_output) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "fmbd_mbs_step before fmbd_mbs_init");
  if (at_output) *at_output = false;
  const double tend = m->set.t_end;
  if (m->t >= tend * (1 - 1e-14)) return 1;
  FMBD_CHECK(m->set.max_steps <= 0 || m->st.steps < m->set.max_steps, FMBD_ERR_CONVERGE,
             "t = %.6g s: step limit %lld reached", m->t, (long long)m->set.max_steps);
  const double oe = m->set.output_every;
  save_state(m);
  bool retried_fresh = false;
  for (;;) {
    double h = m->h_next;
    if (m->set.fixed && h > m->set.step) h = m->set.step;
    if (!m->set.fixed && h > m->set.max_step) h = m->set.max_step;
    double lim = tend;
    bool out_lim = false;
    if (oe > 0) {
      double to = (double)(m->k_out + 1) * oe;
      if (to < lim) lim = to, out_lim = true;
    }
    bool clipped = false;
    if (m->t + h > lim - 0.01 * h) {
      if (lim - m->t < h) clipped = true;
      m->h_prop = h;
      h = lim - m->t;
    }
    bool conv, fresh;
    double err;
    int arc = attempt(m, h, retried_fresh, &conv, &fresh, &err);
    if (arc != 0) {
      restore_state(m);  // the caller may still query (and write) the last accepted state
      return arc;
    }
    if (!conv) {
      restore_state(m);
      if (!fresh && !retried_fresh) {
        retried_fresh = true;  // the old factor was too far off: same h, fresh matrix
        continue;
      }
      m->st.rejected++;
      double hmin = m->set.min_step;
      if (h <= hmin * (1 + 1e-9)) {
        char buf[800];
        worst_residual(m, buf, sizeof buf);
        if (!isfinite(m->worst_v)) {
          // overflow, not a convergence problem: say so rather than "singular" or "diverged"
          FMBD_FAIL(FMBD_ERR_CONVERGE,
                    "t = %.9g s: the equations are not finite (overflow: a load, stiffness, "
                    "mass or initial velocity of absurd magnitude?); first at %s",
                    m->t + h, buf);
        }
        FMBD_FAIL(FMBD_ERR_CONVERGE,
                  "t = %.9g s, h = %.3g s: Newton did not converge; largest residual: %s", m->t + h,
                  h, buf);
      }
      m->h_next = fmax(h / 4, hmin);
      m->after_reject = true;
      retried_fresh = false;
      continue;
    }
    if (fmbd_log_level() >= FMBD_LOG_DEBUG) {
      fmbd_log(FMBD_LOG_DEBUG, "t = %.9g h = %.3g err = %.3g%s", m->t, h, err,
               err > 1 ? " rejected" : "");
    }
    if (!m->set.fixed && err > 1 && h > m->set.min_step * (1 + 1e-9)) {
      restore_state(m);
      m->st.rejected++;
      m->after_reject = true;
      double f = fmax(0.2, 0.9 * pow(err, -1.0 / 3.0));
      m->h_next = fmax(h * f, m->set.min_step);
      retried_fresh = false;
      continue;
    }
    // --- accepted ---
    m->t += h;
    m->st.steps++;
    m->st.h_last = h;
    memcpy(m->xddp, m->xddn, sizeof(double) * (size_t)m->n);  // x'' of the previous step
    m->h_prev = h;
    update_scales(m);
    bool hit_out = oe <= 0;
    if (oe > 0 && clipped && out_lim) {
      m->k_out++;
      hit_out = true;
    } else if (oe > 0) {
      double to = (double)(m->k_out + 1) * oe;
      if (fabs(m->t - to) <= 1e-9 * fmax(1.0, fabs(to))) {
        m->k_out++;
        hit_out = true;
      }
    }
    if (oe > 0 && m->t >= tend * (1 - 1e-14)) hit_out = true;
    if (at_output) *at_output = hit_out;
    if (m->set.fixed) {
      m->h_next = m->set.step;
    } else {
      // elementary controller (order 2 method: local error ~ h^3) with a dead band that
      // keeps h (and the factorised matrix) unchanged for small proposed increases, and no
      // increase right after a rejection (Hairer, Norsett & Wanner I, sec. II.4)
      double f = err > 0 ? SAFETY * pow(err, -1.0 / 3.0) : 2.0;
      f = fmin(2.0, fmax(0.2, f));
      if (f > 1 && (f < 1.25 || m->after_reject)) f = 1;
      if (f < 1 && f > DEAD_LOW) f = 1;
      double hn = h * f;
      if (clipped && m->h_prop > hn) hn = m->h_prop;
      m->h_next = fmin(m->set.max_step, fmax(m->set.min_step, hn));
      m->after_reject = false;
    }
    return FMBD_OK;
  }
}

int fmbd_mbs_run(fmbd_mbs *m, fmbd_mbs_callback cb, void *user) {
  for (;;) {
    bool out;
    int rc = fmbd_mbs_step(m, &out);
    if (rc == 1) return FMBD_OK;
    if (rc != 0) return rc;
    if (cb) {
      int r = cb(m, out, user);
      if (r != 0) return r;
    }
  }
}

// ============================================================================================
// queries
// ============================================================================================
double fmbd_mbs_time(const fmbd_mbs *m) {
  return m->t;
}
int fmbd_mbs_nbodies(const fmbd_mbs *m) {
  return m->nb;
}
int fmbd_mbs_body_nm(const fmbd_mbs *m, int body) {
  return body >= 0 && body < m->nb ? m->b[body].nm : 0;
}
int fmbd_mbs_find_body(const fmbd_mbs *m, const char *name) {
  for (int i = 0; i < m->nb; i++) {
    if (strcmp(m->b[i].name, name) == 0) return i;
  }
  return -1;
}

// body kinematics at the current state: A, wb (body), wbd (body)
static void body_kin(const fmbd_mbs *m, const mbody *b, double *A, double *wb, double *wbd) {
  const double *x = m->x + b->off, *xd = m->xd + b->off, *xdd = m->xdd + b->off;
  double G[12];
  quat_to_A(x + 3, A);
  quat_G(x + 3, G);
  for (int a = 0; a < 3; a++) {
    wb[a] =
        2 * (G[4 * a] * xd[3] + G[4 * a + 1] * xd[4] + G[4 * a + 2] * xd[5] + G[4 * a + 3] * xd[6]);
    if (wbd)
      wbd[a] = 2 * (G[4 * a] * xdd[3] + G[4 * a + 1] * xdd[4] + G[4 * a + 2] * xdd[5] +
                    G[4 * a + 3] * xdd[6]);
  }
}

// local position u, modal velocity and acceleration of a point (body frame)
static void point_local(const fmbd_mbs *m, const mpoint *P, double *u, double *ud, double *udd) {
  const mbody *b = &m->b[P->body];
  const double *q = m->x + b->off + 7, *qd = m->xd + b->off + 7, *qdd = m->xdd + b->off + 7;
  memcpy(u, P->x0, 3 * sizeof(double));
  for (int a = 0; a < 3; a++) ud[a] = udd[a] = 0;
  for (int k = 0; k < b->nm; k++) {
    for (int a = 0; a < 3; a++) {
      u[a] += P->T[a + 3 * k] * q[k];
      ud[a] += P->T[a + 3 * k] * qd[k];
      udd[a] += P->T[a + 3 * k] * qdd[k];
    }
  }
}

void fmbd_mbs_point_position(const fmbd_mbs *m, int pid, double x[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    memcpy(x, P->x0, 3 * sizeof(double));
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], u[3], ud[3], udd[3], Au[3];
  quat_to_A(m->x + b->off + 3, A);
  point_local(m, P, u, ud, udd);
  mv3(A, u, Au);
  for (int a = 0; a < 3; a++) x[a] = m->x[b->off + a] + Au[a];
}

void fmbd_mbs_point_velocity(const fmbd_mbs *m, int pid, double v[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    v[0] = v[1] = v[2] = 0;
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], w[3], u[3], ud[3], udd[3], l[3], g[3];
  body_kin(m, b, A, w, NULL);
  point_local(m, P, u, ud, udd);
  cross3(w, u, l);
  for (int a = 0; a < 3; a++) l[a] += ud[a];
  mv3(A, l, g);
  for (int a = 0; a < 3; a++) v[a] = m->xd[b->off + a] + g[a];
}

void fmbd_mbs_point_acceleration(const fmbd_mbs *m, int pid, double acc[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    acc[0] = acc[1] = acc[2] = 0;
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], w[3], wd[3], u[3], ud[3], udd[3], t1[3], t2[3], t3[3], t4[3], l[3], g[3];
  body_kin(m, b, A, w, wd);
  point_local(m, P, u, ud, udd);
  cross3(wd, u, t1);
  cross3(w, u, t2);
  cross3(w, t2, t3);
  cross3(w, ud, t4);
  for (int a = 0; a < 3; a++) l[a] = t1[a] + t3[a] + 2 * t4[a] + udd[a];
  mv3(A, l, g);
  for (int a = 0; a < 3; a++) acc[a] = m->xdd[b->off + a] + g[a];
}

void fmbd_mbs_body_pose(const fmbd_mbs *m, int body, double R[3], double A[9]) {
  const mbody *b = &m->b[body];
  if (R) memcpy(R, m->x + b->off, 3 * sizeof(double));
  if (A) quat_to_A(m->x + b->off + 3, A);
}

void fmbd_mbs_body_velocity(const fmbd_mbs *m, int body, double v[3], double w[3]) {
  const mbody *b = &m->b[body];
  double A[9], wb[3];
  body_kin(m, b, A, wb, NULL);
  if (v) memcpy(v, m->xd + b->off, 3 * sizeof(double));
  if (w) mv3(A, wb, w);
}

int64_t fmbd_mbs_modal(const fmbd_mbs *m, int body, const double **q, const double **qd,
                       const double **qdd) {
  const mbody *b = &m->b[body];
  if (q) *q = m->x + b->off + 7;
  if (qd) *qd = m->xd + b->off + 7;
  if (qdd) *qdd = m->xdd + b->off + 7;
  return b->nm;
}

// per-body inertia quantities at the current state (c, I, Mwf, velocities)
typedef struct binert {
  double A[9], w[3], c[3], I[9], S1qd[3], Mwfqd[3];
} binert;
static void body_inert(const fmbd_mbs *m, int ib, binert *o) {
  const mbody *b = &m->b[ib];
  const double *q = m->x + b->off + 7, *qd = m->xd + b->off + 7;
  body_kin(m, b, o->A, o->w, NULL);
  const int nm = b->nm;
  double J[9];
  memcpy(o->c, b->c0, sizeof o->c);
  memcpy(J, b->J0, sizeof J);
  for (int a = 0; a < 3; a++) o->S1qd[a] = o->Mwfqd[a] = 0;
  for (int k = 0; k < nm; k++) {
    const double *X = b->XS + 9 * k;
    for (int a = 0; a < 3; a++) {
      o->c[a] += b->S1[a + 3 * k] * q[k];
      o->S1qd[a] += b->S1[a + 3 * k] * qd[k];
      for (int bb = 0; bb < 3; bb++) J[3 * a + bb] += q[k] * (X[a + 3 * bb] + X[bb + 3 * a]);
    }
  }
  // second-order terms: sum_kl SS_ab,kl q_k q_l; Mwf q' = sum_k q'_k (XSx_k + sum_l q_l SSx_lk)
  for (int k = 0; k < nm; k++) {
    for (int l = 0; l < nm; l++) {
      const double *S = b->SS + 9 * k + 9 * (size_t)nm * l;
      double f = q[k] * q[l];
      if (f != 0) {
        for (int a = 0; a < 3; a++) {
          for (int bb = 0; bb < 3; bb++) J[3 * a + bb] += f * S[a + 3 * bb];
        }
      }
      const double *sx = b->SSx + 3 * l + 3 * (size_t)nm * k;
      for (int a = 0; a < 3; a++) o->Mwfqd[a] += qd[k] * q[l] * sx[a];
    }
    for (int a = 0; a < 3; a++) o->Mwfqd[a] += qd[k] * b->XSx[a + 3 * k];
  }
  double tr = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) o->I[i] = -0.5 * (J[i] + J[(i % 3) * 3 + i / 3]);
  o->I[0] += tr, o->I[4] += tr, o->I[8] += tr;
}

void fmbd_mbs_energy(const fmbd_mbs *m, double *kinetic, double *potential, double *strain) {
  double T = 0, V = 0, U = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    binert o;
    body_inert(m, ib, &o);
    const double *Rd = m->xd + b->off, *q = m->x + b->off + 7, *qd = m->xd + b->off + 7;
    const int nm = b->nm;
    // T = 1/2 [R'; w; q']' Mb [R'; w; q']
    double Iw[3], Ac[9], Sc[9], v1[3], AS[3];
    mv3(o.I, o.w, Iw);
    skew3(o.c, Sc);
    mm3(o.A, Sc, Ac);
    mv3(Ac, o.w, v1);
    mv3(o.A, o.S1qd, AS);
    double Tq = 0;
    for (int k = 0; k < nm; k++) {
      for (int l = 0; l < nm; l++) Tq += qd[k] * b->Mff[k + (size_t)nm * l] * qd[l];
    }
    T += 0.5 * (b->m * dot3(Rd, Rd) + dot3(o.w, Iw) + Tq) - dot3(Rd, v1) + dot3(Rd, AS) +
         dot3(o.w, o.Mwfqd);
    double Acw[3];
    mv3(o.A, o.c, Acw);
    V -= b->m * dot3(m->g, m->x + b->off) + dot3(m->g, Acw);
    for (int k = 0; k < nm; k++) {
      for (int l = 0; l < nm; l++) U += 0.5 * q[k] * b->Kff[k + (size_t)nm * l] * q[l];
    }
  }
  if (kinetic) *kinetic = T;
  if (potential) *potential = V;
  if (strain) *strain = U;
}

void fmbd_mbs_momentum(const fmbd_mbs *m, double L[3], double H[3]) {
  double Lt[3] = {0, 0, 0}, Ht[3] = {0, 0, 0};
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    binert o;
    body_inert(m, ib, &o);
    const double *R = m->x + b->off, *Rd = m->xd + b->off;
    double wc[3], lb[3], Lb[3];
    cross3(o.w, o.c, wc);
    for (int a = 0; a < 3; a++) lb[a] = wc[a] + o.S1qd[a];
    mv3(o.A, lb, Lb);
    for (int a = 0; a < 3; a++) Lb[a] += b->m * Rd[a];
    // H = R x Lb + (A c) x R' + A (I w + Mwf q')
    double t1[3], Acw[3], t2[3], hl[3], hw[3];
    cross3(R, Lb, t1);
    mv3(o.A, o.c, Acw);
    cross3(Acw, Rd, t2);
    mv3(o.I, o.w, hl);
    for (int a = 0; a < 3; a++) hl[a] += o.Mwfqd[a];
    mv3(o.A, hl, hw);
    for (int a = 0; a < 3; a++) Lt[a] += Lb[a], Ht[a] += t1[a] + t2[a] + hw[a];
  }
  if (L) memcpy(L, Lt, sizeof Lt);
  if (H) memcpy(H, Ht, sizeof Ht);
}

int fmbd_mbs_joint_reaction(const fmbd_mbs *m, int joint, double F[3], double T[3]) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "joint reaction before fmbd_mbs_init");
  FMBD_CHECK(joint >= 0 && joint < m->nj, FMBD_ERR_VALUE, "unknown joint %d", joint);
  const mjoint *j = &m->j[joint];
  int side = j->body[0] >= 0 ? 0 : 1;
  int ib = j->body[side];
  const mbody *b = &m->b[ib];
  double *gf = m->res;  // scratch: generalized constraint force on all coordinates
  fmbd_mbs *mm = (fmbd_mbs *)m;
  memset(gf, 0, sizeof(double) * (size_t)m->n);
  eval_constraints(mm, m->x, m->t, true);
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (!q->kept) continue;
    bool mine = (q->kind == EQ_JOINT && q->owner == joint) ||
                (q->kind == EQ_DRIVER && m->d[q->owner].joint == joint);
    if (mine) eq_jtv(m, q, -m->lam[q->row], gf);
  }
  const double *g = gf + b->off, *p = m->x + b->off + 3;
  double A[9], G[12], Nb[3], Nw[3];
  quat_to_A(p, A);
  quat_G(p, G);
  for (int a = 0; a < 3; a++)
    Nb[a] =
        0.5 * (G[4 * a] * g[3] + G[4 * a + 1] * g[4] + G[4 * a + 2] * g[5] + G[4 * a + 3] * g[6]);
  mv3(A, Nb, Nw);
  double rp[3], d[3], dxF[3];
  fmbd_mbs_point_position(m, j->pt[side], rp);
  for (int a = 0; a < 3; a++) d[a] = rp[a] - m->x[b->off + a];
  cross3(d, g, dxF);
  double sg = side == 0 ? 1 : -1;
  for (int a = 0; a < 3; a++) {
    F[a] = sg * g[a];
    T[a] = sg * (Nw[a] - dxF[a]);
  }
  return FMBD_OK;
}

int fmbd_mbs_joint_coordinate(const fmbd_mbs *m, int joint, double *value, double *rate) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "joint coordinate before fmbd_mbs_init");
  FMBD_CHECK(joint >= 0 && joint < m->nj, FMBD_ERR_VALUE, "unknown joint %d", joint);
  const mjoint *j = &m->j[joint];
  FMBD_CHECK(j->kind == FMBD_MBS_REVOLUTE || j->kind == FMBD_MBS_PRISMATIC ||
                 j->kind == FMBD_MBS_CYLINDRICAL,
             FMBD_ERR_VALUE, "joint '%s' (%s) has no coordinate", j->name,
             joint_kind_name(j->kind));
  fmbd_mbs *mm = (fmbd_mbs *)m;
  side s1, s2;
  joint_sides(mm, j, m->x, &s1, &s2);
  double *buf = fmbd_malloc(sizeof(double) * (size_t)(s1.n + s2.n + 1));
  FMBD_CHECK(buf, FMBD_ERR_NOMEM, "out of memory");
  double v = joint_coord(j, &s1, &s2, buf);
  double r = 0;
  int o = 0;
  for (int sd = 0; sd < 2; sd++) {
    if (j->body[sd] < 0) continue;
    const mbody *b = &m->b[j->body[sd]];
    for (int i = 0; i < b->n; i++) r += buf[o + i] * m->xd[b->off + i];
    o += b->n;
  }
  fmbd_free(buf);
  if (value) *value = v;
  if (rate) *rate = r;
  return FMBD_OK;
}

void fmbd_mbs_constraint_residual(const fmbd_mbs *m, double *pos, double *vel) {
  fmbd_mbs *mm = (fmbd_mbs *)m;
  eval_constraints(mm, m->x, m->t, true);
  double p = 0, v = 0;
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (q->kind == EQ_NORM) continue;
    double ft, ftt;
    eq_time_derivs(m, m->t, e, &ft, &ftt);
    p = fmax(p, fabs(q->phi));
    v = fmax(v, fabs(eq_jv(m, q, m->xd) + ft));
  }
  if (pos) *pos = p;
  if (vel) *vel = v;
}

void fmbd_mbs_get_stats(const fmbd_mbs *m, fmbd_mbs_stats *s) {
  *s = m->st;
}

int fmbd_mbs_redundant(const fmbd_mbs *m, int k, int *joint, int *eq, const char **text) {
  FMBD_CHECK(k >= 0 && k < m->nred, FMBD_ERR_VALUE, "no redundant equation %d", k);
  const meq *q = &m->eq[m->red[k]];
  if (joint) *joint = q->kind == EQ_JOINT ? q->owner : -1;
  if (eq) *eq = q->kind == EQ_JOINT ? q->sub + 1 : 1;
  if (text) *text = q->text;
  return FMBD_OK;
}

// ============================================================================================
// the mechanism's equations outside the integrator (linearisation, global modes)
// ============================================================================================
// One CSR matrix from per-body dense blocks (the bodies' coordinates are contiguous and their
// blocks do not overlap): block diagonal, column-major blocks.
static int blocks_to_csr(const fmbd_mbs *m, double *const *blk, fmbd_csr **out) {
  int64_t nnz = 0;
  for (int ib = 0; ib < m->nb; ib++) nnz += (int64_t)m->b[ib].n * m->b[ib].n;
  FMBD_CALL(fmbd_csr_create(m->n, m->n, nnz, out));
  fmbd_csr *A = *out;
  int64_t p = 0;
  A->indptr[0] = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    for (int i = 0; i < b->n; i++) {
      for (int j = 0; j < b->n; j++) {
        A->indices[p] = b->off + j;
        A->data[p++] = blk[ib][i + (size_t)b->n * j];
      }
      A->indptr[b->off + i + 1] = p;
    }
  }
  return FMBD_OK;
}

void fmbd_mbs_linear_free(fmbd_mbs_linear *L) {
  if (!L) return;
  fmbd_csr_destroy(&L->M);
  fmbd_csr_destroy(&L->C);
  fmbd_csr_destroy(&L->K);
  fmbd_csr_destroy(&L->Cq);
  fmbd_free(L->Q);
  fmbd_free(L->phi);
  fmbd_free(L->eq);
  memset(L, 0, sizeof *L);
}

int fmbd_mbs_linearise(fmbd_mbs *m, double t, const double *x, const double *xd,
                       fmbd_mbs_linear *L) {
  int rc = FMBD_OK;
  double **blk[3] = {NULL, NULL, NULL}, *row = NULL, *xs = NULL, *xds = NULL;
  memset(L, 0, sizeof *L);
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "fmbd_mbs_linearise before fmbd_mbs_init");
  int64_t n = m->n;
  // evaluate at (x, xd): the model's own state is saved and restored
  FMBD_GALLOC(xs = fmbd_malloc(sizeof(double) * (size_t)n));
  FMBD_GALLOC(xds = fmbd_malloc(sizeof(double) * (size_t)n));
  memcpy(xs, m->x, sizeof(double) * (size_t)n);
  memcpy(xds, m->xd, sizeof(double) * (size_t)n);
  if (x) memcpy(m->x, x, sizeof(double) * (size_t)n);
  if (xd) memcpy(m->xd, xd, sizeof(double) * (size_t)n);
  L->n = n;
  FMBD_GALLOC(L->Q = fmbd_calloc((size_t)(n + 1), sizeof(double)));
  // --- M, C, K: the body blocks with (cm, cc, ck) = (1,0,0), (0,1,0), (0,0,1) ---
  for (int k = 0; k < 3; k++) {
    FMBD_GALLOC(blk[k] = fmbd_calloc((size_t)(m->nb + 1), sizeof(double *)));
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      FMBD_GALLOC(blk[k][ib] = fmbd_calloc((size_t)b->n * b->n, sizeof(double)));
      body_eval(m, ib, t, m->x, m->xd, NULL, m->bres, blk[k][ib], k == 0, k == 1, k == 2);
      if (k == 0) {  // Q = -(residual at zero accelerations)
        for (int i = 0; i < b->n; i++) L->Q[b->off + i] = -m->bres[i];
      }
    }
  }
  FMBD_GCALL(blocks_to_csr(m, blk[0], &L->M));
  FMBD_GCALL(blocks_to_csr(m, blk[1], &L->C));
  FMBD_GCALL(blocks_to_csr(m, blk[2], &L->K));
  // --- the kept constraint equations: values and Jacobian rows ---
  eval_constraints(m, m->x, t, true);
  int64_t nc = 0, nnz = 0;
  FMBD_GALLOC(row = fmbd_calloc((size_t)(n + 1), sizeof(double)));
  for (int64_t e = 0; e < m->neq; e++) {
    if (!m->eq[e].kept) continue;
    nc++;
    nnz += m->eq[e].nj;
  }
  L->nc = nc;
  FMBD_GALLOC(L->phi = fmbd_calloc((size_t)(nc + 1), sizeof(double)));
  FMBD_GALLOC(L->eq = fmbd_calloc((size_t)(nc + 1), sizeof(int64_t)));
  FMBD_GCALL(fmbd_csr_create(nc, n, nnz, &L->Cq));
  {
    fmbd_csr *C = L->Cq;
    int64_t r = 0, p = 0;
    C->indptr[0] = 0;
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      eq_jtv(m, q, 1.0, row);  // the row, dense; gathered in column order, then cleared
      int bo[2] = {q->b[0], q->b[1]};
      if (bo[0] >= 0 && bo[1] >= 0 && m->b[bo[1]].off < m->b[bo[0]].off) {
        int s = bo[0];
        bo[0] = bo[1], bo[1] = s;
      }
      for (int k = 0; k < 2; k++) {
        if (bo[k] < 0 || (k == 1 && bo[1] == bo[0])) continue;
        const mbody *b = &m->b[bo[k]];
        for (int i = 0; i < b->n; i++) {
          C->indices[p] = b->off + i;
          C->data[p++] = row[b->off + i];
          row[b->off + i] = 0.0;
        }
      }
      L->phi[r] = q->phi;
      L->eq[r] = e;
      C->indptr[++r] = p;
    }
  }
done:
  if (xs) memcpy(m->x, xs, sizeof(double) * (size_t)n);
  if (xds) memcpy(m->xd, xds, sizeof(double) * (size_t)n);
  for (int k = 0; k < 3; k++) {
    if (blk[k]) {
      for (int ib = 0; ib < m->nb; ib++) fmbd_free(blk[k][ib]);
    }
    fmbd_free(blk[k]);
  }
  fmbd_free(row);
  fmbd_free(xs);
  fmbd_free(xds);
  if (rc) fmbd_mbs_linear_free(L);
  return rc;
}

int64_t fmbd_mbs_ncoordinates(const fmbd_mbs *m) {
  return m->n;
}

const double *fmbd_mbs_state(const fmbd_mbs *m) {
  return m->x;
}
