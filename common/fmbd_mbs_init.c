// common/fmbd_mbs_init.c: fmbd_mbs_init: redundant constraints, consistent initial conditions
// SPDX-License-Identifier: MIT
#include <lapacke.h>
#include <math.h>
#undef I  // <complex.h> through lapacke.h
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

// ============================================================================================
// initialisation
// ============================================================================================
double mbs_eq_scaled(const fmbd_mbs *m, const meq *q) {
  return fabs(q->phi) / q->sc;
}

// largest scaled residual among kept equations (index in *worst)
static double worst_eq(const fmbd_mbs *m, int64_t *worst) {
  double mx = 0;
  *worst = -1;
  for (int64_t e = 0; e < m->neq; e++) {
    if (!m->eq[e].kept) continue;
    double v = mbs_eq_scaled(m, &m->eq[e]);
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

// The Jacobian rows of the constraint equations (all but the normalisations; only the kept
// ones when kept_only) as unit columns of C (n x nc): the Euler-parameter direction of every
// body projected out (the normalisations handle it), then coordinate i scaled by cs[i] (a
// coordinate's unit; NULL: none). ix[k] = equation of column k.
static void constraint_columns(fmbd_mbs *m, bool kept_only, const double *cs, double *C,
                               int64_t *ix, int64_t *nc_out) {
  int64_t n = m->n, k = 0;
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (q->kind == EQ_NORM || (kept_only && !q->kept)) continue;
    ix[k] = e;
    double *col = C + n * k;
    memset(col, 0, sizeof(double) * (size_t)n);
    mbs_eq_jtv(m, q, 1.0, col);
    for (int ib = 0; ib < m->nb; ib++) {
      const double *p = m->x + m->b[ib].off + 3;
      double *c = col + m->b[ib].off + 3;
      double pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3], cp = 0;
      for (int i = 0; i < 4; i++) cp += c[i] * p[i];
      for (int i = 0; i < 4; i++) c[i] -= cp / pp * p[i];
    }
    if (cs) {
      for (int64_t i = 0; i < n; i++) col[i] *= cs[i];
    }
    double nrm = 0;
    for (int64_t i = 0; i < n; i++) nrm += col[i] * col[i];
    nrm = sqrt(nrm);
    if (nrm > 0) {
      for (int64_t i = 0; i < n; i++) col[i] /= nrm;
    }
    k++;
  }
  *nc_out = k;
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
  int64_t k;
  constraint_columns(m, false, NULL, C, ix, &k);
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
    mbs_eq_describe(m, q, buf, sizeof buf);
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
    mbs_eq_describe(m, q, buf, sizeof buf);
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

// The Gram matrix G = C'C of the unit-normalised Jacobian rows of the kept constraints
// (coordinates in their scales: L_ref for translations) at the current positions, and its
// eigen-decomposition: *w the eigenvalues (ascending, the squared singular values of C), *G
// the eigenvectors (combinations of the equations *ix). frame_only: only the frame
// coordinates' columns (7 per body; the elastic ones zeroed), each row normalised again: the
// equations' dependence on the rigid motion alone. Dense O(n nc^2): false (nothing
// allocated) above 4e6 entries or when no equation is kept; the caller frees *G, *w, *ix.
static bool kept_gram(fmbd_mbs *m, bool frame_only, double **Gp, double **wp, int64_t **ixp,
                      int64_t *ncp) {
  int64_t n = m->n, ne = 0, nc = 0;
  double *C = NULL, *G = NULL, *w = NULL;
  int64_t *ix = NULL;
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kind != EQ_NORM && m->eq[e].kept) ne++;
  }
  if (ne == 0 || (double)n * (double)ne > 4e6) return false;
  C = fmbd_calloc((size_t)(n * ne), sizeof(double));
  G = fmbd_calloc((size_t)(ne * ne), sizeof(double));
  w = fmbd_calloc((size_t)ne, sizeof(double));
  ix = fmbd_malloc(sizeof(int64_t) * (size_t)ne);
  if (!C || !G || !w || !ix) goto fail;
  mbs_eval_constraints(m, m->x, m->t, true);
  constraint_columns(m, true, m->nscale, C, ix, &nc);
  if (frame_only) {
    for (int64_t k = 0; k < nc; k++) {
      double *col = C + n * k, nrm = 0;
      // keep each body's 7 frame coordinates: zero what lies between them (elastic columns)
      int64_t next = 0;  // first coordinate not yet visited
      for (int ib = 0; ib <= m->nb; ib++) {
        int64_t off = ib < m->nb ? m->b[ib].off : n;
        for (int64_t i = next; i < off; i++) col[i] = 0;
        if (ib == m->nb) break;
        for (int64_t i = off; i < off + 7; i++) nrm += col[i] * col[i];
        next = off + 7;
      }
      nrm = sqrt(nrm);
      for (int64_t i = 0; i < n && nrm > 0; i++) col[i] /= nrm;
    }
  }
  fmbd_dense_gemm('T', 'N', nc, nc, n, 1.0, C, n, C, n, 0.0, G, nc);
  if (fmbd_dense_syev(nc, G, w) != FMBD_OK) goto fail;
  fmbd_free(C);
  *Gp = G, *wp = w, *ixp = ix, *ncp = nc;
  return true;
