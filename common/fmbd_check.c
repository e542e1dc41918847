// common/fmbd_check.c: checking a Craig-Bampton body a posteriori (see fmbd_check.h)
// SPDX-License-Identifier: MIT
#include "fmbd_check.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmbd_alloc.h"
#include "fmbd_eig.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"
#include "fmbd_sha256.h"

void fmbd_check_opts_defaults(fmbd_check_opts *o) {
  memset(o, 0, sizeof *o);
}

fmbd_est *fmbd_check_estimator(fmbd_check *c) {
  return c->est_held ? c->est_held : c->est;
}

static char *path_beside(const char *ref, const char *name) {
  const char *slash = strrchr(ref, '/');
  if (!slash || name[0] == '/') {
    return fmbd_strdup(name);
  }
  size_t n = (size_t)(slash - ref) + strlen(name) + 2;
  char *p = fmbd_malloc(n);
  if (p) {
    snprintf(p, n, "%.*s/%s", (int)(slash - ref), ref, name);
  }
  return p;
}

int fmbd_check_load_fe(fmbd_check *c, bool required, const char *why) {
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  char *cand = NULL;
  const fmbd_check_opts *o = &c->opts;
  if (c->fe) {
    return FMBD_OK;
  }
  if (o->fe && !o->plain && !required) {
    // a file the user named must be usable: never a warning and a silent fallback
    required = true;
    why = "it was given with --fe";
  }
  if ((c->fe_tried || o->plain) && !required) {
    return FMBD_OK;
  }
  c->fe_tried = true;
  double t_open = fmbd_wall_s(), c_open = fmbd_cpu_s();
  const char *cbname = fmbd_h5_name(c->cbf);
  const char *name = o->fe ? o->fe : c->cb->fe_file;
  if (!name || !name[0]) {
    fmbd_err_context(cbname, "/cb");
    if (required) {
      FMBD_GFAIL(FMBD_ERR_FORMAT, "no fe file recorded (attribute fe_file) and no --fe given: %s",
                 why);
    }
    goto done;
  }
  // as given, else beside the cb file
  if (o->fe || access(name, R_OK) == 0) {
    FMBD_GALLOC(cand = fmbd_strdup(name));
  } else {
    FMBD_GALLOC(cand = path_beside(cbname, name));
    if (access(cand, R_OK) != 0) {
      fmbd_free(cand);
      FMBD_GALLOC(cand = fmbd_strdup(name));
    }
  }
  rc = fmbd_h5_open(cand, &f);
  if (rc != FMBD_OK) {
    if (!required) {
      fmbd_log(FMBD_LOG_WARN,
               "%s: source fe file %s not readable; estimates from the cb file alone", cbname,
               cand);
      fmbd_err_clear();
      rc = FMBD_OK;
      goto done;
    }
    fmbd_err_context(cbname, "/cb");
    FMBD_GFAIL(FMBD_ERR_IO, "source fe file %s (attribute fe_file%s) cannot be read: %s", cand,
               o->fe ? ", or --fe" : "", why);
  }
  fmbd_err_context(cand, "");
  FMBD_GCALL(fmbd_h5_check_format(
      f, FMBD_FE_FORMAT, FMBD_FE_FORMAT_MAJOR));  // the kind first: a cb file is not "changed"
  const char *sha = fmbd_h5_sha256(f);
  if (c->cb->fe_sha256[0] && strcmp(sha, c->cb->fe_sha256) != 0) {
    if (!required) {
      fmbd_log(FMBD_LOG_WARN, "%s: %s changed since fe2cb read it (SHA-256 differs); not used",
               cbname, cand);
      goto done;
    }
    fmbd_err_context(cbname, "/cb");
    FMBD_GFAIL(FMBD_ERR_VALUE,
               "source fe file %s changed since fe2cb read it: SHA-256 %.12s..., recorded "
               "fe_sha256 %.12s... (%s)",
               cand, sha, c->cb->fe_sha256, why);
  }
  fmbd_err_context(cand, "");
  // K and M only (all that the estimate and --exact use): the SHA-256 check above makes this
  // the very file fe2cb read and validated whole (when the cb file records fe_sha256)
  FMBD_GCALL(fmbd_fe_read_matrices(f, &c->fe));
  if (!c->fe->K || !c->fe->M || c->fe->ndof != c->cb->ndof) {
    fmbd_err_context(cand, "/K");
    fmbd_fe_body_destroy(&c->fe);
    FMBD_GFAIL(FMBD_ERR_FORMAT, "no stiffness and mass of %lld dofs to match the cb file",
               (long long)c->cb->ndof);
  }
  snprintf(c->fe_sha, sizeof c->fe_sha, "%s", sha);
  c->t_load_s = fmbd_wall_s() - t_open;
  c->c_load_s = fmbd_cpu_s() - c_open;
  c->fe_name = cand;
  cand = NULL;
done:
  fmbd_free(cand);
  fmbd_h5_close(&f);
  return rc;
}

