// common/fmbd_scene_build.c: a scene (fmbd_scene.h) turned into a multibody system (fmbd_mbs.h)
// SPDX-License-Identifier: MIT
//
// Body files are opened here; every error names the scene file and the line:column of the
// item at fault (the body's `file` key, the joint, the output), and the body file.
#include "fmbd_scene_build.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_eig.h"
#include "fmbd_err.h"
#include "fmbd_gm.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"

#define SFAIL(s, loc, code, ...)    \
  do {                              \
    fmbd_scene_context((s), (loc)); \
    FMBD_GFAIL(code, __VA_ARGS__);  \
  } while (0)

static void fe_node_modes(const fmbd_scene_model *m, int bi, int64_t node, int64_t n, double *T,
                          double *R);

// the initial state of a scene body
static fmbd_mbs_state0 body_state0(const fmbd_scene_body *b) {
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  memcpy(s0.position, b->position, sizeof s0.position);
  memcpy(s0.rotation, b->rotation, sizeof s0.rotation);
  memcpy(s0.velocity, b->velocity, sizeof s0.velocity);
  memcpy(s0.angular_velocity, b->angular_velocity, sizeof s0.angular_velocity);
  return s0;
}

// --- keeping the first n modes of a modal body ----------------------------------------------
static int truncate_modes(fmbd_rflex *r, int64_t n) {
  int64_t nm = r->nm;
  if (n >= nm) return 0;
  double *SS = fmbd_malloc(sizeof(double) * (size_t)(9 * n * n + 1));
  double *Mff = fmbd_malloc(sizeof(double) * (size_t)(n * n + 1));
  double *Kff = fmbd_malloc(sizeof(double) * (size_t)(n * n + 1));
  if (!SS || !Mff || !Kff) {
    fmbd_free(SS);
    fmbd_free(Mff);
    fmbd_free(Kff);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t l = 0; l < n; l++) {
    for (int64_t k = 0; k < n; k++) {
      memcpy(SS + 9 * k + 9 * n * l, r->SS + 9 * k + 9 * nm * l, 9 * sizeof(double));
      Mff[k + n * l] = r->Mff[k + nm * l];
      Kff[k + n * l] = r->Kff[k + nm * l];
    }
  }
  fmbd_free(r->SS);
  fmbd_free(r->Mff);
  fmbd_free(r->Kff);
  r->SS = SS;
  r->Mff = Mff;
  r->Kff = Kff;
  // arrays with the mode index slowest keep their prefix: S1, XS, shapes, stress, interfaces
  r->nm = n;
  return 0;
}

// --- a modal body from a cb file ------------------------------------------------------------
// The flexible modes of the reduced eigenproblem (those /reduced/rigid does not flag), turned
// into a body by the one producer, fmbd_rflex_build, exactly as cbcheck does for a selection.
// With desc_out, the body's description is handed to the caller (to form the stress later at
// the nodes it needs, fmbd_rflex_form_stress).
// With no_ss, the body is for partial inertia coupling only (fmbd_rflex_input no_ss).
// With keep > 0, only the first keep flexible modes are built (those a scene's `modes` keeps:
// the others' shapes, nodal motion and invariants are never read); keep <= 0 or more than the
// file has: all of them.
static int rflex_from_cb(fmbd_h5 *f, bool stress, bool no_ss, int64_t keep, fmbd_rflex **out,
                         fmbd_fe_body **desc_out) {
  int rc = FMBD_OK;
  fmbd_cb *cb = NULL;
  fmbd_fe_body *desc = NULL;
  double *Xi = NULL, *chibar = NULL;
  *out = NULL;
  FMBD_GCALL(fmbd_cb_read_basis(f, &cb));
  FMBD_GCALL(fmbd_fe_read(f, &desc));
  int64_t nr = cb->nr, nm = nr - cb->n_rigid;
  if (keep > 0 && keep < nm) nm = keep;
  FMBD_GALLOC(Xi = fmbd_malloc(sizeof(double) * (size_t)(nr * nm + 1)));
  FMBD_GALLOC(chibar = fmbd_malloc(sizeof(double) * (size_t)(nm + 1)));
  for (int64_t k = 0, j = 0; k < nr && j < nm; k++) {
    if (cb->rigid[k]) continue;
    chibar[j] = cb->chibar[k];
    memcpy(Xi + nr * j, cb->Xi + nr * k, sizeof(double) * (size_t)nr);
    j++;
  }
  fmbd_rflex_input mi = {desc,    cb->ns, cb->nb,  cb->interior, cb->boundary, cb->nd,
                         cb->Phi, cb->ns, cb->Psi, nm,           chibar,       Xi,
                         nr,      stress, no_ss,   cb->Phi};
  cb->Phi = NULL;  // handed over: freed once the shapes are formed (the load's peak)
  FMBD_GCALL(fmbd_rflex_build(&mi, out));
  if (desc_out) {
    *desc_out = desc;
    desc = NULL;
  }
done:
  fmbd_free(Xi);
  fmbd_free(chibar);
  fmbd_fe_body_destroy(&desc);
  fmbd_cb_destroy(&cb);
  return rc;
}

int fmbd_scene_rflex_from_cb(fmbd_h5 *f, bool stress, fmbd_rflex **out) {
  return rflex_from_cb(f, stress, false, 0, out, NULL);
}

// --- points --------------------------------------------------------------------------------
static void to_world(const fmbd_scene_body *b, const double x0[3], double xw[3]) {
  for (int i = 0; i < 3; i++) {
    xw[i] = b->position[i];
    for (int j = 0; j < 3; j++) xw[i] += b->rotation[3 * i + j] * x0[j];
  }
}
static void to_body(const fmbd_scene_body *b, const double xw[3], double x0[3]) {
  for (int j = 0; j < 3; j++) {
    x0[j] = 0;
    for (int i = 0; i < 3; i++) x0[j] += b->rotation[3 * i + j] * (xw[i] - b->position[i]);
  }
}

static double body_size(const fmbd_rflex *r) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int64_t p = 0; p < r->nnodes; p++) {
    for (int a = 0; a < 3; a++) {
      lo[a] = fmin(lo[a], r->node_xyz[a + 3 * p]);
      hi[a] = fmax(hi[a], r->node_xyz[a + 3 * p]);
    }
  }
  double d = 0;
  for (int a = 0; a < 3; a++) d += (hi[a] - lo[a]) * (hi[a] - lo[a]);
  return sqrt(d);
}

