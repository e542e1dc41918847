// common/fmbd_mbs.c: multibody model building: creation, bodies, points, joints, drivers, loads,
// settings (fmbd_mbs.h; the core is split over common/fmbd_mbs_*.c, internals in fmbd_mbs_impl.h)
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

void fmbd_mbs_rotation_quat(const double p[4], double A[9]) {
  quat_to_A(p, A);
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
  s->linearise_only = false;
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
  fmbd_free(b->Hk), fmbd_free(b->Mwf), fmbd_free(b->cor);
  fmbd_free(b->XX), fmbd_free(b->XT), fmbd_free(b->pk);
  mbs_fe_free(&b->fe);
}

void fmbd_mbs_destroy(fmbd_mbs **mp) {
  if (!mp || !*mp) return;
  fmbd_mbs *m = *mp;
  for (int i = 0; i < m->nb; i++) body_free(&m->b[i]);
  fmbd_free(m->b);
  for (int i = 0; i < m->np; i++)
    fmbd_free(m->p[i].T), fmbd_free(m->p[i].Rr), fmbd_free(m->p[i].sup);
  fmbd_free(m->p);
  for (int i = 0; i < m->nj; i++) fmbd_free(m->j[i].name);
  fmbd_free(m->j);
  for (int i = 0; i < m->nd; i++) fmbd_free(m->d[i].name), mbs_fn_free(&m->d[i].f);
  fmbd_free(m->d);
  for (int i = 0; i < m->nl; i++) fmbd_free(m->l[i].name), mbs_fn_free(&m->l[i].f);
  fmbd_free(m->l);
  if (m->eq) {
    for (int64_t e = 0; e < m->neq; e++) {
      fmbd_free(m->eq[e].jac), fmbd_free(m->eq[e].pr), fmbd_free(m->eq[e].pc),
          fmbd_free(m->eq[e].jw), fmbd_free(m->eq[e].text), fmbd_free(m->eq[e].cols);
    }
    fmbd_free(m->eq);
  }
  double *arrs[] = {m->x,      m->xd,     m->xdd,  m->a,    m->lam,  m->xn,    m->xdn,
                    m->xddn,   m->an,     m->lamn, m->res,  m->rhs,  m->scale, m->nscale,
                    m->ascale, m->floor_, m->wk,   m->bres, m->bblk, m->bwork, m->Ax,
                    m->rscale, m->itx,    m->ity,  m->tx,   m->dyp};
  for (size_t i = 0; i < sizeof arrs / sizeof arrs[0]; i++) fmbd_free(arrs[i]);
  for (int k = 0; k < PRED_NH; k++) {
    fmbd_free(m->xddh[k]);
    fmbd_free(m->lamh[k]);
  }
  fmbd_free(m->dpos);
  fmbd_free(m->qpar);
  if (m->bpos) {
    for (int i = 0; i < m->nb; i++) fmbd_free(m->bpos[i]);
    fmbd_free(m->bpos);
  }
  fmbd_klu_destroy(&m->klu);
  mbs_schur_free(&m->sc);
  fmbd_free(m->red);
  fmbd_free(m);
  *mp = NULL;
}