fail:
  fmbd_free(C), fmbd_free(G), fmbd_free(w), fmbd_free(ix);
  return false;
}

// The number of combinations of the kept equations that are dependent on the frame
// coordinates alone (singular values of the frame-only rows below tol; see kept_gram): an
// over-constrained mechanism (the Sarrus linkage) has such a combination at every position,
// kept because the bodies' elastic columns make it independent; a dead point adds one.
static int64_t frame_dependent(fmbd_mbs *m, double tol) {
  double *G = NULL, *w = NULL;
  int64_t *ix = NULL, nc = 0, cnt = 0;
  if (!kept_gram(m, true, &G, &w, &ix, &nc)) return 0;
  for (int64_t k = 0; k < nc; k++) cnt += w[k] < tol * tol;
  fmbd_free(G), fmbd_free(w), fmbd_free(ix);
  return cnt;
}

// Singular positions (a dead point): the smallest singular value s of the unit-normalised
// Jacobian rows of the kept constraints at the current positions (the eigenvalues of C'C,
// s^2, are resolved down to s ~ 1e-7 by round-off); when s < tol, buf names the joints and
// drivers whose rows make up the dependent combination (the right singular vector's entries
// above 0.1 of its largest). Dense O(n nc^2): skipped (false) above 4e6 entries, where a
// failed step stays described by its residual. Runs only when a step has failed.
bool mbs_constraints_singular(fmbd_mbs *m, double tol, double *smin, char *buf, size_t len) {
  bool sing = false;
  double *G = NULL, *w = NULL;
  int64_t *ix = NULL, nc = 0;
  *smin = -1;
  if (!kept_gram(m, false, &G, &w, &ix, &nc)) return false;
  *smin = sqrt(fmax(w[0], 0));
  if (*smin >= tol) goto done;
  sing = true;
  const double *v = G;  // eigenvector of the smallest eigenvalue
  double vmax = 0;
  for (int64_t k = 0; k < nc; k++) vmax = fmax(vmax, fabs(v[k]));
  // the owners (joints, then drivers) of the combination, each once, in the scene's order:
  // "joints 'a', 'b' and 'c' and driver 'd'"
  size_t pos = 0;
  buf[0] = 0;
  for (int pass = 0; pass < 2; pass++) {
    int kind = pass == 0 ? EQ_JOINT : EQ_DRIVER, cnt = 0, nw = 0;
    for (int sweep = 0; sweep < 2; sweep++) {  // count, then write
      for (int64_t k = 0; k < nc; k++) {
        const meq *q = &m->eq[ix[k]];
        if (q->kind != kind || fabs(v[k]) < 0.1 * vmax) continue;
        bool seen = false;
        for (int64_t k2 = 0; k2 < k && !seen; k2++) {
          const meq *q2 = &m->eq[ix[k2]];
          seen = q2->kind == kind && q2->owner == q->owner && fabs(v[k2]) >= 0.1 * vmax;
        }
        if (seen) continue;
        if (sweep == 0) {
          cnt++;
          continue;
        }
        const char *name = kind == EQ_JOINT ? m->j[q->owner].name : m->d[q->owner].name;
        const char *sep = nw == 0 ? (pos > 0 ? " and " : "") : nw == cnt - 1 ? " and " : ", ";
        const char *word = nw > 0             ? ""
                           : kind == EQ_JOINT ? (cnt > 1 ? "joints " : "joint ")
                                              : (cnt > 1 ? "drivers " : "driver ");
        if (pos < len) {
          int r = snprintf(buf + pos, len - pos, "%s%s'%s'", sep, word, name);
          if (r > 0) pos += (size_t)r;
        }
        nw++;
      }
    }
  }
done:
  fmbd_free(G), fmbd_free(w), fmbd_free(ix);
  return sing;
}