// The node of a flexible body an attachment names; x0b: a body-frame point for DEFAULT/POINT.
// what names the item for messages.
static int flex_node(const fmbd_scene *s, int bi, const fmbd_rflex *r, const fmbd_scene_at *at,
                     const double x0b[3], fmbd_scene_loc loc, const char *what, int64_t *node) {
  int rc = 0;
  const fmbd_scene_body *b = &s->bodies[bi];
  switch (at->kind) {
    case FMBD_AT_INTERFACE: {
      int i = fmbd_rflex_find_interface(r, at->interface);
      if (i < 0) {
        char list[512] = "";
        for (int k = 0; k < r->ninterfaces && strlen(list) < 400; k++) {
          strcat(list, k ? ", " : "");
          strcat(list, r->interfaces[k].name);
        }
        SFAIL(s, at->loc, FMBD_ERR_SCENE, "%s: body '%s' (%s) has no interface '%s' (it has: %s)",
              what, b->name, b->file, at->interface, r->ninterfaces ? list : "none");
      }
      *node = r->interfaces[i].node;
      break;
    }
    case FMBD_AT_NODE:
      if (at->node >= r->nnodes) {
        SFAIL(s, at->loc, FMBD_ERR_SCENE, "%s: body '%s' has nodes 0..%lld, not %lld", what,
              b->name, (long long)r->nnodes - 1, (long long)at->node);
      }
      *node = at->node;
      break;
    case FMBD_AT_NEAREST:
      *node = fmbd_rflex_nearest_node(r, at->p, NULL);
      break;
    default: {  // a point that must be a node
      double dist = 0;
      int64_t p = fmbd_rflex_nearest_node(r, x0b, &dist);
      double tol = 1e-6 * body_size(r);
      if (p < 0 || dist > tol) {
        const char *itf = NULL;
        for (int k = 0; k < r->ninterfaces; k++) {
          if (r->interfaces[k].node == p) itf = r->interfaces[k].name;
        }
        SFAIL(s, loc, FMBD_ERR_SCENE,
              "%s: the point (%g, %g, %g) (body frame) is not on body '%s': the nearest node "
              "%lld%s%s%s is %.3g m "
              "away; name an interface, a node or 'nearest'",
              what, x0b[0], x0b[1], x0b[2], b->name, (long long)p, itf ? " (interface '" : "",
              itf ? itf : "", itf ? "')" : "", dist);
      }
      *node = p;
    }
  }
done:
  return rc;
}

// Add the mbs point of an attachment on scene body bi (or ground, bi < 0). xw: the world
// point to use for DEFAULT (may be NULL for loads/outputs: the body origin).
static int add_point(fmbd_scene_model *m, const fmbd_scene *s, int bi, const fmbd_scene_at *at,
                     const double *xw, fmbd_scene_loc loc, const char *what, int *pid,
                     int64_t *node_out) {
  int rc = 0;
  double *T = NULL, *R = NULL;
  if (node_out) *node_out = -1;
  if (bi < 0) {
    const double *p = at->kind == FMBD_AT_POINT ? at->p : xw;
    FMBD_GCALL(fmbd_mbs_add_point(m->mbs, FMBD_MBS_GROUND, p, NULL, NULL, pid));
    goto done;
  }
  const fmbd_scene_body *b = &s->bodies[bi];
  double x0[3] = {0, 0, 0};
  if (at->kind == FMBD_AT_POINT) {
    memcpy(x0, at->p, sizeof x0);
  } else if (at->kind == FMBD_AT_DEFAULT && xw) {
    to_body(b, xw, x0);
  }
  if (b->kind == FMBD_SCENE_RIGID || (at->kind == FMBD_AT_DEFAULT && !xw)) {
    FMBD_GCALL(fmbd_mbs_add_point(m->mbs, m->body_id[bi], x0, NULL, NULL, pid));
    goto done;
  }
  const fmbd_rflex *r = m->flex[bi];
  int64_t node;
  FMBD_GCALL(flex_node(s, bi, r, at, x0, loc, what, &node));
  if (m->fe[bi]) {
    int64_t n = fmbd_mbs_body_nm(m->mbs, m->body_id[bi]);
    FMBD_GALLOC(T = fmbd_malloc(sizeof(double) * (size_t)(3 * n + 1)));
    FMBD_GALLOC(R = fmbd_malloc(sizeof(double) * (size_t)(3 * n + 1)));
    fe_node_modes(m, bi, node, n, T, R);
    memcpy(x0, r->node_xyz + 3 * node, sizeof x0);
    FMBD_GCALL(fmbd_mbs_add_point(m->mbs, m->body_id[bi], x0, T, R, pid));
    if (node_out) *node_out = node;
    goto done;
  }
  int64_t nm = r->nm;
  FMBD_GALLOC(T = fmbd_malloc(sizeof(double) * (size_t)(3 * nm + 1)));
  FMBD_GALLOC(R = fmbd_malloc(sizeof(double) * (size_t)(3 * nm + 1)));
  rc = fmbd_rflex_node_modes(r, node, x0, T, R);
  if (rc) SFAIL(s, loc, rc, "%s: body '%s' (%s): %s", what, b->name, b->file, fmbd_err_get()->msg);
  FMBD_GCALL(fmbd_mbs_add_point(m->mbs, m->body_id[bi], x0, T, R, pid));
  if (node_out) *node_out = node;
done:
  fmbd_free(T);
  fmbd_free(R);
  return rc;
}

static int add_input(fmbd_scene_model *m, const char *name, const char *sha) {
  char **nn = fmbd_realloc(m->input_name, sizeof(char *) * (size_t)(m->ninputs + 1));
  if (!nn) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  m->input_name = nn;
  char(*ns)[65] = fmbd_realloc(m->input_sha, sizeof(*ns) * (size_t)(m->ninputs + 1));
  if (!ns) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  m->input_sha = ns;
  m->input_name[m->ninputs] = fmbd_strdup(name);
  if (!m->input_name[m->ninputs]) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  snprintf(m->input_sha[m->ninputs], 65, "%s", sha ? sha : "");
  m->ninputs++;
  return 0;
}