// holds: the positions in /cb/boundary_dofs of the held interfaces' dofs, and the others
static int held_partition(fmbd_check *c) {
  int rc = FMBD_OK;
  const fmbd_cb *cb = c->cb;
  const fmbd_fe_body *d = c->desc;
  bool *held = NULL;
  FMBD_GALLOC(held = fmbd_calloc((size_t)(cb->nb + 1), sizeof(bool)));
  FMBD_GALLOC(c->held_idx = fmbd_malloc(sizeof(int64_t) * (size_t)(cb->nb + 1)));
  FMBD_GALLOC(c->free_idx = fmbd_malloc(sizeof(int64_t) * (size_t)(cb->nb + 1)));
  for (int q = 0; q < c->opts.nhold; q++) {
    const char *want = c->opts.hold[q];
    int found = -1;
    for (int i = 0; i < d->ninterfaces; i++) {
      if (!strcmp(d->interfaces[i].name, want)) found = i;
    }
    if (found < 0) {
      char names[512] = "";
      for (int i = 0; i < d->ninterfaces; i++) {
        size_t l = strlen(names);
        snprintf(names + l, sizeof names - l, "%s%s", i ? ", " : "", d->interfaces[i].name);
      }
      fmbd_err_context(fmbd_h5_name(c->cbf), "/interfaces");
      FMBD_GFAIL(FMBD_ERR_VALUE, "--hold %s: no such interface (the body has: %s)", want,
                 names[0] ? names : "none");
    }
    int64_t node = d->interfaces[found].node, n = 0;
    for (int64_t j = 0; j < cb->nb; j++) {
      if (d->dofs[2 * cb->boundary[j]] == node) held[j] = true, n++;
    }
    FMBD_GCHECK(n > 0, FMBD_ERR_VALUE, "--hold %s: its node is not among the boundary dofs", want);
  }
  c->nheld = c->nfree = 0;
  for (int64_t j = 0; j < cb->nb; j++) {
    if (held[j])
      c->held_idx[c->nheld++] = j;
    else
      c->free_idx[c->nfree++] = j;
  }
done:
  fmbd_free(held);
  return rc;
}

// Residual blocks at nd = pool (projected with Ks, Ms when the fe file is there) -> estimators
static int set_pool(fmbd_check *c) {
  int rc = FMBD_OK;
  fmbd_cb *cb = c->cb;
  int64_t nb = cb->nb;
  double *Xb = fmbd_calloc((size_t)(nb * nb + 1), sizeof(double));
  double *Gb = fmbd_calloc((size_t)(nb * nb + 1), sizeof(double));
  FMBD_GCHECK(Xb && Gb, FMBD_ERR_NOMEM, "out of memory");
  if (nb > 0) {
    if (c->fe && !c->opts.plain) {
      FMBD_GCALL(fmbd_est_base_projected(c->fe->K, c->fe->M, cb->ns, cb->interior, nb, cb->nd,
                                         cb->A, cb->KsinvA, cb->Phi, cb->kappa, cb->PhitA, Xb, Gb));
    } else {
      FMBD_GCALL(fmbd_est_base_plain(cb->ns, nb, cb->nd, cb->A, cb->KsinvA, cb->KsinvMsKsinvA,
                                     cb->kappa, cb->PhitA, Xb, Gb, NULL));
    }
  }
  FMBD_GCALL(fmbd_est_set_pool(c->est, cb->nd, cb->kappa, cb->PhitA, Xb, Gb));
  fmbd_est_set_kappa_next(c->est, cb->kappa_next);
  if (c->est_held) {
    FMBD_GCALL(fmbd_est_set_pool_subset(c->est_held, c->est, c->nfree, c->free_idx));
  }
done:
  fmbd_free(Xb);
  fmbd_free(Gb);
  return rc;
}