// Shared modal coordinates (GMs, fmbd_mbs_share_modal) and a rigidly redundant equation. An
// over-constrained mechanism with flexible bodies (the Sarrus linkage) keeps its rigidly
// redundant equations when the elastic columns make them independent at t = 0 (ndep
// combinations of the kept equations dependent on the frame coordinates alone). Each body's
// own elastic coordinates (FE dofs, NM, CB, GMc) keep them independent along the motion. Global
// modes shared by the bodies do not: they satisfy the linearised constraints, Cq x = 0, at the
// configuration they were computed at, so where the motion passes it the kept rows turn
// singular, and near it the redundant equation is held by large modal amplitudes. Measured on
// the Sarrus fall from p0 (examples/sarrus/README.md): kept, Newton fails at the linearisation
// height (4 global modes) or passes it with E 1.6 cm off (8 modes); the smallest singular value
// of the kept rows at t = 0 is 7e-5 to 1.6e-4 for GMs but also 1.8e-4 for the full model, so no
// tolerance tells the two apart. With shared coordinates the equations are therefore decided
// on the frame columns: for each such combination (the eigenvector of the smallest eigenvalue
// of the frame-only Gram matrix), the last joint equation, in the scene's order, with a weight
// above 0.1 of the combination's largest is removed, as find_redundant removes the later
// equations (a driver is never removed: find_redundant's rule; it stays kept).
static int drop_rigidly_redundant(fmbd_mbs *m, int64_t ndep) {
  for (; ndep > 0; ndep--) {
    double *G = NULL, *w = NULL;
    int64_t *ix = NULL, nc = 0, drop = -1;
    if (!kept_gram(m, true, &G, &w, &ix, &nc)) return FMBD_OK;
    double vmax = 0;
    for (int64_t k = 0; k < nc; k++) vmax = fmax(vmax, fabs(G[k]));
    for (int64_t k = 0; k < nc; k++) {
      if (fabs(G[k]) >= 0.1 * vmax) drop = ix[k];
    }
    fmbd_free(G), fmbd_free(w), fmbd_free(ix);
    if (drop < 0 || m->eq[drop].kind != EQ_JOINT) return FMBD_OK;
    meq *q = &m->eq[drop];
    char buf[512];
    mbs_eq_describe(m, q, buf, sizeof buf);
    int *red = fmbd_realloc(m->red, sizeof(int) * (size_t)(m->nred + 1));
    FMBD_CHECK(red, FMBD_ERR_NOMEM, "out of memory");
    m->red = red;
    FMBD_CHECK(q->text = fmbd_strdup(buf), FMBD_ERR_NOMEM, "out of memory");
    m->red[m->nred++] = (int)drop;
    q->kept = false;
    fmbd_log(FMBD_LOG_WARN,
             "redundant constraint removed: %s (dependent on the rigid motion; the shared modal "
             "coordinates (GMs) satisfy the linearised constraints at their linearisation "
             "configuration and cannot keep it independent)",
             buf);
  }
  return FMBD_OK;
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
    mbs_eq_time_derivs(m, m->t, e, &ft, &ftt);
    gam[q->row] = ftt;
  }
  if (vmax > 0) {
    double eps = 1e-5 / vmax;
    double *xs = m->xn;  // scratch
    memcpy(xs, m->x, sizeof(double) * (size_t)m->n);
    for (int sgn = -1; sgn <= 1; sgn += 2) {
      double *xe = m->xdn;  // scratch
      for (int64_t i = 0; i < m->n; i++) xe[i] = xs[i] + sgn * eps * m->xd[i];
      mbs_eval_constraints(m, xe, m->t, true);
      for (int64_t e = 0; e < m->neq; e++) {
        const meq *q = &m->eq[e];
        if (q->kept) gam[q->row] += sgn * mbs_eq_jv(m, q, m->xd) / (2 * eps);
      }
    }
    mbs_eval_constraints(m, m->x, m->t, true);
  }
}