// --- a global-mode (GMc or GMs) basis instead of the file's modes ----------------------------
// The body's GMc basis from a gmsolve file (/gmc/<body>: shapes on the FE dofs, Mff, Kff),
// turned into the body by fmbd_rflex_from_basis with the description of the body's own file
// (f: a .rflex.h5, .cb.h5 or .fe.h5), which must be the file the basis was made from (its
// SHA-256). A full FE body so becomes a modal body with the GMc shapes as its modes.
// basis_kind gms: the body's rows of the first `modes` global modes (/gms/<body>), whose
// coordinates the bodies naming the same file share (fmbd_mbs_share_modal, in
// fmbd_scene_build); the body's own S'MS may then be singular.
// With desc_out, no stress is formed and the description is handed to the caller (to form it at
// the nodes the scene reads, stress_at_outputs).
static int load_gmc(fmbd_scene_model *m, const fmbd_scene *s, int bi, fmbd_h5 *f,
                    fmbd_fe_body **desc_out) {
  int rc = 0;
  const fmbd_scene_body *b = &s->bodies[bi];
  const char *name = b->basis_body ? b->basis_body : b->name;
  const char *kind = b->basis_gms ? "gms" : "gmc", *KIND = b->basis_gms ? "GMs" : "GMc";
  fmbd_h5 *g = NULL;
  fmbd_fe_body *desc = NULL;
  fmbd_rflex *r = NULL;
  double *S = NULL, *Mff = NULL, *Kff = NULL;
  char *sha = NULL, path[600];
  fmbd_err_clear();
  rc = fmbd_h5_open(b->basis, &g);
  if (!rc) rc = fmbd_h5_check_format(g, FMBD_GM_FORMAT, FMBD_GM_FORMAT_MAJOR);
  if (rc) {
    char msg[1100];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    SFAIL(s, b->basis_loc, rc, "body '%s': basis %s: %s", b->name, b->basis, msg);
  }
  snprintf(path, sizeof path, "/%s/%s", kind, name);
  if (!fmbd_h5_exists(g, path)) {
    SFAIL(s, b->basis_loc, FMBD_ERR_SCENE,
          "body '%s': %s has no %s basis of a body '%s' (name it with basis_body)", b->name,
          b->basis, KIND, name);
  }
  snprintf(path, sizeof path, "/%s/%s/Mff", kind, name);
  if (!fmbd_h5_exists(g, path)) {
    SFAIL(s, b->basis_loc, FMBD_ERR_SCENE,
          "body '%s': %s has no %s (made by an older gmsolve: run it again)", b->name, b->basis,
          path);
  }
  snprintf(path, sizeof path, "/%s/%s", kind, name);
  if (fmbd_h5_has_attr(g, path, "file_sha256")) {
    FMBD_GCALL(fmbd_h5_read_attr_str(g, path, "file_sha256", &sha));
    if (sha[0] && strcmp(sha, fmbd_h5_sha256(f))) {
      SFAIL(s, b->basis_loc, FMBD_ERR_SCENE,
            "body '%s': the basis in %s was made from another version of %s (SHA-256 differs): "
            "run gmsolve again",
            b->name, b->basis, b->file);
    }
  }
  int64_t ndof = -1, nc = -1, r1 = -1, c1 = -1, r2 = -1, c2 = -1;
  snprintf(path, sizeof path, "/%s/%s/shapes", kind, name);
  rc = fmbd_h5_read_f64_cm(g, path, &ndof, &nc, &S);
  if (!rc) {
    snprintf(path, sizeof path, "/%s/%s/Mff", kind, name);
    rc = fmbd_h5_read_f64_cm(g, path, &r1, &c1, &Mff);
  }
  if (!rc) {
    snprintf(path, sizeof path, "/%s/%s/Kff", kind, name);
    rc = fmbd_h5_read_f64_cm(g, path, &r2, &c2, &Kff);
  }
  if (rc) {
    char msg[1100];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    SFAIL(s, b->basis_loc, rc, "body '%s': %s:%s: %s", b->name, b->basis, path, msg);
  }
  FMBD_GCALL(fmbd_fe_read(f, &desc));
  if (nc == 0 || r1 != nc || c1 != nc || r2 != nc || c2 != nc || ndof != desc->ndof) {
    SFAIL(s, b->basis_loc, FMBD_ERR_SCENE,
          "body '%s': the %s basis of '%s' in %s has %lld columns on %lld dofs (Mff %lld x %lld, "
          "Kff %lld x %lld); the body has %lld dofs%s",
          b->name, KIND, name, b->basis, (long long)nc, (long long)ndof, (long long)r1,
          (long long)c1, (long long)r2, (long long)c2, (long long)desc->ndof,
          nc == 0 ? " (an empty basis: the body does not deform in the global modes)" : "");
  }
  if (b->basis_gms && b->modes > nc) {
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE, "body '%s' asks for %lld global modes; %s has %lld",
          b->name, (long long)b->modes, b->basis, (long long)nc);
  }
  if (b->basis_gms && b->modes > 0) {  // GMs: column k is global mode k + 1
    for (int64_t j = 0; j < b->modes; j++) {
      for (int64_t i = 0; i < b->modes; i++) {
        Mff[i + b->modes * j] = Mff[i + nc * j];
        Kff[i + b->modes * j] = Kff[i + nc * j];
      }
    }
    nc = b->modes;
  } else if (b->modes > 0) {  // the columns of the first `modes` global modes: a prefix
    int64_t ng = -1, *gmode = NULL, keep = 0;
    snprintf(path, sizeof path, "/gmc/%s/global_mode", name);
    rc = fmbd_h5_read_i64(g, path, 1, &ng, &gmode);
    if (rc) {
      char msg[1100];
      snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
      SFAIL(s, b->basis_loc, rc, "body '%s': %s:%s: %s", b->name, b->basis, path, msg);
    }
    while (keep < ng && keep < nc && gmode[keep] <= b->modes) keep++;
    int64_t last = ng > 0 ? gmode[ng - 1] : 0;
    fmbd_free(gmode);
    if (keep == 0) {
      SFAIL(s, b->file_loc, FMBD_ERR_SCENE,
            "body '%s': none of the %lld GMc columns of '%s' in %s comes from the first %lld "
            "global modes",
            b->name, (long long)nc, name, b->basis, (long long)b->modes);
    }
    if (b->modes > last && last > 0) {
      fmbd_log(FMBD_LOG_INFO,
               "body '%s': modes %lld, but %s has the GMc columns of %lld global modes", b->name,
               (long long)b->modes, b->basis, (long long)last);
    }
    for (int64_t j = 0; j < keep; j++) {  // leading keep x keep blocks, in place
      for (int64_t i = 0; i < keep; i++) {
        Mff[i + keep * j] = Mff[i + nc * j];
        Kff[i + keep * j] = Kff[i + nc * j];
      }
    }
    nc = keep;
  }
  // a full FE body's file has its M and K: the projections are made here; a modal body's
  // description has none: the file's Mff, Kff (gmsolve's projections with the modal matrices)
  fmbd_rflex_basis in = {desc, desc->M, desc->K, nc, S, ndof, Mff, Kff, false, b->basis_gms};
  rc = fmbd_rflex_from_basis(&in, &r);
  if (rc) SFAIL(s, b->basis_loc, rc, "body '%s': %s: %s", b->name, b->basis, fmbd_err_get()->msg);
  fmbd_rflex_destroy(&m->flex[bi]);
  m->flex[bi] = r;
  r = NULL;
  FMBD_GCALL(add_input(m, b->basis, fmbd_h5_sha256(g)));
  if (desc_out) {
    *desc_out = desc;
    desc = NULL;
  }
done:
  fmbd_h5_close(&g);
  fmbd_fe_body_destroy(&desc);
  fmbd_rflex_destroy(&r);
  fmbd_free(S);
  fmbd_free(Mff);
  fmbd_free(Kff);
  fmbd_free(sha);
  return rc;
}

// --- full FE bodies (docs/THEORY.md section 4b) ---------------------------------------------
// Stiffness-proportional damping D = (2 zeta / omega_1) K: ratio zeta at the body's first
// frequency omega_1 held at its frame node (the lowest eigenvalue of K, M), zeta omega/omega_1
// above (Rayleigh's beta K; the modal damping of a modal body has zeta on every mode).
static int fe_damping(const fmbd_csr *K, const fmbd_csr *M, double zeta, fmbd_csr **D,
                      double *omega1) {
  fmbd_eig_opts o;
  fmbd_eig_opts_defaults(&o);
  o.nev = 1;
  o.sturm = false;
  fmbd_eig_result er;
  memset(&er, 0, sizeof er);
  int rc = fmbd_eig_solve(K, M, NULL, &o, &er);
  if (rc) {
    fmbd_eig_result_free(&er);
    return rc;
  }
  *omega1 = sqrt(er.lambda[0]);
  fmbd_eig_result_free(&er);
  FMBD_CALL(fmbd_csr_duplicate(K, D));
  double f = 2 * zeta / *omega1;
  for (int64_t e = 0; e < K->indptr[K->nrows]; e++) (*D)->data[e] *= f;
  return FMBD_OK;
}