// the estimator of the body as reduced: its boundary blocks of /reduced
static int create_estimator(fmbd_check *c) {
  const fmbd_cb *cb = c->cb;
  int64_t nb = cb->nb, nd = cb->nd, nr = cb->nr;
  double *Mbb = fmbd_calloc((size_t)(nb * nb + 1), sizeof(double));
  double *Kbb = fmbd_calloc((size_t)(nb * nb + 1), sizeof(double));
  if (!Mbb || !Kbb) {
    fmbd_free(Mbb);
    fmbd_free(Kbb);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < nb; i++) {
      Mbb[i + nb * j] = cb->Mr[(nd + i) + nr * (nd + j)];
      Kbb[i + nb * j] = cb->Kr[(nd + i) + nr * (nd + j)];
    }
  }
  fmbd_est_opts eopt;
  fmbd_est_opts_defaults(&eopt);
  int rc = fmbd_est_create(nb, Mbb, Kbb, &eopt, &c->est);
  fmbd_free(Mbb);
  fmbd_free(Kbb);
  return rc;
}

int fmbd_check_open(const char *cb_path, const fmbd_check_opts *o, fmbd_check **out) {
  int rc = FMBD_OK;
  *out = NULL;
  fmbd_check *c = fmbd_calloc(1, sizeof *c);
  FMBD_CHECK(c, FMBD_ERR_NOMEM, "out of memory");
  c->opts = *o;
  // its SHA-256 only when an rflex file records it (fmbd_check_write_rflex)
  FMBD_GCALL(fmbd_h5_open_unhashed(cb_path, &c->cbf));
  FMBD_GCALL(fmbd_h5_check_format(c->cbf, FMBD_CB_FORMAT, FMBD_CB_FORMAT_MAJOR));
  FMBD_GCALL(fmbd_cb_read(c->cbf, &c->cb));
  FMBD_GCALL(fmbd_fe_read(c->cbf, &c->desc));
  c->nd_file = c->cb->nd;
  c->nd_max = c->cb->ns - 1;
  if (o->max_modes > 0 && o->max_modes < c->nd_max) {
    c->nd_max = o->max_modes;
  }
  FMBD_GCALL(fmbd_check_load_fe(c, false, ""));
  FMBD_GCALL(create_estimator(c));
  FMBD_GCALL(set_pool(c));
  if (o->nhold > 0) {
    FMBD_GCALL(held_partition(c));
    FMBD_GCALL(fmbd_est_create_subset(c->est, c->nfree, c->free_idx, &c->est_held));
  }
  *out = c;
  return FMBD_OK;
done:
  fmbd_check_close(&c);
  return rc;
}

void fmbd_check_close(fmbd_check **pc) {
  fmbd_check *c = *pc;
  if (!c) {
    return;
  }
  fmbd_est_destroy(&c->est);
  fmbd_est_destroy(&c->est_held);
  fmbd_free(c->held_idx);
  fmbd_free(c->free_idx);
  fmbd_fe_body_destroy(&c->fe);
  fmbd_fe_body_destroy(&c->desc);
  fmbd_free(c->fe_name);
  fmbd_free(c->subset_scene);
  fmbd_free(c->subset_body);
  fmbd_cb_destroy(&c->cb);
  fmbd_h5_close(&c->cbf);
  fmbd_free(c);
  *pc = NULL;
}