void mbs_update_scales(fmbd_mbs *m) {
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
    if (b->share >= 0 && b->share != ib) continue;  // a shared set: once, by its owner
    double qm = 0, am = 0;
    for (int k = 0; k < b->nm; k++) {
      qm = fmax(qm, m->scale[b->qoff + k]);
      am = fmax(am, m->ascale[b->qoff + k]);
    }
    for (int k = 0; k < b->nm; k++) {
      int64_t i = b->qoff + k;
      m->scale[i] = qm, m->ascale[i] = am;
      m->nscale[i] = fmax(qm, 1e-3 * m->Lref * QUNIT(b));
    }
  }
}

// --- the phases of fmbd_mbs_init ------------------------------------------------------------
// settings: check them, keep a copy, and the generalized-alpha parameters (fmbd_mbs.h)
static int init_settings(fmbd_mbs *m, const fmbd_mbs_settings *s) {
  FMBD_CHECK(s->rho_inf >= 0 && s->rho_inf <= 1, FMBD_ERR_VALUE, "rho_inf %g outside [0, 1]",
             s->rho_inf);
  if (s->rho_inf > 0.99) {
    // measured (docs/STABILITY.md, "rho_inf and rotation"): at rho_inf = 1 the parasitic
    // root -1 of the index-3 scheme is undamped and rotation pushes it outside the unit circle:
    // the Euler parameters' p . p' alternates and grows by about h Omega / 2 per step, so a
    // body turning at Omega gains energy at a rate Omega / 2 whatever the step (a rigid rod at
    // 400 rad/s: +1e-4 at 0.08 s, collapse at 0.13 s); a spinning flexible rod doubled in 1 s
    fmbd_log(FMBD_LOG_WARN,
             "rho_inf %g > 0.99 leaves the index-3 scheme without damping of its parasitic "
             "mode: a body turning at Omega rad/s gains energy at a rate of about Omega/2 per "
             "second whatever the step (docs/STABILITY.md, rho_inf and rotation); 0.9 (the "
             "default) to 0.99 with steps below (1 - rho_inf)/Omega is safe",
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
  return FMBD_OK;
}

// the elastic mass block of each shared set (the sum of its bodies' Mff) and the Mff of a body
// added for a set but left alone must be positive definite
static int check_shared_mass(fmbd_mbs *m) {
  int rc = FMBD_OK;
  double *S = NULL;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (!(b->share == ib || (b->share < 0 && b->mff_unchecked)) || b->nm == 0) continue;
    size_t n2 = (size_t)b->nm * (size_t)b->nm;
    FMBD_GALLOC(S = fmbd_calloc(n2, sizeof(double)));
    for (int k = 0; k < m->nb; k++) {
      if (k != ib && (b->share < 0 || m->b[k].share != ib)) continue;
      for (size_t i = 0; i < n2; i++) S[i] += m->b[k].Mff[i];
    }
    int pd = mbs_spd(S, b->nm);
    fmbd_free(S);
    S = NULL;
    FMBD_CHECK(pd >= 0, FMBD_ERR_NOMEM, "out of memory");
    FMBD_CHECK(pd, FMBD_ERR_SINGULAR,
               "%s '%s': the modal mass matrix of the shared coordinates (the sum of the bodies' "
               "Mff) is not positive definite: a coordinate moves no body",
               b->share >= 0 ? "shared set of body" : "body", b->name);
  }
done:
  fmbd_free(S);
  return rc;
}

// dimensions: coordinate offsets, equation count, the state and workspace arrays
static int init_dimensions(fmbd_mbs *m) {
  int rc = FMBD_OK;
  int64_t n = 0;
  m->maxn = 7;
  m->maxb = 7;
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    b->off = n;
    // a shared set's elastic coordinates follow its owner's frame (fmbd_mbs_share_modal)
    b->gn = b->share >= 0 && b->share != ib ? 7 : b->n;
    n += b->gn;
    if (b->n > m->maxb) m->maxb = b->n;
    if (!b->fe && b->n > m->maxn) m->maxn = b->n;
  }
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    b->qoff = (b->share >= 0 ? m->b[b->share].off : b->off) + 7;
    b->qunit = b->fe ? 1.0 : sqrt(b->m);
    if (b->share >= 0) {  // sqrt of the set's mass: GMs coordinates are mass-normalised on it
      double ms = 0;
      for (int k = 0; k < m->nb; k++) ms += m->b[k].share == b->share ? m->b[k].m : 0;
      b->qunit = sqrt(ms);
    }
  }
  FMBD_GCALL(check_shared_mass(m));
  for (int ip = 0; ip < m->np; ip++) {
    if (m->p[ip].sup && 7 + m->p[ip].nsup > m->maxn) m->maxn = 7 + m->p[ip].nsup;
  }
  m->n = n;
  int64_t neq = 0;
  for (int j = 0; j < m->nj; j++) neq += m->j[j].neq;
  neq += m->nd + m->nb;
  m->neq = neq;
  size_t nn = (size_t)n;
  double **arrs[] = {&m->x,  &m->xd,  &m->xdd,   &m->a,      &m->xn,     &m->xdn,    &m->xddn,
                     &m->an, &m->res, &m->scale, &m->nscale, &m->ascale, &m->floor_, &m->rscale};
  for (size_t i = 0; i < sizeof arrs / sizeof arrs[0]; i++)
    FMBD_GALLOC(*arrs[i] = fmbd_calloc(nn, sizeof(double)));
  size_t mx = (size_t)m->maxn, n6 = mx - 1;
  FMBD_GALLOC(m->wk = fmbd_calloc(30 * mx, sizeof(double)));
  FMBD_GALLOC(m->bres = fmbd_calloc((size_t)m->maxb, sizeof(double)));
  FMBD_GALLOC(m->bblk = fmbd_calloc(mx * mx, sizeof(double)));
  FMBD_GALLOC(m->bwork = fmbd_calloc(2 * n6 * n6 + n6, sizeof(double)));
  FMBD_GALLOC(m->eq = fmbd_calloc((size_t)neq, sizeof(meq)));