// A .fe.h5 body: every active FE dof but the frame node's a coordinate. The frame is attached
// to the first rbe2 interface node (by name): its 6 dofs are the frame's motion.
static int load_fe(fmbd_scene_model *m, const fmbd_scene *s, int bi, fmbd_h5 *f) {
  int rc = 0;
  const fmbd_scene_body *b = &s->bodies[bi];
  fmbd_fe_body *fe = NULL;
  fmbd_csr *Mf = NULL, *Kf = NULL, *D = NULL, *E = NULL, *Mn = NULL;
  int64_t *kept = NULL, *rows = NULL, *kdofs = NULL;
  double *C = NULL, *S1c = NULL, *Mw0 = NULL;
  fmbd_rflex *r = NULL;
  if (b->modes > 0) {
    SFAIL(s, b->loc, FMBD_ERR_SCENE,
          "body '%s': 'modes' makes no sense for a full-model body (%s keeps every FE dof); "
          "drop it, or use the .cb.h5 or .rflex.h5 of this body",
          b->name, b->file);
  }
  if (b->inertia_partial) {
    SFAIL(s, b->inertia_loc, FMBD_ERR_SCENE,
          "body '%s': 'inertia_coupling: partial' is for modal bodies; a full-model body (%s) "
          "keeps its full inertia",
          b->name, b->file);
  }
  FMBD_GCALL(fmbd_fe_read(f, &fe));
  if (!fe->K || !fe->M || !fe->expand) {
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE, "body '%s': %s has no /K, /M or /expand", b->name,
          b->file);
  }
  int frame = -1;
  for (int i = 0; i < fe->ninterfaces && frame < 0; i++) {
    int64_t nd = fe->interfaces[i].node;
    if (fe->interfaces[i].kind == FMBD_FE_RBE3) continue;
    int cnt = 0;
    for (int d = 0; d < 6; d++) cnt += fmbd_fe_dof(fe, nd, d) >= 0;
    if (cnt == 6) frame = i;
  }
  if (frame < 0) {
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE,
          "body '%s': %s: full-model bodies need an rbe2 interface node with its 6 dofs (mesh2fe "
          "--interface GROUP): the floating frame is attached to it (docs/THEORY.md section 4b)",
          b->name, b->file);
  }
  const int64_t nfr = fe->interfaces[frame].node, ndof = fe->ndof, nn = fe->nnodes;
  const int64_t n = ndof - 6;
  if (n < 1)
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE, "body '%s': %s has no dof besides its frame node",
          b->name, b->file);
  FMBD_GALLOC(kept = fmbd_malloc(sizeof(int64_t) * (size_t)n));
  FMBD_GALLOC(kdofs = fmbd_malloc(sizeof(int64_t) * (size_t)(2 * n)));
  FMBD_GALLOC(m->fe_col[bi] = fmbd_malloc(sizeof(int64_t) * (size_t)ndof));
  for (int64_t i = 0, k = 0; i < ndof; i++) {
    if (fe->dofs[2 * i] == nfr) {
      m->fe_col[bi][i] = -1;
      continue;
    }
    m->fe_col[bi][i] = k;
    kdofs[2 * k] = fe->dofs[2 * i], kdofs[2 * k + 1] = fe->dofs[2 * i + 1];
    kept[k++] = i;
  }
  FMBD_GCALL(fmbd_csr_submatrix(fe->M, n, kept, n, kept, &Mf));
  FMBD_GCALL(fmbd_csr_submatrix(fe->K, n, kept, n, kept, &Kf));
  FMBD_GALLOC(rows = fmbd_malloc(sizeof(int64_t) * (size_t)(3 * nn)));
  for (int a = 0; a < 3; a++) {
    for (int64_t p = 0; p < nn; p++) rows[p + nn * a] = 6 * p + a;
  }
  FMBD_GCALL(fmbd_csr_submatrix(fe->expand, 3 * nn, rows, n, kept, &E));
  FMBD_GCALL(fmbd_rflex_nodal_mass(fe, &Mn));
  if (fe->nbeam > 0 && fe->mass_kind == FMBD_FE_MASS_LUMPED) {
    // not one mass: the frame's coupling and the FE mass differ at first order, and the mass
    // matrix turns indefinite within milliseconds (a falling link: 1.1 ms; THEORY 4b)
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE,
          "body '%s': %s has beam elements with lumped mass, which a full FE body cannot use "
          "(its rigid-flexible coupling would not come from the mass its M holds, and the mass "
          "matrix turns indefinite: docs/THEORY.md section 4b); mesh it with --mass consistent",
          b->name, b->file);
  }
  if (fmbd_rflex_beam_coupling(fe)) {  // S1, M_wf(0) from the consistent M (THEORY 4b)
    FMBD_GALLOC(C = fmbd_malloc(sizeof(double) * (size_t)(6 * ndof + 6 * n)));
    FMBD_GCALL(fmbd_rflex_rigid_coupling(fe, C));
    S1c = C + 6 * ndof, Mw0 = S1c + 3 * n;
    for (int64_t k = 0; k < n; k++) {
      for (int a = 0; a < 3; a++) {
        S1c[a + 3 * k] = C[kept[k] + ndof * a];
        Mw0[a + 3 * k] = C[kept[k] + ndof * (3 + a)];
      }
    }
  }
  if (b->damping_ratio > 0) {
    double w1 = 0;
    FMBD_GCALL(fe_damping(Kf, Mf, b->damping_ratio, &D, &w1));
    fmbd_log(FMBD_LOG_INFO,
             "body '%s': stiffness-proportional damping %g K (ratio %g at its first frequency "
             "%.6g Hz held at the frame node)",
             b->name, 2 * b->damping_ratio / w1, b->damping_ratio, w1 / (2 * M_PI));
  }
  fmbd_mbs_fe_data d = {.n = n,
                        .mass = fe->mass,
                        .M = Mf,
                        .K = Kf,
                        .D = D,
                        .nnodes = nn,
                        .node_xyz = fe->xyz,
                        .Mn = Mn,
                        .E = E,
                        .dofs = kdofs,
                        .S1 = S1c,
                        .Mw0 = Mw0};
  for (int a = 0; a < 3; a++) d.first_moment[a] = fe->mass * fe->center_of_mass[a];
  {  // J = tr(Ic)/2 I - Ic + m c c' (as the reduced bodies)
    const double *Ic = fe->inertia, *c = fe->center_of_mass;
    double tr = Ic[0] + Ic[4] + Ic[8];
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        d.second_moment[a + 3 * bb] = (a == bb ? 0.5 * tr : 0.0) -
                                      0.5 * (Ic[3 * a + bb] + Ic[3 * bb + a]) +
                                      fe->mass * c[a] * c[bb];
      }
    }
  }
  fmbd_mbs_state0 s0 = body_state0(b);
  rc = fmbd_mbs_add_fe(m->mbs, b->name, &d, &s0, &m->body_id[bi]);
  if (rc) SFAIL(s, b->loc, rc, "body '%s' (%s): %s", b->name, b->file, fmbd_err_get()->msg);
  fmbd_log(FMBD_LOG_INFO,
           "body '%s': full FE model, %lld dofs in the floating frame attached to interface '%s'",
           b->name, (long long)n, fe->interfaces[frame].name);
  // nodes and interfaces for placing points (no modes)
  FMBD_GALLOC(r = fmbd_calloc(1, sizeof *r));
  r->nnodes = nn;
  r->ndof = ndof;
  FMBD_GALLOC(r->node_xyz = fmbd_malloc(sizeof(double) * (size_t)(3 * nn)));
  memcpy(r->node_xyz, fe->xyz, sizeof(double) * (size_t)(3 * nn));
  r->ninterfaces = fe->ninterfaces;
  FMBD_GALLOC(r->interfaces =
                  fmbd_calloc((size_t)fe->ninterfaces + 1, sizeof(fmbd_rflex_interface)));
  for (int i = 0; i < fe->ninterfaces; i++) {
    fmbd_rflex_interface *it = &r->interfaces[i];
    FMBD_GALLOC(it->name = fmbd_strdup(fe->interfaces[i].name));
    FMBD_GALLOC(it->kind = fmbd_strdup(fe->interfaces[i].kind == FMBD_FE_RBE3 ? "rbe3" : "rbe2"));
    it->node = fe->interfaces[i].node;
    memcpy(it->x0, fe->xyz + 3 * it->node, sizeof it->x0);
  }
  m->flex[bi] = r;
  r = NULL;
  m->fe[bi] = fe;
  fe = NULL;