// ctx: a label ("more fixed-interface modes", "exact eigenvalues")
static void eig_progress(void *ctx, const char *stage, int64_t solves, int64_t nev) {
  fmbd_progress("%s (%lld): %s, %lld solves", (const char *)ctx, (long long)nev, stage,
                (long long)solves);
}

int fmbd_check_extend(void *ctx, fmbd_est *e, int64_t nd_wanted) {
  fmbd_check *c = ctx;
  (void)e;
  char why[128];
  snprintf(why, sizeof why, "%lld fixed-interface modes needed, the cb file has %lld",
           (long long)nd_wanted, (long long)c->cb->nd);
  FMBD_CALL(fmbd_check_load_fe(c, true, why));
  int64_t np = c->cb->nd;
  int64_t grow = np / 2 > 10 ? np / 2 : 10;
  int64_t nd_new = nd_wanted > np + grow ? nd_wanted : np + grow;
  if (nd_new > c->nd_max) {
    nd_new = c->nd_max;
  }
  if (nd_new < nd_wanted) {
    nd_new = nd_wanted;
  }
  fmbd_log(FMBD_LOG_INFO, "extending the fixed-interface modes from %lld to %lld", (long long)np,
           (long long)nd_new);
  double t0 = fmbd_wall_s();
  fmbd_eig_opts eo;
  fmbd_eig_opts_defaults(&eo);
  eo.progress = eig_progress;
  eo.progress_ctx = (void *)"more fixed-interface modes";
  fmbd_err_context(c->fe_name, "/K");
  FMBD_CALL(fmbd_cb_extend(c->fe->K, c->fe->M, c->cb, nd_new, &eo));
  fmbd_progress(NULL);
  FMBD_CALL(set_pool(c));
  c->t_extend_s += fmbd_wall_s() - t0;
  c->nextend++;
  return FMBD_OK;
}

static fmbd_check_exact_engine exact_engine;  // NULL: fmbd_eig_solve
static void *exact_engine_ctx;

void fmbd_check_set_exact_engine(fmbd_check_exact_engine fn, void *ctx) {
  exact_engine = fn;
  exact_engine_ctx = ctx;
}

int fmbd_check_exact(fmbd_check *c, const fmbd_est_modes *m, int64_t nflex, double **chi) {
  *chi = fmbd_calloc((size_t)nflex + 1, sizeof(double));
  FMBD_CHECK(*chi, FMBD_ERR_NOMEM, "out of memory");
  if (!strcmp(c->cb->method, "nm")) {
    int64_t j = 0;
    for (int64_t k = 0; k < m->nmodes && j < nflex; k++) {
      if (!m->rigid[k]) {
        (*chi)[j++] = m->chibar[k];
      }
    }
    return FMBD_OK;
  }
  FMBD_CALL(fmbd_check_load_fe(c, true, "--exact needs the full body"));
  int64_t nrig = c->cb->n_rigid;
  fmbd_eig_opts eo;
  fmbd_eig_opts_defaults(&eo);
  eo.nev = nrig + nflex;
  eo.free_body = nrig > 0;
  eo.progress = eig_progress;
  eo.progress_ctx = (void *)"exact eigenvalues of the full body";
  fmbd_eig_result res = {0};
  double t0 = fmbd_wall_s(), c0 = fmbd_cpu_s();
  fmbd_err_context(c->fe_name, "/K");
  int rc = FMBD_OK;
  if (exact_engine) {
    res.lambda = fmbd_calloc((size_t)eo.nev, sizeof(double));
    FMBD_CHECK(res.lambda, FMBD_ERR_NOMEM, "out of memory");
    rc = exact_engine(exact_engine_ctx, c->fe_name, c->fe->K, c->fe->M, eo.nev, eo.free_body,
                      res.lambda);
  } else {
    rc = fmbd_eig_solve(c->fe->K, c->fe->M, NULL, &eo, &res);
  }
  fmbd_progress(NULL);
  c->t_exact_s += fmbd_wall_s() - t0;
  c->c_exact_s += fmbd_cpu_s() - c0;
  if (rc == FMBD_OK) {
    memcpy(*chi, res.lambda + nrig, sizeof(double) * (size_t)nflex);
  }
  fmbd_eig_result_free(&res);
  return rc;
}