done:
  return rc;
}

// The coordinates an equation's Jacobian covers on its side sd (pts: the joint's points, or
// -1): all of a modal body's (7 + nm), on an FE body the 7 rigid ones and those that move the
// point (a driven body coordinate; nothing more for the normalisation). cols may be NULL.
static int eq_side_cols(const fmbd_mbs *m, const meq *q, const int pts[2], int sd, int64_t *cols) {
  int ib;
  if (pts[0] >= 0) {
    ib = m->p[pts[sd]].body;
  } else {
    ib = q->b[sd];
  }
  if (ib < 0) return 0;
  const mbody *b = &m->b[ib];
  int cnt = 0;
  if (!b->fe) {
    for (int i = 0; i < b->n; i++, cnt++)
      if (cols) cols[cnt] = mbs_col(b, i);
    return cnt;
  }
  for (int i = 0; i < 7; i++, cnt++)
    if (cols) cols[cnt] = b->off + i;
  if (pts[0] >= 0) {
    const mpoint *P = &m->p[pts[sd]];
    for (int k = 0; k < P->nsup; k++, cnt++)
      if (cols) cols[cnt] = b->off + 7 + P->sup[k];
  } else if (q->kind == EQ_DRIVER && m->d[q->owner].coord >= 3) {
    if (cols) cols[cnt] = b->off + 7 + (m->d[q->owner].coord - 3);
    cnt++;
  }
  return cnt;
}

// equations: kind, owner, bodies, scale kind (positions get L_ref later) and Jacobian storage
static int init_equations(fmbd_mbs *m) {
  int rc = FMBD_OK;
  const int64_t neq = m->neq;
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
    int pts[2] = {-1, -1};
    if (q->kind == EQ_JOINT || (q->kind == EQ_DRIVER && m->d[q->owner].joint >= 0)) {
      const mjoint *j = &m->j[q->kind == EQ_JOINT ? q->owner : m->d[q->owner].joint];
      pts[0] = j->pt[0], pts[1] = j->pt[1];
    }
    q->nj = 0;
    for (int sd = 0; sd < 2; sd++) q->nj += eq_side_cols(m, q, pts, sd, NULL);
    q->kept = true;
    FMBD_GALLOC(q->jac = fmbd_calloc((size_t)(q->nj ? q->nj : 1), sizeof(double)));
    FMBD_GALLOC(q->cols = fmbd_calloc((size_t)(q->nj ? q->nj : 1), sizeof(int64_t)));
    for (int sd = 0, o = 0; sd < 2; sd++) o += eq_side_cols(m, q, pts, sd, q->cols + o);
  }
done:
  return rc;
}