done:
  fmbd_rflex_destroy(&r);
  fmbd_fe_body_destroy(&fe);
  fmbd_csr_destroy(&Mf), fmbd_csr_destroy(&Kf), fmbd_csr_destroy(&D), fmbd_csr_destroy(&E),
      fmbd_csr_destroy(&Mn);
  fmbd_free(kept), fmbd_free(rows), fmbd_free(kdofs), fmbd_free(C);
  return rc;
}

// A node's translation and rotation on a full FE body: rows 6p.. of /expand on the coordinates
// (T, R: 3 x n dense, zeroed here)
static void fe_node_modes(const fmbd_scene_model *m, int bi, int64_t node, int64_t n, double *T,
                          double *R) {
  const fmbd_fe_body *fe = m->fe[bi];
  const fmbd_csr *X = fe->expand;
  memset(T, 0, sizeof(double) * (size_t)(3 * n));
  memset(R, 0, sizeof(double) * (size_t)(3 * n));
  for (int d = 0; d < 6; d++) {
    int64_t row = 6 * node + d;
    for (int64_t e = X->indptr[row]; e < X->indptr[row + 1]; e++) {
      int64_t k = m->fe_col[bi][X->indices[e]];
      if (k < 0) continue;
      (d < 3 ? T : R)[d % 3 + 3 * k] = X->data[e];
    }
  }
}

// --- flexible bodies ---------------------------------------------------------------------
// The modal stress of a body built here (from a cb file or a GMc basis), formed only at the
// nodes the scene's stress and strain outputs read (fmbd_rflex_form_stress: bitwise the whole
// field's rows there), resolved as the outputs resolve them (flex_node). An output whose place
// does not resolve is left to the outputs' loop, which says why.
static int stress_at_outputs(const fmbd_scene *s, int bi, fmbd_rflex *r, const fmbd_fe_body *desc) {
  int rc = 0;
  int64_t *nodes = NULL, n = 0;
  FMBD_GALLOC(nodes = fmbd_malloc(sizeof(int64_t) * (size_t)(s->noutputs + 1)));
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    if (op->body != bi ||
        !(op->quantities & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN)) ||
        op->at.kind == FMBD_AT_DEFAULT)  // the body's origin: no node (refused later)
      continue;
    double x0[3] = {0, 0, 0};
    if (op->at.kind == FMBD_AT_POINT) memcpy(x0, op->at.p, sizeof x0);
    int64_t node = -1;
    if (flex_node(s, bi, r, &op->at, x0, op->loc, "output", &node) == 0 && node >= 0) {
      nodes[n++] = node;
    } else {
      fmbd_err_clear();
    }
  }
  FMBD_GCALL(fmbd_rflex_form_stress(r, desc, n, nodes));
done:
  fmbd_free(nodes);
  return rc;
}