int fmbd_check_rflex(fmbd_check *c, const fmbd_est_modes *m, const double *Xi, int64_t nm,
                     bool stress, fmbd_rflex **rf, int64_t *nkept) {
  int rc = FMBD_OK;
  const fmbd_cb *cb = c->cb;
  fmbd_est *E = fmbd_check_estimator(c);
  int64_t nd = fmbd_est_nd(E), nr = nd + fmbd_est_nb(E);
  double *chif = fmbd_calloc((size_t)nm + 1, sizeof(double));
  double *Xif = fmbd_calloc((size_t)(nr * nm) + 1, sizeof(double));
  FMBD_GCHECK(chif && Xif, FMBD_ERR_NOMEM, "out of memory");
  int64_t j = 0;
  for (int64_t k = 0; k < m->nmodes && j < nm; k++) {
    if (!m->rigid[k]) {
      chif[j] = m->chibar[k];
      memcpy(Xif + nr * j, Xi + nr * k, sizeof(double) * (size_t)nr);
      j++;
    }
  }
  *nkept = nm;
  int64_t ldx = nr;
  if (c->est_held) {
    // the held problem's modes with the held dofs' constraint modes, Ritz on the full body
    // (docs/THEORY.md section 12)
    double *ch = NULL, *xh = NULL;
    rc = fmbd_est_held_modes(c->est, c->nheld, c->held_idx, nm, Xif, nr, nkept, &ch, &xh);
    fmbd_free(chif);
    fmbd_free(Xif);
    chif = ch;
    Xif = xh;
    ldx = nd + cb->nb;
    FMBD_GCALL(rc);
  }
  if (stress && c->desc->ntet == 0) {
    // modal stress is recovered from solid elements only: without them it would be all zero
    // (a beam body, or a file whose /mesh/elements was lost); none is written, and an output
    // asking for stress is then refused by fmbd-run
    stress = false;
    fmbd_log(c->desc->nbeam > 0 ? FMBD_LOG_INFO : FMBD_LOG_WARN,
             "%s: no solid elements (/mesh/elements/tet4 or tet10)%s: no modal stress written",
             fmbd_h5_name(c->cbf), c->desc->nbeam > 0 ? ", beams only" : "");
  }
  fmbd_rflex_input mi = {c->desc, cb->ns, cb->nb,  cb->interior, cb->boundary, nd,
                         cb->Phi, cb->ns, cb->Psi, *nkept,       chif,         Xif,
                         ldx,     stress, false,   NULL};
  rc = fmbd_rflex_build(&mi, rf);
done:
  fmbd_free(chif);
  fmbd_free(Xif);
  return rc;
}