// initial state of every body: x = [R; p; q0], x' = [v; p' from the angular velocity; qd0]
static void init_state(fmbd_mbs *m) {
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    double *x = m->x + b->off, *xd = m->xd + b->off;
    memcpy(x, b->x0, sizeof(double) * 7);
    if (b->nm && (b->share < 0 || b->share == ib))  // a shared set: its owner's
      memcpy(m->x + b->qoff, b->q0, sizeof(double) * (size_t)b->nm);
    memcpy(xd, b->v0, sizeof(double) * 3);
    double A[9], G[12], wl[3];
    quat_to_A(x + 3, A);
    quat_G(x + 3, G);
    mtv3(A, b->w0, wl);
    for (int c = 0; c < 4; c++)
      xd[3 + c] = 0.5 * (G[c] * wl[0] + G[4 + c] * wl[1] + G[8 + c] * wl[2]);
    if (b->nm && (b->share < 0 || b->share == ib))
      memcpy(m->xd + b->qoff, b->qd0, sizeof(double) * (size_t)b->nm);
  }
}

// the reference length L_ref (fmbd_mbs.h, STEP-SIZE) and the scales and floors of coordinates
// and equations
static void init_scales(fmbd_mbs *m) {
  const int64_t neq = m->neq;
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
    for (int i = 0; i < b->gn; i++) {
      int64_t k = b->off + i;
      if (i < 3)
        m->floor_[k] = 1e-3 * m->Lref, m->nscale[k] = m->Lref;
      else if (i < 7)
        m->floor_[k] = 1e-3, m->nscale[k] = 1;
      else
        m->floor_[k] = MODAL_FLOOR * m->Lref * QUNIT(b), m->nscale[k] = 1e-3 * m->Lref * QUNIT(b);
      m->scale[k] = m->floor_[k];
      // an FE dof is a nodal displacement (rotation) in the frame: the constraints' round-off
      // (eps Lref) reaches it through the frame's motion, amplified where the dof carries
      // little mass (a beam's nodal rotations), so its Newton increment stagnates at a few
      // eps Lref, not at eps nscale = 1e-3 eps Lref (measured: a two-link beam pendulum's FM).
      // A modal coordinate likewise, in its unit: eps Lref QUNIT (measured: the 8-link beam
      // pendulum of held modes, examples/nlink, stalled with increments of link1's first mode
      // at 1.7e-15 against the floor 1e3 eps nscale = 1.0e-15, residuals at 1e-16)
      m->rscale[k] = i >= 7 ? m->Lref * QUNIT(b) : m->nscale[k];
      // an Euler parameter likewise: a change de turns the body by 2 de and moves its mass
      // (radius of gyration gyr) by 2 gyr de, and its points' positions R + A s carry R's
      // round-off eps Lref, so the joints and forces cannot resolve e below eps Lref / (2 gyr):
      // the same floor in displacement as R's (1e3 eps Lref). Its floor 1e3 eps |e| = 1e3 eps
      // was 230x finer on a long chain (Lref 40 m, gyr 0.087 m), the acceleration bound
      // newton_tol ascale beta h^2 below it at h = 1e-3 s, and at 1,965 of 2,000 steps of the
      // 100-link chain the last iterate's worst coordinate was an Euler parameter at that
      // floor; with this one 3.2 instead of 4.0 Newton iterations a step, the tips 1.3e-9 m
      // from the old floor's newton_tol 1e-10 run, the step's own error 1.3e-5 m (h against h / 2)
      // (bench/README.md, "An Euler parameter's round-off floor")
      if (i >= 3 && i < 7 && b->gyr > 0) m->rscale[k] = fmax(1, m->Lref / (2 * b->gyr));
    }
  }
  for (int64_t e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    if (q->sc == 0) q->sc = m->Lref;
    if (q->sc < 0) q->sc = 1e-3 * m->Lref * QUNIT(&m->b[q->b[0]]);
  }
  mbs_update_scales(m);
}