static int load_flex(fmbd_scene_model *m, const fmbd_scene *s, int bi, bool need_stress) {
  int rc = 0;
  const fmbd_scene_body *b = &s->bodies[bi];
  fmbd_h5 *f = NULL;
  fmbd_fe_body *desc = NULL;  // a body built here: its description, for its stress
  char *format = NULL;
  fmbd_err_clear();
  rc = fmbd_h5_open(b->file, &f);
  if (rc) {
    char msg[1100];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    SFAIL(s, b->file_loc, rc, "body '%s': %s: %s", b->name, b->file, msg);
  }
  if (fmbd_h5_has_attr(f, "/", "format"))
    FMBD_GCALL(fmbd_h5_read_attr_str(f, "/", "format", &format));
  if (format && !strcmp(format, FMBD_RFLEX_FORMAT)) {
    rc = fmbd_rflex_read(f, &m->flex[bi]);
  } else if (format && !strcmp(format, FMBD_CB_FORMAT)) {
    rc = fmbd_h5_check_format(f, FMBD_CB_FORMAT, FMBD_CB_FORMAT_MAJOR);
    if (!rc) {
      // partial inertia coupling takes SS as zero (fmbd_mbs_add_flex): not formed
      // and only the modes the scene keeps are built (the others are never read)
      rc = rflex_from_cb(f, false, b->inertia_partial && !b->basis,
                         !b->basis && b->modes > 0 ? b->modes : 0, &m->flex[bi],
                         need_stress && !b->basis ? &desc : NULL);
    }
  } else if (format && !strcmp(format, FMBD_FE_FORMAT)) {
    rc = fmbd_h5_check_format(f, FMBD_FE_FORMAT, FMBD_FE_FORMAT_MAJOR);
    // with a GMc basis the body is the modal body of that basis (load_gmc, below)
    if (!rc && !b->basis) {
      FMBD_GALLOC(m->file_kind[bi] = fmbd_strdup(format));
      FMBD_GCALL(load_fe(m, s, bi, f));
      FMBD_GCALL(add_input(m, b->file, fmbd_h5_sha256(f)));
      m->E[bi] = m->fe[bi]->E, m->nu[bi] = m->fe[bi]->nu;
      goto done;
    }
  } else {
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE,
          "body '%s': %s is %s%s%s; a flexible body needs a fmbd-rflex file (cbcheck), a fmbd-cb "
          "file (fe2cb) or a fmbd-fe file (mesh2fe: the full model)",
          b->name, b->file, format ? "a " : "not a toolchain file", format ? format : "",
          format ? " file" : "");
  }
  if (rc) {
    // keep the HDF5 path of the failure, prefix the scene item
    char msg[1100], where[600];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    snprintf(where, sizeof where, "%s", fmbd_err_get()->where);
    SFAIL(s, b->file_loc, rc, "body '%s': %s%s%s: %s", b->name, b->file, where[0] ? ":" : "", where,
          msg);
  }
  FMBD_GALLOC(m->file_kind[bi] = fmbd_strdup(format));
  if (!strcmp(format, FMBD_RFLEX_FORMAT)) {
    // a body used in a way its file was not made for: the modes of an interface reduced free
    // cannot deform as a joint that holds it asks (docs/THEORY.md section 12), and modes made
    // for a held interface are too stiff where it is free
    char want[1024], *made = NULL;
    fmbd_scene_held_interfaces(s, NULL, bi, want, sizeof want);
    if (fmbd_h5_has_attr(f, "/modes", "held_interfaces")) {
      FMBD_GCALL(fmbd_h5_read_attr_str(f, "/modes", "held_interfaces", &made));
    }
    for (const char *p = want; *p;) {
      const char *e = strchr(p, ',');
      size_t l = e ? (size_t)(e - p) : strlen(p);
      char name[256];
      snprintf(name, sizeof name, "%.*s", (int)l, p);
      if (!fmbd_scene_list_has(made ? made : "", name)) {
        fmbd_log(FMBD_LOG_WARN,
                 "%s:%d: body '%s': a joint holds interface '%s', but %s was "
                 "reduced with it free: its modes cannot bend there as the joint asks (reduce "
                 "it with cbcheck --hold %s; fmbd-run -M makes that rule)",
                 s->file, b->file_loc.line, b->name, name, b->file, name);
      }
      p = e ? e + 1 : p + l;
    }
    for (const char *p = made ? made : ""; *p;) {
      const char *e = strchr(p, ',');
      size_t l = e ? (size_t)(e - p) : strlen(p);
      char name[256];
      snprintf(name, sizeof name, "%.*s", (int)l, p);
      if (!fmbd_scene_list_has(want, name)) {
        fmbd_log(FMBD_LOG_WARN,
                 "%s:%d: body '%s': %s was reduced with interface '%s' held, but "
                 "no joint of this scene holds it there: the body is too stiff at it",
                 s->file, b->file_loc.line, b->name, b->file, name);
      }
      p = e ? e + 1 : p + l;
    }
    fmbd_free(made);
  }
  if (b->basis) FMBD_GCALL(load_gmc(m, s, bi, f, need_stress ? &desc : NULL));
  fmbd_rflex *r = m->flex[bi];
  if (desc) {  // with every mode of the file, as the whole field was formed before truncation
    rc = stress_at_outputs(s, bi, r, desc);
    if (rc) SFAIL(s, b->file_loc, rc, "body '%s' (%s): %s", b->name, b->file, fmbd_err_get()->msg);
  }
  if (!b->basis && b->modes > r->nm) {
    SFAIL(s, b->file_loc, FMBD_ERR_SCENE, "body '%s' asks for %lld modes; %s has %lld", b->name,
          (long long)b->modes, b->basis ? b->basis : b->file, (long long)r->nm);
  }
  if (!b->basis && b->modes > 0) FMBD_GCALL(truncate_modes(r, b->modes));
  if (!need_stress && r->stress) {  // nothing asks for stress: do not keep it
    fmbd_free(r->stress);
    r->stress = NULL;
  }
  m->E[bi] = NAN;
  m->nu[bi] = NAN;
  if (fmbd_h5_has_attr(f, "/material", "E")) {
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "E", 1, &m->E[bi]));
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "nu", 1, &m->nu[bi]));
  }
  FMBD_GCALL(add_input(m, b->file, fmbd_h5_sha256(f)));
  fmbd_mbs_flex_data d = {.nm = r->nm,
                          .mass = r->mass,
                          .S1 = r->S1,
                          .XS = r->XS,
                          .SS = r->SS,
                          .Mff = r->Mff,
                          .Kff = r->Kff,
                          .damping_ratio = b->damping_ratio,
                          .shared = b->basis_gms,
                          .partial_coupling = b->inertia_partial};
  memcpy(d.first_moment, r->first_moment, sizeof d.first_moment);
  memcpy(d.second_moment, r->second_moment, sizeof d.second_moment);
  fmbd_mbs_state0 s0 = body_state0(b);
  rc = fmbd_mbs_add_flex(m->mbs, b->name, &d, &s0, &m->body_id[bi]);
  if (rc) SFAIL(s, b->loc, rc, "body '%s' (%s): %s", b->name, b->file, fmbd_err_get()->msg);
  if (b->inertia_partial) {
    fmbd_log(FMBD_LOG_INFO,
             "body '%s': partial inertia coupling (the invariants of second order in the modes, "
             "SS and SSx, taken as zero; docs/THEORY.md section 4c)",
             b->name);
  }
done:
  fmbd_free(format);
  fmbd_fe_body_destroy(&desc);
  fmbd_h5_close(&f);
  return rc;
}