bool mbs_finite_n(const double *v, int64_t n) {
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
  FMBD_CHECK(mbs_finite_n(s->position, 3) && mbs_finite_n(s->rotation, 9) &&
                 mbs_finite_n(s->velocity, 3) && mbs_finite_n(s->angular_velocity, 3),
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
  b->share = -1;
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

// mass, first moment and the symmetrised second moment of a flexible body, and its scales
static void set_inertia(mbody *b, double mass, const double *c0, const double *J) {
  b->m = mass;
  memcpy(b->c0, c0, sizeof b->c0);
  for (int a = 0; a < 3; a++) {
    for (int c = 0; c < 3; c++) b->J0[3 * a + c] = 0.5 * (J[3 * a + c] + J[3 * c + a]);
  }
  body_scales(b);
}

int fmbd_mbs_add_rigid(fmbd_mbs *m, const char *name, double mass, const double com[3],
                       const double inertia[9], const fmbd_mbs_state0 *s0, int *id) {
  FMBD_CHECK(isfinite(mass) && mass > 0, FMBD_ERR_VALUE, "body '%s': mass %g must be positive",
             name ? name : "?", mass);
  FMBD_CHECK(com && inertia && mbs_finite_n(com, 3) && mbs_finite_n(inertia, 9), FMBD_ERR_VALUE,
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

// 1 when the symmetric n x n A (column-major) is positive definite (Cholesky, plain loops: n
// is a body's number of modes), 0 when not, -1 out of memory
int mbs_spd(const double *A, int64_t n) {
  double *L = fmbd_malloc(sizeof(double) * (size_t)(n * n + 1));
  if (!L) return -1;
  memcpy(L, A, sizeof(double) * (size_t)(n * n));
  int pd = 1;
  for (int64_t j = 0; j < n && pd; j++) {
    double s = L[j + n * j];
    for (int64_t k = 0; k < j; k++) s -= L[j + n * k] * L[j + n * k];
    if (!(s > 0)) {
      pd = 0;
      break;
    }
    s = sqrt(s);
    L[j + n * j] = s;
    for (int64_t i = j + 1; i < n; i++) {
      double t = L[i + n * j];
      for (int64_t k = 0; k < j; k++) t -= L[i + n * k] * L[j + n * k];
      L[i + n * j] = t / s;
    }
  }
  fmbd_free(L);
  return pd;
}

int fmbd_mbs_add_flex(fmbd_mbs *m, const char *name, const fmbd_mbs_flex_data *d,
                      const fmbd_mbs_state0 *s0, int *id) {
  const char *nm_ = name ? name : "?";
  FMBD_CHECK(d, FMBD_ERR_VALUE, "body '%s': no flexible data", nm_);
  FMBD_CHECK(d->nm >= 0 && d->nm <= 10000, FMBD_ERR_VALUE, "body '%s': bad number of modes %lld",
             nm_, (long long)d->nm);
  FMBD_CHECK(isfinite(d->mass) && d->mass > 0, FMBD_ERR_VALUE,
             "body '%s': mass %g must be positive", nm_, d->mass);
  FMBD_CHECK(mbs_finite_n(d->first_moment, 3) && mbs_finite_n(d->second_moment, 9), FMBD_ERR_VALUE,
             "body '%s': non-finite first or second moment", nm_);
  int64_t nm = d->nm;
  if (nm > 0) {
    FMBD_CHECK(d->S1 && d->XS && d->SS && d->Mff && d->Kff, FMBD_ERR_VALUE,
               "body '%s': missing modal invariants (S1, XS, SS, Mff, Kff)", nm_);
    FMBD_CHECK(mbs_finite_n(d->S1, 3 * nm) && mbs_finite_n(d->XS, 9 * nm) &&
                   mbs_finite_n(d->SS, 9 * nm * nm) && mbs_finite_n(d->Mff, nm * nm) &&
                   mbs_finite_n(d->Kff, nm * nm),
               FMBD_ERR_VALUE, "body '%s': non-finite modal invariants", nm_);
    FMBD_CHECK(isfinite(d->damping_ratio) && d->damping_ratio >= 0, FMBD_ERR_VALUE,
               "body '%s': damping ratio %g must be >= 0", nm_, d->damping_ratio);
    // Mff positive definite (a shared body's may be semidefinite: its set's sum is checked by
    // fmbd_mbs_init)
    if (!d->shared) {
      int pd = mbs_spd(d->Mff, nm);
      FMBD_CHECK(pd >= 0, FMBD_ERR_NOMEM, "out of memory");
      FMBD_CHECK(pd, FMBD_ERR_SINGULAR, "body '%s': modal mass matrix Mff is not positive definite",
                 nm_);
    }
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
  set_inertia(b, d->mass, d->first_moment, d->second_moment);
  b->mff_unchecked = d->shared;
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
    b->Hk = fmbd_calloc(9 * n1, sizeof(double));
    b->Mwf = fmbd_calloc(3 * n1, sizeof(double));
    b->cor = fmbd_calloc(3 * n1, sizeof(double));
    b->XX = fmbd_malloc(sizeof(double) * 9 * n1);
    b->XT = fmbd_malloc(sizeof(double) * 9 * n1);
    FMBD_CHECK(b->S1 && b->XS && b->SS && b->Mff && b->Kff && b->Dff && b->XSx && b->SSx && b->q0 &&
                   b->qd0 && b->Hk && b->Mwf && b->cor && b->XX && b->XT,
               FMBD_ERR_NOMEM, "out of memory");
    memcpy(b->S1, d->S1, sizeof(double) * 3 * n1);
    memcpy(b->XS, d->XS, sizeof(double) * 9 * n1);
    // partial inertia coupling (docs/THEORY.md section 4c): the second-order invariant SS (and
    // SSx, formed from it below) zero, so every term built from them (the equations, their
    // derivatives, the kinetic energy of fmbd_mbs_energy) is that of the partial model
    b->partial = d->partial_coupling;
    if (b->partial)
      memset(b->SS, 0, sizeof(double) * 9 * n1 * n1);
    else
      memcpy(b->SS, d->SS, sizeof(double) * 9 * n1 * n1);
    FMBD_CALL(mbs_body_consts(b));
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
    // Kff and Mff exactly diagonal (Dff is): the modes of fe2cb's and cbcheck's bodies are
    // the M-orthonormal eigenvectors of the reduced problem, stored as Mff = I and Kff =
    // diag(chibar) exactly (fmbd_rflex.c); O(nm) products and the Schur path's C diagonal
    b->kdiag = b->mdiag = true;
    for (size_t i = 0; i < n1; i++) {
      for (size_t k = 0; k < n1; k++) {
        if (i != k && b->Kff[i + n1 * k] != 0) b->kdiag = false;
        if (i != k && b->Mff[i + n1 * k] != 0) b->mdiag = false;
      }
    }
    if (d->q0) memcpy(b->q0, d->q0, sizeof(double) * n1);
    if (d->qd0) memcpy(b->qd0, d->qd0, sizeof(double) * n1);
    FMBD_CHECK(mbs_finite_n(b->q0, nm) && mbs_finite_n(b->qd0, nm), FMBD_ERR_VALUE,
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
    // SS is read at load only: its packed triangle (full coupling, in b->pk) and SSx hold what
    // the evaluation and the outputs use
    fmbd_free(b->SS);
    b->SS = NULL;
  }
  if (id) *id = m->nb - 1;
  return FMBD_OK;
}

static bool csr_shape(const fmbd_csr *A, int64_t nr, int64_t nc) {
  return A && A->nrows == nr && A->ncols == nc && mbs_finite_n(A->data, A->indptr[nr]);
}

int fmbd_mbs_share_modal(fmbd_mbs *m, int nids, const int *ids) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "fmbd_mbs_share_modal after fmbd_mbs_init");
  FMBD_CHECK(nids >= 1 && ids, FMBD_ERR_VALUE, "fmbd_mbs_share_modal: no bodies");
  int own = ids[0];
  for (int i = 0; i < nids; i++) {
    FMBD_CHECK(ids[i] >= 0 && ids[i] < m->nb, FMBD_ERR_VALUE, "shared modes: no body %d", ids[i]);
    const mbody *b = &m->b[ids[i]];
    FMBD_CHECK(!b->fe && b->nm >= 1, FMBD_ERR_VALUE,
               "shared modes: body '%s' is not a modal flexible body", b->name);
    FMBD_CHECK(b->nm == m->b[ids[0]].nm, FMBD_ERR_VALUE,
               "shared modes: body '%s' has %d modal coordinates, body '%s' %d: a shared set has "
               "one number",
               b->name, b->nm, m->b[ids[0]].name, m->b[ids[0]].nm);
    FMBD_CHECK(b->share < 0, FMBD_ERR_VALUE, "shared modes: body '%s' is already in a set",
               b->name);
    for (int k = 0; k < i; k++)
      FMBD_CHECK(ids[k] != ids[i], FMBD_ERR_VALUE, "shared modes: body '%s' twice", b->name);
    if (ids[i] < own) own = ids[i];
  }
  for (int i = 0; i < nids; i++) m->b[ids[i]].share = own;
  return FMBD_OK;
}

int fmbd_mbs_add_fe(fmbd_mbs *m, const char *name, const fmbd_mbs_fe_data *d,
                    const fmbd_mbs_state0 *s0, int *id) {
  const char *nm_ = name ? name : "?";
  FMBD_CHECK(d, FMBD_ERR_VALUE, "body '%s': no data", nm_);
  const int64_t n = d->n, nn = d->nnodes;
  FMBD_CHECK(n >= 1 && n < INT32_MAX / 16 && nn >= 1, FMBD_ERR_VALUE,
             "body '%s': bad size (%lld coordinates, %lld nodes)", nm_, (long long)n,
             (long long)nn);
  FMBD_CHECK(isfinite(d->mass) && d->mass > 0, FMBD_ERR_VALUE,
             "body '%s': mass %g must be positive", nm_, d->mass);
  FMBD_CHECK(mbs_finite_n(d->first_moment, 3) && mbs_finite_n(d->second_moment, 9), FMBD_ERR_VALUE,
             "body '%s': non-finite first or second moment", nm_);
  FMBD_CHECK(csr_shape(d->M, n, n) && csr_shape(d->K, n, n) && (!d->D || csr_shape(d->D, n, n)) &&
                 csr_shape(d->Mn, nn, nn) && csr_shape(d->E, 3 * nn, n),
             FMBD_ERR_VALUE,
             "body '%s': M, K (and D) must be %lld x %lld, Mn %lld x %lld, E %lld x %lld, finite",
             nm_, (long long)n, (long long)n, (long long)nn, (long long)nn, (long long)(3 * nn),
             (long long)n);
  FMBD_CHECK(d->node_xyz && mbs_finite_n(d->node_xyz, 3 * nn), FMBD_ERR_VALUE,
             "body '%s': missing or non-finite node positions", nm_);
  FMBD_CHECK((!d->q0 || mbs_finite_n(d->q0, n)) && (!d->qd0 || mbs_finite_n(d->qd0, n)),
             FMBD_ERR_VALUE, "body '%s': non-finite q0 or qd0", nm_);
  FMBD_CHECK(
      !d->S1 == !d->Mw0 && (!d->S1 || (mbs_finite_n(d->S1, 3 * n) && mbs_finite_n(d->Mw0, 3 * n))),
      FMBD_ERR_VALUE, "body '%s': S1 and Mw0 must be given together, finite", nm_);
  mbs_fe *fe = NULL;
  FMBD_CALL(mbs_fe_create(d, &fe));
  double *q0 = fmbd_calloc((size_t)n, sizeof(double)),
         *qd0 = fmbd_calloc((size_t)n, sizeof(double));
  mbody *b = NULL;
  int rc = q0 && qd0 ? add_body(m, name, (int)n, s0, &b) : FMBD_ERR_NOMEM;
  if (rc) {
    mbs_fe_free(&fe), fmbd_free(q0), fmbd_free(qd0);
    if (rc == FMBD_ERR_NOMEM) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    return rc;
  }
  b->fe = fe, b->q0 = q0, b->qd0 = qd0;
  if (d->q0) memcpy(b->q0, d->q0, sizeof(double) * (size_t)n);
  if (d->qd0) memcpy(b->qd0, d->qd0, sizeof(double) * (size_t)n);
  set_inertia(b, d->mass, d->first_moment, d->second_moment);
  if (id) *id = m->nb - 1;
  return FMBD_OK;
}

int fmbd_mbs_add_point(fmbd_mbs *m, int body, const double x0[3], const double *T,
                       const double *Rot, int *pid) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "point added after fmbd_mbs_init");
  FMBD_CHECK(body == FMBD_MBS_GROUND || (body >= 0 && body < m->nb), FMBD_ERR_VALUE,
             "point on unknown body %d", body);
  FMBD_CHECK(x0 && mbs_finite_n(x0, 3), FMBD_ERR_VALUE, "point: missing or non-finite position");
  int nm = body >= 0 ? m->b[body].nm : 0;
  if (nm > 0) {
    FMBD_CHECK((!T || mbs_finite_n(T, 3 * nm)) && (!Rot || mbs_finite_n(Rot, 3 * nm)),
               FMBD_ERR_VALUE, "point on body '%s': non-finite modal translation or rotation",
               m->b[body].name);
  }
  GROW(m->p, m->np, m->npcap, mpoint);
  mpoint *p = &m->p[m->np];
  memset(p, 0, sizeof *p);
  p->body = body;
  memcpy(p->x0, x0, sizeof p->x0);
  if (nm > 0 && m->b[body].fe) {
    // an FE body: keep the coordinates that move the point
    int ns = 0;
    for (int k = 0; k < nm; k++) {
      bool nz = false;
      for (int a = 0; a < 3; a++) nz |= (T && T[a + 3 * k] != 0) || (Rot && Rot[a + 3 * k] != 0);
      ns += nz;
    }
    p->sup = fmbd_malloc(sizeof(int64_t) * (size_t)(ns + 1));
    p->T = fmbd_calloc(3 * (size_t)ns + 1, sizeof(double));
    p->Rr = fmbd_calloc(3 * (size_t)ns + 1, sizeof(double));
    if (!p->sup || !p->T || !p->Rr) {
      fmbd_free(p->T), fmbd_free(p->Rr), fmbd_free(p->sup);
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    p->nsup = 0;
    for (int k = 0; k < nm; k++) {
      bool nz = false;
      for (int a = 0; a < 3; a++) nz |= (T && T[a + 3 * k] != 0) || (Rot && Rot[a + 3 * k] != 0);
      if (!nz) continue;
      for (int a = 0; a < 3; a++) {
        p->T[a + 3 * p->nsup] = T ? T[a + 3 * k] : 0;
        p->Rr[a + 3 * p->nsup] = Rot ? Rot[a + 3 * k] : 0;
      }
      p->sup[p->nsup++] = k;
    }
  } else if (nm > 0) {
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
  FMBD_CHECK(xw && mbs_finite_n(xw, 3), FMBD_ERR_VALUE, "point: missing or non-finite position");
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
const char *mbs_joint_kind_name(int kind) {
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
  FMBD_CHECK(mbs_finite_n(jd->axis, 3) && mbs_finite_n(jd->axis2, 3) && mbs_finite_n(jd->ref, 3),
             FMBD_ERR_VALUE, "joint '%s': non-finite axis", nm);
  // world frame of the joint: z = axis, x = ref (projected) or any normal
  double z[3] = {0, 0, 1}, x[3], y[3];
  double na = norm3(jd->axis);
  bool needs_axis = jd->kind != FMBD_MBS_SPHERICAL && jd->kind != FMBD_MBS_FIXED;
  FMBD_CHECK(!needs_axis || na > 0, FMBD_ERR_VALUE, "joint '%s' (%s): zero axis", nm,
             mbs_joint_kind_name(jd->kind));
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
  FMBD_CALL(mbs_fn_copy(f, &d->f, what));
  d->name = fmbd_strdup(name);
  if (!d->name) {
    mbs_fn_free(&d->f);
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
             name ? name : "?", m->j[joint].name, mbs_joint_kind_name(k));
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
  FMBD_CHECK(direction && mbs_finite_n(direction, 3), FMBD_ERR_VALUE,
             "load '%s': missing or non-finite direction", name);
  FMBD_CHECK(f, FMBD_ERR_VALUE, "load '%s': no function", name);
  GROW(m->l, m->nl, m->nlcap, mload);
  mload *l = &m->l[m->nl];
  memset(l, 0, sizeof *l);
  char what[300];
  snprintf(what, sizeof what, "load '%s'", name);
  FMBD_CALL(mbs_fn_copy(f, &l->f, what));
  l->name = fmbd_strdup(name);
  if (!l->name) {
    mbs_fn_free(&l->f);
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