// redundant equations at the initial configuration (skipped for a tree of joints), then the
// rows of the kept ones, the multiplier and right-hand side arrays and the matrix pattern
static int init_redundancy(fmbd_mbs *m) {
  int rc = FMBD_OK;
  const int64_t neq = m->neq;
  mbs_eval_constraints(m, m->x, m->t, true);
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
    // with shared modal coordinates, the kept combinations dependent on the rigid motion
    // alone are removed (drop_rigidly_redundant)
    bool shared = false;
    for (int ib = 0; ib < m->nb; ib++) shared = shared || m->b[ib].share >= 0;
    // a rigid dependence is exact at the scene's undeformed assembly: the Sarrus linkage's
    // frame-only singular values are 0 (below the 1e-7 the eigenvalues of C'C resolve) and
    // then 0.14; 1e-5 stays 100 times above that round-off, and a dead point (s falling as the
    // square root of the distance to it, SINGULAR_TOL) reaches it only 1e-4 of the way from
    // s = 1e-3 to the fold, where the run would stop anyway
    int64_t ndep = shared ? frame_dependent(m, 1e-5) : 0;
    if (ndep > 0) FMBD_GCALL(drop_rigidly_redundant(m, ndep));
  }
  int64_t kept = 0;
  for (int64_t e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    q->row = q->kept ? kept++ : -1;
  }
  m->m = kept;
  m->N = m->n + kept;
  FMBD_GALLOC(m->lam = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  FMBD_GALLOC(m->lamn = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  for (int k = 0; k < PRED_NH; k++) {
    FMBD_GALLOC(m->lamh[k] = fmbd_calloc((size_t)kept + 1, sizeof(double)));
    FMBD_GALLOC(m->xddh[k] = fmbd_calloc((size_t)m->n + 1, sizeof(double)));
  }
  FMBD_GALLOC(m->itx = fmbd_calloc((size_t)m->n + 1, sizeof(double)));
  FMBD_GALLOC(m->rhs = fmbd_calloc((size_t)m->N, sizeof(double)));
  FMBD_GCALL(mbs_build_pattern(m));
done:
  return rc;
}

// equations removed as redundant must hold too (dependent to first order but violated means
// the assembly is inconsistent, e.g. two ball joints too far apart on one rod)
static int removed_hold(fmbd_mbs *m, const double *x, double t, const char *what) {
  mbs_eval_constraints(m, x, t, false);
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (q->kept || mbs_eq_scaled(m, q) <= 1e-8) continue;
    char buf[512];
    mbs_eq_describe(m, q, buf, sizeof buf);
    FMBD_FAIL(FMBD_ERR_CONVERGE,
              "%s cannot be made consistent with the constraints: the redundant %s is violated by "
              "%.3g (scaled)",
              what, buf, mbs_eq_scaled(m, q));
  }
  return FMBD_OK;
}

int fmbd_mbs_check_removed(fmbd_mbs *m, double t, const double *x) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "fmbd_mbs_check_removed before fmbd_mbs_init");
  return removed_hold(m, x ? x : m->x, t, "the configuration");
}