int fmbd_scene_build(const fmbd_scene *s, fmbd_scene_model **out) {
  int rc = 0;
  fmbd_scene_model *m = NULL;
  *out = NULL;
  FMBD_GALLOC(m = fmbd_calloc(1, sizeof *m));
  FMBD_GCALL(fmbd_mbs_create(&m->mbs));
  int nb = s->nbodies;
  m->nbodies = nb;
  FMBD_GALLOC(m->body_id = fmbd_calloc((size_t)nb + 1, sizeof(int)));
  FMBD_GALLOC(m->flex = fmbd_calloc((size_t)nb + 1, sizeof(fmbd_rflex *)));
  FMBD_GALLOC(m->file_kind = fmbd_calloc((size_t)nb + 1, sizeof(char *)));
  FMBD_GALLOC(m->fe = fmbd_calloc((size_t)nb + 1, sizeof(fmbd_fe_body *)));
  FMBD_GALLOC(m->fe_col = fmbd_calloc((size_t)nb + 1, sizeof(int64_t *)));
  FMBD_GALLOC(m->E = fmbd_calloc((size_t)nb + 1, sizeof(double)));
  FMBD_GALLOC(m->nu = fmbd_calloc((size_t)nb + 1, sizeof(double)));
  FMBD_GALLOC(m->joint_id = fmbd_calloc((size_t)s->njoints + 1, sizeof(int)));
  m->noutputs = s->noutputs;
  FMBD_GALLOC(m->out_point = fmbd_calloc((size_t)s->noutputs + 1, sizeof(int)));
  FMBD_GALLOC(m->out_body = fmbd_calloc((size_t)s->noutputs + 1, sizeof(int)));
  FMBD_GALLOC(m->out_node = fmbd_calloc((size_t)s->noutputs + 1, sizeof(int64_t)));
  FMBD_GALLOC(m->out_sigma = fmbd_calloc((size_t)s->noutputs + 1, sizeof(double *)));
  // --- bodies ---
  for (int i = 0; i < nb; i++) {
    const fmbd_scene_body *b = &s->bodies[i];
    if (b->kind == FMBD_SCENE_RIGID) {
      fmbd_mbs_state0 s0 = body_state0(b);
      rc = fmbd_mbs_add_rigid(m->mbs, b->name, b->mass, b->com, b->inertia, &s0, &m->body_id[i]);
      if (rc) SFAIL(s, b->loc, rc, "body '%s': %s", b->name, fmbd_err_get()->msg);
    } else {
      bool need_stress = false;
      for (int o = 0; o < s->noutputs; o++) {
        need_stress |=
            s->outputs[o].body == i &&
            (s->outputs[o].quantities & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN));
      }
      FMBD_GCALL(load_flex(m, s, i, need_stress));
    }
  }
  // --- GMs: the bodies naming one basis file with basis_kind gms share its coordinates ---
  for (int i = 0; i < nb; i++) {
    const fmbd_scene_body *b = &s->bodies[i];
    if (b->kind != FMBD_SCENE_FLEXIBLE || !b->basis_gms) continue;
    bool first = true;
    for (int k = 0; k < i && first; k++)
      first = !(s->bodies[k].kind == FMBD_SCENE_FLEXIBLE && s->bodies[k].basis_gms &&
                !strcmp(s->bodies[k].basis, b->basis));
    if (!first) continue;
    int ids[FMBD_SCENE_GMS_MAX], cnt = 0;
    for (int k = i; k < nb; k++) {
      const fmbd_scene_body *o = &s->bodies[k];
      if (o->kind != FMBD_SCENE_FLEXIBLE || !o->basis_gms || strcmp(o->basis, b->basis)) continue;
      if (cnt == FMBD_SCENE_GMS_MAX) {
        SFAIL(s, o->basis_loc, FMBD_ERR_SCENE, "body '%s': more than %d bodies share %s", o->name,
              FMBD_SCENE_GMS_MAX, o->basis);
      }
      if (m->flex[k]->nm != m->flex[i]->nm) {
        SFAIL(s, o->basis_loc, FMBD_ERR_SCENE,
              "body '%s' takes %lld GMs coordinates of %s, body '%s' %lld: the bodies sharing "
              "them need one number (modes)",
              o->name, (long long)m->flex[k]->nm, o->basis, b->name, (long long)m->flex[i]->nm);
      }
      ids[cnt++] = m->body_id[k];
    }
    rc = fmbd_mbs_share_modal(m->mbs, cnt, ids);
    if (rc) SFAIL(s, b->basis_loc, rc, "body '%s': %s", b->name, fmbd_err_get()->msg);
  }
  // --- joints ---
  for (int k = 0; k < s->njoints; k++) {
    const fmbd_scene_joint *j = &s->joints[k];
    char what[200];
    snprintf(what, sizeof what, "joint '%s'", j->name);
    double P[3];
    if (j->has_point) {
      memcpy(P, j->point, sizeof P);
    } else {  // from the first attachment that names a place
      int side = j->at[0].kind != FMBD_AT_DEFAULT ? 0 : 1;
      int bi = j->body[side];
      const fmbd_scene_at *at = &j->at[side];
      if (bi < 0) {
        memcpy(P, at->p, sizeof P);
      } else if (s->bodies[bi].kind == FMBD_SCENE_RIGID) {
        to_world(&s->bodies[bi], at->p, P);
      } else {
        int64_t node;
        FMBD_GCALL(flex_node(s, bi, m->flex[bi], at, at->p, at->loc, what, &node));
        to_world(&s->bodies[bi], m->flex[bi]->node_xyz + 3 * node, P);
      }
    }
    int pid[2];
    for (int sd = 0; sd < 2; sd++) {
      fmbd_scene_loc loc = j->has_point ? j->point_loc : j->loc;
      FMBD_GCALL(add_point(m, s, j->body[sd], &j->at[sd], P, loc, what, &pid[sd], NULL));
    }
    fmbd_mbs_joint_desc d = {.name = j->name, .kind = j->kind, .point = {pid[0], pid[1]}};
    memcpy(d.axis, j->axis, sizeof d.axis);
    memcpy(d.axis2, j->axis2, sizeof d.axis2);
    rc = fmbd_mbs_add_joint(m->mbs, &d, &m->joint_id[k]);
    if (rc) SFAIL(s, j->loc, rc, "%s: %s", what, fmbd_err_get()->msg);
  }
  // --- drivers ---
  for (int k = 0; k < s->ndrivers; k++) {
    const fmbd_scene_driver *d = &s->drivers[k];
    fmbd_mbs_fn fn = d->fn;
    if (d->joint >= 0) {
      rc = fmbd_mbs_add_driver_joint(m->mbs, d->name, m->joint_id[d->joint], &fn, NULL);
    } else {
      rc = fmbd_mbs_add_driver_body(m->mbs, d->name, m->body_id[d->body], d->coordinate, &fn, NULL);
    }
    if (rc) SFAIL(s, d->loc, rc, "driver '%s': %s", d->name, fmbd_err_get()->msg);
  }
  // --- loads ---
  for (int k = 0; k < s->nloads; k++) {
    const fmbd_scene_load *l = &s->loads[k];
    char what[200];
    snprintf(what, sizeof what, "load '%s'", l->name);
    int pid;
    FMBD_GCALL(add_point(m, s, l->body, &l->at, NULL, l->loc, what, &pid, NULL));
    fmbd_mbs_fn fn = l->fn;
    rc = fmbd_mbs_add_load(m->mbs, l->name,
                           l->kind == FMBD_LOAD_TORQUE ? FMBD_MBS_TORQUE : FMBD_MBS_FORCE, pid,
                           l->body_frame, l->direction, &fn, NULL);
    if (rc) SFAIL(s, l->loc, rc, "%s: %s", what, fmbd_err_get()->msg);
  }
  fmbd_mbs_set_gravity(m->mbs, s->gravity);
  // --- outputs ---
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    char what[200];
    snprintf(what, sizeof what, "output '%s'", op->name);
    m->out_body[o] = op->body;
    FMBD_GCALL(
        add_point(m, s, op->body, &op->at, NULL, op->loc, what, &m->out_point[o], &m->out_node[o]));
    if ((op->quantities & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN)) &&
        m->fe[op->body]) {
      if (m->fe[op->body]->ntet == 0 && m->fe[op->body]->nbeam == 0) {
        SFAIL(s, op->loc, FMBD_ERR_SCENE, "%s asks for stress, but %s has no elements", what,
              s->bodies[op->body].file);
      }
    } else if (op->quantities & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN)) {
      const fmbd_rflex *r = m->flex[op->body];
      if (!r->stress) {
        SFAIL(s, op->loc, FMBD_ERR_SCENE,
              "%s asks for stress or strain, but %s has no modal stress (%s)", what,
              s->bodies[op->body].file,
              !strcmp(m->file_kind[op->body], FMBD_CB_FORMAT)
                  ? "it is recovered from solid elements, and its /mesh/elements has no tet4 or "
                    "tet10"
                  : "no /modes/stress: cbcheck writes it for bodies with solid elements");
      }
      if ((op->quantities & FMBD_OUT_STRAIN) && !(m->E[op->body] > 0)) {
        SFAIL(s, op->loc, FMBD_ERR_SCENE, "%s asks for strain, but %s has no /material E and nu",
              what, s->bodies[op->body].file);
      }
      FMBD_GALLOC(m->out_sigma[o] = fmbd_malloc(sizeof(double) * (size_t)(6 * r->nm + 1)));
      rc = fmbd_rflex_node_stress(r, m->out_node[o], m->out_sigma[o]);
      if (rc)
        SFAIL(s, op->loc, rc, "%s: body '%s' (%s): %s", what, s->bodies[op->body].name,
              s->bodies[op->body].file, fmbd_err_get()->msg);
    }
  }
  *out = m;
  m = NULL;
done:
  fmbd_scene_model_destroy(&m);
  return rc;
}