int fmbd_check_subset_for_scene(fmbd_check *c, fmbd_rflex *rf, const char *spec) {
  int rc = FMBD_OK;
  fmbd_scene *s = NULL;
  int64_t *mo = NULL, *st = NULL, nmo = 0, nst = 0;
  char *file = NULL;
  const char *colon = strrchr(spec, ':');
  FMBD_GCHECK(colon && colon != spec && colon[1], FMBD_ERR_VALUE,
              "--for-scene %s: give SCENE.yaml:BODY", spec);
  FMBD_GALLOC(file = fmbd_strdup(spec));
  file[colon - spec] = 0;
  const char *body = colon + 1;
  FMBD_GCALL(fmbd_scene_read(file, &s));
  int bi = fmbd_scene_find_body(s, body);
  FMBD_GCHECK(bi >= 0 && s->bodies[bi].kind == FMBD_SCENE_FLEXIBLE, FMBD_ERR_VALUE,
              "--for-scene: %s has no flexible body '%s'", file, body);
  FMBD_GCALL(fmbd_scene_body_nodes(s, bi, rf, &mo, &nmo, &st, &nst));
  int64_t ndof = rf->ndof;
  FMBD_GCALL(fmbd_rflex_subset(rf, nmo, mo, nst, st));
  int64_t held = 0;
  for (int64_t p = 0; p < rf->nnodes; p++) held += rf->held[p] != 0;
  fmbd_log(FMBD_LOG_INFO,
           "for scene %s, body '%s': modal motion of %lld of %lld nodes (%lld of %lld dofs), "
           "stress at %lld",
           file, body, (long long)held, (long long)rf->nnodes, (long long)rf->ndof, (long long)ndof,
           (long long)rf->nstress);
  FMBD_GCALL(fmbd_sha256_file(file, c->subset_sha));
  fmbd_free(c->subset_scene);
  fmbd_free(c->subset_body);
  c->subset_scene = file;
  file = NULL;
  FMBD_GALLOC(c->subset_body = fmbd_strdup(body));
done:
  fmbd_free(file);
  fmbd_free(mo);
  fmbd_free(st);
  fmbd_scene_destroy(&s);
  return rc;
}

int fmbd_check_write_rflex(fmbd_check *c, const char *path, const fmbd_rflex *rf,
                           const fmbd_check_record *rec, double wall_s, double cpu_s) {
  int rc = FMBD_OK;
  fmbd_h5 *out = NULL;
  const char *cb_sha = NULL;
  FMBD_GCALL(fmbd_h5_sha256_now(c->cbf, &cb_sha));
  FMBD_GCALL(fmbd_h5_create(path, FMBD_RFLEX_FORMAT, FMBD_RFLEX_VERSION, &out));
  FMBD_GCALL(fmbd_h5_add_input(out, fmbd_h5_name(c->cbf), cb_sha));
  if (c->fe_name) {
    FMBD_GCALL(fmbd_h5_add_input(out, c->fe_name, c->fe_sha));
  }
  if (rf->held) {  // a subset body: the description without the whole body's dofs, /expand
    // and elements (fmbd_rflex_write writes its own /dofs and /expand)
    static const char *const part[] = {"/mesh/nodes", "/mesh/node_mass", "/mesh/groups",
                                       "/material",   "/body",           "/interfaces",
                                       "/clamped"};
    for (size_t i = 0; i < sizeof part / sizeof *part; i++) {
      if (i < 2 || fmbd_h5_exists(c->cbf, part[i])) FMBD_GCALL(fmbd_h5_copy(c->cbf, part[i], out));
    }
    if (c->subset_scene) FMBD_GCALL(fmbd_h5_add_input(out, c->subset_scene, c->subset_sha));
  } else {
    FMBD_GCALL(fmbd_fe_copy_description(c->cbf, out));
  }
  FMBD_GCALL(fmbd_rflex_write(out, rf));
  if (rf->held && c->subset_scene) {
    FMBD_GCALL(fmbd_h5_write_attr_str(out, "/subset", "scene", c->subset_scene));
    FMBD_GCALL(fmbd_h5_write_attr_str(out, "/subset", "body", c->subset_body));
  }
  int64_t ndv = rec->nd;
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/modes", "n_fixed_interface_modes", 1, &ndv));
  FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/modes", "max_estimate", 1, &rec->max_estimate));
  if (rec->tolerance > 0) {
    FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/modes", "tolerance", 1, &rec->tolerance));
  }
  {  // the interfaces held in the problem the modes were selected for ("" = none: free)
    char held[1024] = "";
    for (int q = 0; q < c->opts.nhold; q++) {
      size_t l = strlen(held);
      snprintf(held + l, sizeof held - l, "%s%s", q ? "," : "", c->opts.hold[q]);
    }
    FMBD_GCALL(fmbd_h5_write_attr_str(out, "/modes", "held_interfaces", held));
  }
  FMBD_GCALL(fmbd_h5_commit(&out, wall_s, cpu_s));
done:
  fmbd_h5_close(&out);
  return rc;
}