// positions: minimum-change (mass metric) Newton onto Phi = 0; the redundant equations must
// hold too; Euler parameters normalised exactly
static int init_positions(fmbd_mbs *m) {
  int rc = FMBD_OK;
  const int64_t neq = m->neq;
  {
    int it;
    double r = 0, rprev = INFINITY;
    int64_t worst = -1;
    for (it = 0; it < 50; it++) {
      mbs_eval_system(m, m->t, NULL, true, 1, 0, 0, false);
      r = worst_eq(m, &worst);
      if (r <= 1e-13 || (it > 3 && r >= rprev)) break;
      rprev = r;
      FMBD_GCALL(mbs_factor(m));
      memset(m->rhs, 0, sizeof(double) * (size_t)m->N);
      for (int64_t e = 0; e < neq; e++) {
        if (m->eq[e].kept) m->rhs[m->n + m->eq[e].row] = -m->eq[e].phi;
      }
      FMBD_GCALL(mbs_solve(m, m->rhs));
      for (int64_t i = 0; i < m->n; i++) m->x[i] += m->rhs[i];
    }
    if (r > 1e-10) {
      char buf[512] = "?";
      if (worst >= 0) mbs_eq_describe(m, &m->eq[worst], buf, sizeof buf);
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
  FMBD_GCALL(removed_hold(m, m->x, m->t, "initial positions"));
  // normalise the Euler parameters exactly
  for (int ib = 0; ib < m->nb; ib++) {
    double *p = m->x + m->b[ib].off + 3;
    double pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
    for (int c = 0; c < 4; c++) p[c] /= pn;
  }
done:
  return rc;
}

// velocities: [M Phi_x'; Phi_x 0] [x'; mu] = [M x'0; -Phi_t]
static int init_velocities(fmbd_mbs *m) {
  int rc = FMBD_OK;
  const int64_t neq = m->neq;
  mbs_eval_system(m, m->t, NULL, true, 1, 0, 0, false);
  mbs_fill_modal_blocks(m);  // the body blocks of Ax are read below
  FMBD_GCALL(mbs_factor(m));
  {
    memset(m->rhs, 0, sizeof(double) * (size_t)m->N);
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      const int64_t *pos = m->bpos[ib];
      if (b->fe) {
        mbs_fe_block_mul(b, m->Ax, m->xd + b->off, m->rhs + b->off);
        continue;
      }
      // a shared set's elastic block holds the sum of its bodies': added once, by the owner
      bool other = b->share >= 0 && b->share != ib;
      for (int j = 0; j < b->n; j++) {
        for (int i = 0; i < b->n; i++) {
          if (other && i >= 7 && j >= 7) continue;
          m->rhs[mbs_col(b, i)] += m->Ax[pos[i + b->n * j]] * m->xd[mbs_col(b, j)];
        }
      }
    }
    for (int64_t e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      double ft, ftt;
      mbs_eq_time_derivs(m, m->t, e, &ft, &ftt);
      m->rhs[m->n + q->row] = -ft;
    }
    double vres = 0;
    for (int64_t e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      vres = fmax(vres, fabs(mbs_eq_jv(m, q, m->xd) - m->rhs[m->n + q->row]) / q->sc);
    }
    FMBD_GCALL(mbs_solve(m, m->rhs));
    memcpy(m->xd, m->rhs, sizeof(double) * (size_t)m->n);
    if (vres > 1e-12) fmbd_log(FMBD_LOG_INFO, "initial velocities projected onto the constraints");
  }
done:
  return rc;
}

// consistent accelerations and multipliers: [M Phi_x'; Phi_x 0] [x''; lambda] = [-(v - f); -gam]
static int init_accelerations(fmbd_mbs *m) {
  int rc = FMBD_OK;
  const int64_t neq = m->neq, kept = m->m;
  double *gam = NULL;
  FMBD_GALLOC(gam = fmbd_calloc((size_t)kept + 1, sizeof(double)));
  {
    constraint_gamma(m, gam);
    mbs_eval_system(m, m->t, NULL, false, 1, 0, 0, false);  // res = T'(v - f)
    for (int64_t i = 0; i < m->n; i++) m->rhs[i] = -m->res[i];
    for (int64_t e = 0; e < neq; e++) {
      const meq *q = &m->eq[e];
      if (q->kept) m->rhs[m->n + q->row] = -gam[q->row];
    }
    FMBD_GCALL(mbs_solve(m, m->rhs));
    memcpy(m->xdd, m->rhs, sizeof(double) * (size_t)m->n);
    memcpy(m->a, m->xdd, sizeof(double) * (size_t)m->n);
    for (int64_t k = 0; k < kept; k++) m->lam[k] = m->rhs[m->n + k];
  }
done:
  fmbd_free(gam);
  return rc;
}

int fmbd_mbs_init(fmbd_mbs *m, const fmbd_mbs_settings *s) {
  FMBD_CHECK(!m->ready, FMBD_ERR_VALUE, "fmbd_mbs_init called twice");
  FMBD_CHECK(m->nb > 0, FMBD_ERR_VALUE, "the system has no bodies");
  FMBD_CHECK(s, FMBD_ERR_VALUE, "no settings");
  FMBD_CALL(init_settings(m, s));
  FMBD_CALL(init_dimensions(m));
  FMBD_CALL(init_equations(m));
  init_state(m);
  init_scales(m);
  m->t = 0;
  FMBD_CALL(init_redundancy(m));
  if (!m->set.linearise_only) {  // (gmsolve: its own consistent configuration, zero velocities)
    FMBD_CALL(init_positions(m));
    FMBD_CALL(init_velocities(m));
    FMBD_CALL(init_accelerations(m));
  }
  // acceleration scales: the largest |x''_i| seen, at least nscale_i / t_end^2
  for (int64_t i = 0; i < m->n; i++) m->ascale[i] = m->nscale[i] / (m->set.t_end * m->set.t_end);
  mbs_update_scales(m);
  m->need_factor = true;
  m->h_next = m->set.fixed ? m->set.step : m->set.first_step;
  m->h_fact = 0;
  m->h_prop = 0;
  m->err_prev[0] = m->err_prev[1] = 0;
  m->k_out = 0;
  m->pred_rigid = true;  // the predictor's order chosen only for rigid bodies (fmbd_mbs_step.c)
  for (int ib = 0; ib < m->nb; ib++)
    if (m->b[ib].n != 7) m->pred_rigid = false;
  m->st.coordinates = m->n;
  m->st.equations = m->m;
  m->st.redundant = m->nred;
  m->ready = true;
  return FMBD_OK;
}