// the stress of a full FE body at a node: its nodal displacements as the one "mode" of
// fmbd_fe_nodal_stress_at (element stresses averaged at the node, from its elements only)
static int fe_output_stress(const fmbd_scene_model *m, int bi, int64_t node, double sigma[6]) {
  int rc = FMBD_OK;
  const fmbd_fe_body *fe = m->fe[bi];
  double *u = NULL, st[6];
  const double *q = NULL;
  fmbd_mbs_modal(m->mbs, m->body_id[bi], &q, NULL, NULL);
  FMBD_GALLOC(u = fmbd_calloc((size_t)fe->ndof, sizeof(double)));
  for (int64_t i = 0; i < fe->ndof; i++) {
    int64_t k = m->fe_col[bi][i];
    u[i] = k >= 0 ? q[k] : 0.0;
  }
  FMBD_GCALL(fmbd_fe_nodal_stress_at(fe, 1, u, 1, &node, st));
  memcpy(sigma, st, sizeof st);
done:
  fmbd_free(u);
  return rc;
}

int fmbd_scene_output_stress(const fmbd_scene_model *m, int o, double sigma[6]) {
  FMBD_CHECK(o >= 0 && o < m->noutputs, FMBD_ERR_VALUE, "output %d has no stress", o);
  int bi = m->out_body[o];
  if (bi >= 0 && m->fe[bi] && m->out_node[o] >= 0)
    return fe_output_stress(m, bi, m->out_node[o], sigma);
  FMBD_CHECK(m->out_sigma[o], FMBD_ERR_VALUE, "output %d has no stress", o);
  const double *q = NULL;
  int64_t nm = fmbd_mbs_modal(m->mbs, m->body_id[m->out_body[o]], &q, NULL, NULL);
  const double *S = m->out_sigma[o];
  for (int i = 0; i < 6; i++) {
    double v = 0;
    for (int64_t k = 0; k < nm; k++) v += S[i + 6 * k] * q[k];
    sigma[i] = v;
  }
  return 0;
}

double fmbd_scene_strain(double E, double nu, const double s[6], double e[6]) {
  double tr = s[0] + s[1] + s[2];
  for (int i = 0; i < 3; i++) e[i] = ((1 + nu) * s[i] - nu * tr) / E;
  for (int i = 3; i < 6; i++) e[i] = (1 + nu) * s[i] / E;  // tensor (not engineering) shear
  double sv = sqrt(0.5 * ((s[0] - s[1]) * (s[0] - s[1]) + (s[1] - s[2]) * (s[1] - s[2]) +
                          (s[2] - s[0]) * (s[2] - s[0])) +
                   3 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
  return 2 * (1 + nu) * sv / (3 * E);
}

void fmbd_scene_model_destroy(fmbd_scene_model **mp) {
  if (!mp || !*mp) return;
  fmbd_scene_model *m = *mp;
  fmbd_mbs_destroy(&m->mbs);
  for (int i = 0; i < m->nbodies; i++) {
    if (m->flex) fmbd_rflex_destroy(&m->flex[i]);
    if (m->file_kind) fmbd_free(m->file_kind[i]);
    if (m->fe) fmbd_fe_body_destroy(&m->fe[i]);
    if (m->fe_col) fmbd_free(m->fe_col[i]);
  }
  for (int o = 0; o < m->noutputs; o++) {
    if (m->out_sigma) fmbd_free(m->out_sigma[o]);
  }
  for (int i = 0; i < m->ninputs; i++) fmbd_free(m->input_name[i]);
  fmbd_free(m->input_name);
  fmbd_free(m->input_sha);
  fmbd_free(m->body_id);
  fmbd_free(m->flex);
  fmbd_free(m->file_kind);
  fmbd_free(m->fe);
  fmbd_free(m->fe_col);
  fmbd_free(m->E);
  fmbd_free(m->nu);
  fmbd_free(m->joint_id);
  fmbd_free(m->out_point);
  fmbd_free(m->out_node);
  fmbd_free(m->out_body);
  fmbd_free(m->out_sigma);
  fmbd_free(m);
  *mp = NULL;
}

// --- the nodes a scene reads on one body (cbcheck --for-scene: a subset body) ----------------
// The places are resolved on r exactly as fmbd_scene_build resolves them (flex_node), so that
// the subset holds the very nodes the run will ask for.
static int push_node(int64_t **v, int64_t *n, int64_t p) {
  int64_t *q = fmbd_realloc(*v, sizeof(int64_t) * (size_t)(*n + 1));
  if (!q) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  *v = q;
  q[(*n)++] = p;
  return 0;
}

int fmbd_scene_body_nodes(const fmbd_scene *s, int bi, const fmbd_rflex *r, int64_t **motion,
                          int64_t *nmotion, int64_t **stress, int64_t *nstress) {
  int rc = 0;
  *motion = *stress = NULL;
  *nmotion = *nstress = 0;
  const fmbd_scene_body *b = &s->bodies[bi];
  for (int k = 0; k < s->njoints; k++) {
    const fmbd_scene_joint *j = &s->joints[k];
    char what[200];
    snprintf(what, sizeof what, "joint '%s'", j->name);
    for (int sd = 0; sd < 2; sd++) {
      if (j->body[sd] != bi) continue;
      const fmbd_scene_at *at = &j->at[sd];
      double x0[3] = {0, 0, 0}, P[3];
      if (at->kind == FMBD_AT_POINT) {
        memcpy(x0, at->p, sizeof x0);
      } else if (at->kind == FMBD_AT_DEFAULT) {  // the joint's point, in this body's frame
        int first = j->at[0].kind != FMBD_AT_DEFAULT ? 0 : 1;
        int ob = j->body[first];
        if (j->has_point) {
          memcpy(P, j->point, sizeof P);
        } else if (ob < 0) {
          memcpy(P, j->at[first].p, sizeof P);
        } else if (s->bodies[ob].kind == FMBD_SCENE_RIGID) {
          to_world(&s->bodies[ob], j->at[first].p, P);
        } else {
          SFAIL(s, j->loc, FMBD_ERR_SCENE,
                "%s: its point on body '%s' comes from flexible body '%s''s file; give the joint "
                "a point (or name the place on '%s') to make a body that holds only what the "
                "scene reads",
                what, b->name, s->bodies[ob].name, b->name);
        }
        to_body(b, P, x0);
      }
      int64_t node;
      FMBD_GCALL(flex_node(s, bi, r, at, x0, j->has_point ? j->point_loc : j->loc, what, &node));
      FMBD_GCALL(push_node(motion, nmotion, node));
    }
  }
  for (int k = 0; k < s->nloads; k++) {
    const fmbd_scene_load *l = &s->loads[k];
    if (l->body != bi || l->at.kind == FMBD_AT_DEFAULT) continue;  // default: the body origin
    char what[200];
    snprintf(what, sizeof what, "load '%s'", l->name);
    int64_t node;
    FMBD_GCALL(flex_node(s, bi, r, &l->at, l->at.p, l->loc, what, &node));
    FMBD_GCALL(push_node(motion, nmotion, node));
  }
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    if (op->body != bi || op->at.kind == FMBD_AT_DEFAULT) continue;
    char what[200];
    snprintf(what, sizeof what, "output '%s'", op->name);
    int64_t node;
    FMBD_GCALL(flex_node(s, bi, r, &op->at, op->at.p, op->loc, what, &node));
    bool sig = op->quantities & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN);
    FMBD_GCALL(push_node(sig ? stress : motion, sig ? nstress : nmotion, node));
  }
done:
  if (rc) {
    fmbd_free(*motion);
    fmbd_free(*stress);
    *motion = *stress = NULL;
    *nmotion = *nstress = 0;
  }
  return rc;
}
