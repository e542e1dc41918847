// gmsolve/main.c: global modes of a linearised mechanism (SCENE.yaml -> SCENE.gm.h5)
// SPDX-License-Identifier: MIT
//
// A thin command line over common/fmbd_gm (docs/THEORY.md section 6): build the scene's
// mechanism, find the rigid-reference configuration, linearise, solve the constrained
// eigenproblem on a null-space basis, write the global modes and the GMs / GMc bases (format
// fmbd-gm, docs/FORMAT.md). See docs/man/gmsolve.1.
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_gm.h"
#include "fmbd_gm_scene.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"
#include "fmbd_svg.h"
#include "fmbd_xdmf.h"

static const char *usage_text =
    "Usage: gmsolve SCENE.yaml [-o SCENE.gm.h5] [--modes K | --fmax HZ] [--at T]\n"
    "               [--keep-drivers] [--rank-tol E] [--matrices] [--dense-max N]\n"
    "               [--plot PREFIX] [--xdmf] [--body-dir DIR] [-M]\n"
    "Global modes of a mechanism linearised at a rigid-reference configuration (Cammarata\n"
    "2021): the constrained eigenproblem K x = w^2 M x, Cq x = 0 solved on a sparse null-\n"
    "space basis of the constraint Jacobian (checked so that no mode is skipped), the f\n"
    "rigid-reference (zero-frequency) modes checked against the mechanism's mobility, the\n"
    "flexible modes, their participation masses, and the GMs and GMc reduction bases of every\n"
    "flexible body (an fmbd-gm HDF5 file).\n"
    "\n"
    "SCENE.yaml  an fmbd-run scene (docs/SCENE.md); its flexible bodies' files must exist.\n"
    "\n"
    "Options:\n"
    "  -o FILE          output (\"-\": standard output). Default: SCENE with .yaml replaced\n"
    "                   by .gm.h5, or standard output when that is not a terminal\n"
    "  --modes K        number of flexible global modes (default 10)\n"
    "  --fmax HZ        every flexible global mode up to HZ instead of a count\n"
    "  --at T           linearise where the drivers put the mechanism at time T s (default:\n"
    "                   the scene's initial configuration, t = 0)\n"
    "  --keep-drivers   keep the drivers' equations in the constraints (default: left out,\n"
    "                   so that a driven joint's motion is a rigid-reference mode)\n"
    "  --rank-tol E     GMc: a body's mode column is dropped as linearly dependent when its\n"
    "                   part independent of the columns kept before it is below E times its\n"
    "                   own size (mass norm), default 1e-3\n"
    "  --matrices       also write the linearised M, K and the constraint Jacobian used\n"
    "                   (/linear), e.g. for an independent check\n"
    "  --dense-max N    solve the reduced eigenproblem densely (LAPACK) up to order N, by\n"
    "                   shift-invert Lanczos above (default 1000)\n"
    "  --plot PREFIX    PREFIX-mode1.svg ... PREFIX-mode6.svg: the first flexible modes drawn\n"
    "                   on the mechanism (flexible bodies' nodes, rigid bodies' frame origins)\n"
    "                   in the plane of its two largest extents\n"
    "  --xdmf           also OUT.xdmf beside OUT.h5 (.h5 replaced): each flexible global\n"
    "                   mode as a frame (time = mode number) on the flexible bodies' solid\n"
    "                   meshes for ParaView: displacement (world, the rigid-reference motion\n"
    "                   of the frames included; unit modal mass) and von Mises stress; the\n"
    "                   fields are written into OUT.h5 (/fields)\n"
    "  --body-dir DIR   resolve the scene's body files against DIR instead of the scene's\n"
    "                   folder (as fmbd-run --body-dir)\n"
    "  -M               print make rules of the files the scene needs (as fmbd-run -M) for\n"
    "                   the target SCENE.gm.h5, and exit\n"
    "  -q, --quiet      errors only\n"
    "  -v, --verbose    the linearisation, the null space and where the time went\n"
    "  -h, --help       this help\n"
    "  -V, --version    the version\n"
    "\n"
    "Example:\n"
    "  gmsolve fourbar.yaml --modes 12 -o fourbar.gm.h5\n";

typedef struct args {
  const char *input, *output, *body_dir, *plot;
  long modes;
  bool modes_given;
  double fmax_hz, at, rank_tol;
  bool at_given, keep_drivers, matrices, make_rules, xdmf;
  long dense_max;
  int quiet, verbose;
} args;

enum {
  OPT_OUTPUT = 1,
  OPT_MODES,
  OPT_FMAX,
  OPT_AT,
  OPT_RANK_TOL,
  OPT_DENSE_MAX,
  OPT_BODY_DIR,
  OPT_PLOT,
  OPT_KEEP_DRIVERS,
  OPT_MATRICES,
  OPT_RULES,
  OPT_XDMF
};
static const fmbd_cli_option options[] = {{"--output", 'o', true, OPT_OUTPUT},
                                          {"--modes", 0, true, OPT_MODES},
                                          {"--fmax", 0, true, OPT_FMAX},
                                          {"--at", 0, true, OPT_AT},
                                          {"--rank-tol", 0, true, OPT_RANK_TOL},
                                          {"--dense-max", 0, true, OPT_DENSE_MAX},
                                          {"--body-dir", 0, true, OPT_BODY_DIR},
                                          {"--plot", 0, true, OPT_PLOT},
                                          {"--keep-drivers", 0, false, OPT_KEEP_DRIVERS},
                                          {"--matrices", 0, false, OPT_MATRICES},
                                          {"--xdmf", 0, false, OPT_XDMF},
                                          {NULL, 'M', false, OPT_RULES},
                                          {0}};

// 0: go on; -1: done (help/version printed); > 0: exit status (usage error)
static int parse_args(int argc, char **argv, args *a) {
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    switch (id) {
      case FMBD_CLI_EXIT:
        return p.status ? p.status : -1;
      case FMBD_CLI_ARG:
        if (a->input) {
          return fmbd_cli_usage_error("one SCENE.yaml expected, got '%s' and '%s'", a->input,
                                      p.value);
        }
        a->input = p.value;
        break;
      case OPT_OUTPUT:
        a->output = p.value;
        break;
      case OPT_MODES:
        if (fmbd_cli_long(&p, 1, LONG_MAX, &a->modes)) return p.status;
        a->modes_given = true;
        break;
      case OPT_FMAX:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &a->fmax_hz)) return p.status;
        break;
      case OPT_AT:
        if (fmbd_cli_double(&p, -INFINITY, INFINITY, 0, &a->at)) return p.status;
        a->at_given = true;
        break;
      case OPT_RANK_TOL:
        if (fmbd_cli_double(&p, 0, 1, FMBD_CLI_OPEN_LO | FMBD_CLI_OPEN_HI, &a->rank_tol))
          return p.status;
        break;
      case OPT_DENSE_MAX:
        if (fmbd_cli_long(&p, 0, LONG_MAX, &a->dense_max)) return p.status;
        break;
      case OPT_BODY_DIR:
        a->body_dir = p.value;
        break;
      case OPT_PLOT:
        a->plot = p.value;
        break;
      case OPT_KEEP_DRIVERS:
        a->keep_drivers = true;
        break;
      case OPT_MATRICES:
        a->matrices = true;
        break;
      case OPT_RULES:
        a->make_rules = true;
        break;
      case OPT_XDMF:
        a->xdmf = true;
        break;
    }
  }
  a->quiet = p.quiet;
  a->verbose = p.verbose;
  if (!a->input) return fmbd_cli_usage_error("no SCENE.yaml given");
  if (a->modes_given && a->fmax_hz > 0.0) {
    return fmbd_cli_usage_error("--modes and --fmax are exclusive");
  }
  return 0;
}

// --- --xdmf: the flexible global modes on the bodies' meshes -----------------------------------
// A body's field of a mode dx (all n coordinates): the elastic translations of its nodes from its
// elastic coordinates (a full FE body's dofs, or a modal body's modal coordinates through the
// file's shapes) through /expand, plus the rigid-reference motion of its frame, in the world:
//   w_p = dR + dA x0_p + A u_p,   dA = dA/dp dp (central difference, h = 1e-6: 1e-12 relative)
// and the stress of the elastic part (fmbd_fe_nodal_stress, body frame), both times the mode's
// display scale (the largest node displacement of the mode 10 % of the mechanism's extent, as
// --plot; /fields/mode_scale), so that the frames' positions show the shape.
typedef struct gm_field {
  const fmbd_fe_body *fe;  // the body's description (elements, /expand)
  const int64_t *col;      // full FE body: dof -> elastic coordinate (-1 frame node); or NULL
  const fmbd_rflex *r;     // modal body: its shapes (ndof x nm)
  int64_t off;             // the body's first coordinate
  double R[3], p[4], A[9];
  double *ua, *uall, *x0;  // ndof, 6 nnodes, 3 nnodes (body frame)
  double scale;            // the mode's display scale
} gm_field;

static int gm_field_fn(void *user, const double *dx, double *u, double *sigma) {
  gm_field *d = user;
  const fmbd_fe_body *fe = d->fe;
  const double *q = dx + d->off + 7;
  for (int64_t i = 0; i < fe->ndof; i++) {
    double v = 0.0;
    if (d->col) {
      v = d->col[i] >= 0 ? q[d->col[i]] : 0.0;
    } else {
      for (int64_t k = 0; k < d->r->nm; k++) v += d->r->shapes[i + d->r->ndof * k] * q[k];
    }
    d->ua[i] = v;
  }
  fmbd_csr_matvec(fe->expand, d->ua, d->uall);
  const double h = 1e-6;
  double pp[4], pm[4], Ap[9], Am[9], dA[9];
  for (int c = 0; c < 4; c++) pp[c] = d->p[c] + h * dx[d->off + 3 + c];
  for (int c = 0; c < 4; c++) pm[c] = d->p[c] - h * dx[d->off + 3 + c];
  fmbd_mbs_rotation_quat(pp, Ap);
  fmbd_mbs_rotation_quat(pm, Am);
  for (int i = 0; i < 9; i++) dA[i] = (Ap[i] - Am[i]) / (2 * h);
  for (int64_t p = 0; p < fe->nnodes; p++) {
    const double *x0 = d->x0 + 3 * p, *ue = d->uall + 6 * p;
    for (int a = 0; a < 3; a++) {
      u[a + 3 * p] = dx[d->off + a];
      for (int c = 0; c < 3; c++) u[a + 3 * p] += dA[3 * a + c] * x0[c] + d->A[3 * a + c] * ue[c];
      u[a + 3 * p] *= d->scale;
    }
  }
  if (!sigma) return FMBD_OK;
  FMBD_CALL(fmbd_fe_nodal_stress(fe, 1, d->ua, sigma));
  for (int64_t i = 0; i < 6 * fe->nnodes; i++) sigma[i] *= d->scale;
  return FMBD_OK;
}

// The fields of every flexible body with solid elements into out, one frame per mode; the XDMF
// file is written by the caller (fmbd_xdmf_commit) once out is committed.
static int xdmf_modes(fmbd_xdmf *xd, fmbd_h5 *out, const fmbd_scene *s, const fmbd_scene_model *md,
                      const int64_t *bodyoff, const double *x, int64_t n, const double *Xf,
                      int64_t nk) {
  int rc = FMBD_OK;
  int nb = 0;
  gm_field *d = NULL;
  fmbd_fe_body **own = NULL;
  const double **R = NULL, **A = NULL, **q = NULL;
  fmbd_h5 *f = NULL;
  double *ubuf = NULL, *scale = NULL, lo[3] = {INFINITY, INFINITY, INFINITY},
         hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  int64_t nmax = 0;
  FMBD_GALLOC(d = fmbd_calloc((size_t)s->nbodies + 1, sizeof *d));
  FMBD_GALLOC(own = fmbd_calloc((size_t)s->nbodies + 1, sizeof *own));
  FMBD_GALLOC(R = fmbd_calloc((size_t)s->nbodies + 1, sizeof *R));
  FMBD_GALLOC(A = fmbd_calloc((size_t)s->nbodies + 1, sizeof *A));
  FMBD_GALLOC(q = fmbd_calloc((size_t)s->nbodies + 1, sizeof *q));
  static const double zero[3] = {0, 0, 0}, eye[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int i = 0; i < s->nbodies; i++) {
    if (s->bodies[i].kind != FMBD_SCENE_FLEXIBLE) continue;
    const char *file = s->bodies[i].file;
    FMBD_GCALL(fmbd_h5_open(file, &f));
    if (!fmbd_h5_exists(f, "/mesh/elements/tet4") && !fmbd_h5_exists(f, "/mesh/elements/tet10")) {
      fmbd_log(FMBD_LOG_WARN, "--xdmf: body '%s' (%s) has no solid elements: not in the fields",
               s->bodies[i].name, file);
      fmbd_h5_close(&f);
      continue;
    }
    gm_field *g = &d[nb];
    if (md->fe && md->fe[i]) {
      g->fe = md->fe[i];
      g->col = md->fe_col[i];
    } else {  // a modal body: its file's description (elements, material, /expand)
      FMBD_GCALL(fmbd_fe_read(f, &own[nb]));
      g->fe = own[nb];
      g->r = md->flex[i];
      FMBD_GCHECK(g->fe->ndof == g->r->ndof && g->fe->expand, FMBD_ERR_FORMAT,
                  "--xdmf: body '%s': %s describes %lld dofs, its modes %lld", s->bodies[i].name,
                  file, (long long)g->fe->ndof, (long long)g->r->ndof);
    }
    g->off = bodyoff[md->body_id[i]];
    memcpy(g->R, x + g->off, sizeof g->R);
    memcpy(g->p, x + g->off + 3, sizeof g->p);
    fmbd_mbs_rotation_quat(g->p, g->A);
    int64_t nn = g->fe->nnodes;
    FMBD_GALLOC(g->ua = fmbd_calloc((size_t)g->fe->ndof + 1, sizeof(double)));
    FMBD_GALLOC(g->uall = fmbd_calloc((size_t)(6 * nn) + 1, sizeof(double)));
    FMBD_GALLOC(g->x0 = fmbd_calloc((size_t)(3 * nn) + 1, sizeof(double)));
    double *w = NULL;  // world reference positions: the grid's nodes
    FMBD_GALLOC(w = fmbd_calloc((size_t)(3 * nn) + 1, sizeof(double)));
    for (int64_t p = 0; p < nn; p++) {
      memcpy(g->x0 + 3 * p, g->fe->xyz + 3 * p, 3 * sizeof(double));
      for (int a = 0; a < 3; a++) {
        w[3 * p + a] = g->R[a];
        for (int c = 0; c < 3; c++) w[3 * p + a] += g->A[3 * a + c] * g->x0[3 * p + c];
        lo[a] = fmin(lo[a], w[3 * p + a]), hi[a] = fmax(hi[a], w[3 * p + a]);
      }
    }
    if (nn > nmax) nmax = nn;
    rc = fmbd_xdmf_add_body_fn(xd, s->bodies[i].name, file, nn, w, f, n, gm_field_fn, g);
    fmbd_free(w);
    FMBD_GCALL(rc);
    R[nb] = zero, A[nb] = eye;
    nb++;
    fmbd_h5_close(&f);
  }
  FMBD_GCHECK(nb > 0, FMBD_ERR_VALUE, "--xdmf: the scene has no flexible body with solid elements");
  double size = fmax(fmax(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2]);
  FMBD_GALLOC(ubuf = fmbd_calloc((size_t)(3 * nmax) + 1, sizeof(double)));
  FMBD_GALLOC(scale = fmbd_calloc((size_t)nk + 1, sizeof(double)));
  for (int64_t k = 0; k < nk; k++) {
    double big = 0.0;  // the mode's largest node displacement at unit modal mass
    for (int b = 0; b < nb; b++) {
      d[b].scale = 1.0;
      FMBD_GCALL(gm_field_fn(&d[b], Xf + n * k, ubuf, NULL));
      for (int64_t p = 0; p < d[b].fe->nnodes; p++)
        big = fmax(big, hypot(hypot(ubuf[3 * p], ubuf[3 * p + 1]), ubuf[3 * p + 2]));
    }
    scale[k] = big > 0 ? 0.1 * (size > 0 ? size : 1.0) / big : 1.0;
    for (int b = 0; b < nb; b++) q[b] = Xf + n * k, d[b].scale = scale[k];
    FMBD_GCALL(fmbd_xdmf_frame(xd, (double)(k + 1), R, A, q));
  }
  int64_t dk[1] = {nk};
  FMBD_GCALL(fmbd_h5_write_f64(out, "/fields/mode_scale", 1, dk, scale));
done:
  fmbd_free(ubuf);
  fmbd_free(scale);
  fmbd_h5_close(&f);
  for (int b = 0; d && b < s->nbodies; b++) {
    fmbd_free(d[b].ua);
    fmbd_free(d[b].uall);
    fmbd_free(d[b].x0);
    fmbd_fe_body_destroy(&own[b]);
  }
  fmbd_free(d);
  fmbd_free(own);
  fmbd_free(R);
  fmbd_free(A);
  fmbd_free(q);
  return rc;
}

// --- --plot: the first modes drawn on the mechanism -------------------------------------------
// World positions of the drawn points (flexible bodies: every node; rigid bodies: the frame
// origin) at the configuration x + eps dx, linearised in the elastic part: r = R + A (x0 + S q).
static void draw_points(const fmbd_scene *s, const fmbd_scene_model *md, const int64_t *bodyoff,
                        const double *x, const double *dx, double eps, double *P) {
  int64_t k = 0;
  for (int i = 0; i < s->nbodies; i++) {
    int64_t off = bodyoff[md->body_id[i]];
    double R[3], p[4], A[9];
    for (int c = 0; c < 3; c++) R[c] = x[off + c] + (dx ? eps * dx[off + c] : 0.0);
    for (int c = 0; c < 4; c++) p[c] = x[off + 3 + c] + (dx ? eps * dx[off + 3 + c] : 0.0);
    fmbd_mbs_rotation_quat(p, A);
    const fmbd_rflex *r = md->flex[i];
    const fmbd_fe_body *fe = md->fe ? md->fe[i] : NULL;
    if (!r) {
      memcpy(P + 3 * k++, R, sizeof R);
      continue;
    }
    for (int64_t nd = 0; nd < r->nnodes; nd++) {
      double u[3];
      memcpy(u, r->node_xyz + 3 * nd, sizeof u);
      if (dx && fe) {  // a full FE body: its dofs other than the frame node's
        for (int c = 0; c < 3; c++) {
          const fmbd_csr *E = fe->expand;
          for (int64_t q = E->indptr[6 * nd + c]; q < E->indptr[6 * nd + c + 1]; q++) {
            int64_t j = md->fe_col[i][E->indices[q]];
            if (j >= 0) u[c] += eps * E->data[q] * dx[off + 7 + j];
          }
        }
      } else if (dx) {
        for (int c = 0; c < 3; c++) {
          const fmbd_csr *E = r->expand;
          for (int64_t q = E->indptr[6 * nd + c]; q < E->indptr[6 * nd + c + 1]; q++) {
            const double *col = r->shapes + E->indices[q];
            for (int64_t j = 0; j < r->nm; j++)
              u[c] += eps * E->data[q] * col[r->ndof * j] * dx[off + 7 + j];
          }
        }
      }
      for (int a = 0; a < 3; a++) {
        P[3 * k + a] = R[a] + A[3 * a] * u[0] + A[3 * a + 1] * u[1] + A[3 * a + 2] * u[2];
      }
      k++;
    }
  }
}

static int plot_modes(const char *prefix, const fmbd_scene *s, const fmbd_scene_model *md,
                      const int64_t *bodyoff, const double *x, int64_t n, const double *Xf,
                      int64_t nk, const double *fhz) {
  int rc = FMBD_OK;
  int64_t np = 0;
  for (int i = 0; i < s->nbodies; i++) np += md->flex[i] ? md->flex[i]->nnodes : 1;
  double *P0 = NULL, *P1 = NULL, *xy = NULL;
  char *path = NULL;
  FMBD_GALLOC(P0 = fmbd_malloc(sizeof(double) * (size_t)(3 * np)));
  FMBD_GALLOC(P1 = fmbd_malloc(sizeof(double) * (size_t)(3 * np)));
  FMBD_GALLOC(xy = fmbd_malloc(sizeof(double) * (size_t)(4 * np)));
  FMBD_GALLOC(path = fmbd_malloc(strlen(prefix) + 32));
  draw_points(s, md, bodyoff, x, NULL, 0.0, P0);
  // the drawing plane: the two world axes along which the mechanism is largest
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int64_t k = 0; k < np; k++) {
    for (int a = 0; a < 3; a++)
      lo[a] = fmin(lo[a], P0[3 * k + a]), hi[a] = fmax(hi[a], P0[3 * k + a]);
  }
  int ax0 = 0, ax1 = 1, small = 2;
  for (int a = 0; a < 3; a++) {
    if (hi[a] - lo[a] < hi[small] - lo[small]) small = a;
  }
  ax0 = small == 0 ? 1 : 0;
  ax1 = small == 2 ? 1 : 2;
  double size = fmax(fmax(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2]);
  static const char *axn[3] = {"x (m)", "y (m)", "z (m)"};
  for (int64_t m = 0; m < nk && m < 6; m++) {
    const double *dx = Xf + n * m;
    // the largest point displacement is drawn as 10 % of the mechanism's size
    double eps = 1e-6, big = 0.0;
    draw_points(s, md, bodyoff, x, dx, eps, P1);
    for (int64_t k = 0; k < np; k++) {
      double d = 0.0;
      for (int a = 0; a < 3; a++)
        d += (P1[3 * k + a] - P0[3 * k + a]) * (P1[3 * k + a] - P0[3 * k + a]);
      big = fmax(big, sqrt(d) / eps);
    }
    double scale = big > 0 ? 0.1 * (size > 0 ? size : 1.0) / big : 0.0;
    // linear in the elastic part, nonlinear in the rotations: drawn at the scaled amplitude
    draw_points(s, md, bodyoff, x, dx, scale, P1);
    for (int64_t k = 0; k < np; k++) {
      xy[k] = P0[3 * k + ax0];
      xy[np + k] = P0[3 * k + ax1];
      xy[2 * np + k] = P1[3 * k + ax0];
      xy[3 * np + k] = P1[3 * k + ax1];
    }
    char title[160];
    snprintf(title, sizeof title, "global mode %lld: %.6g Hz (amplitude scaled)", (long long)m + 1,
             fhz[m]);
    fmbd_svg_plot pl;
    fmbd_svg_plot_defaults(&pl);
    pl.title = title;
    pl.xlabel = axn[ax0];
    pl.ylabel = axn[ax1];
    fmbd_svg_series sr[2] = {
        {"reference", np, xy, xy + np, "#999999", FMBD_SVG_CIRCLE, FMBD_SVG_NOLINE},
        {"mode", np, xy + 2 * np, xy + 3 * np, "#d62728", FMBD_SVG_CIRCLE, FMBD_SVG_NOLINE}};
    sprintf(path, "%s-mode%lld.svg", prefix, (long long)m + 1);
    FMBD_GCALL(fmbd_svg_write(path, &pl, 2, sr));
  }
done:
  fmbd_free(P0);
  fmbd_free(P1);
  fmbd_free(xy);
  fmbd_free(path);
  return rc;
}

int main(int argc, char **argv) {
  fmbd_cli_init("gmsolve", argc, argv);
  args a;
  memset(&a, 0, sizeof a);
  a.modes = 10;
  a.rank_tol = 1e-3;
  {
    fmbd_gm_opts go;
    fmbd_gm_opts_defaults(&go);
    a.dense_max = (long)go.dense_max;
  }
  int st = parse_args(argc, argv, &a);
  if (st != 0) return fmbd_cli_finish(st < 0 ? 0 : st);
  fmbd_cli_set_verbosity(a.quiet, a.verbose);

  int rc = FMBD_OK;
  fmbd_scene *s = NULL;
  fmbd_scene_model *md = NULL;
  fmbd_h5 *out = NULL;
  fmbd_mbs_linear L = {0};
  fmbd_csr *Cq = NULL;
  fmbd_gm_result res = {0};
  char *oname = NULL, *rules = NULL, *xname = NULL;
  fmbd_xdmf *xw = NULL;
  bool *rigid = NULL;
  double *x = NULL, *xd = NULL, *rt = NULL, *P = NULL, *fhz = NULL;
  int64_t *rows = NULL, *coord = NULL, *bodyoff = NULL;
  static const char *const strip[] = {".yaml", ".yml", NULL};
  double T = a.at_given ? a.at : 0.0;

  FMBD_GCALL(fmbd_scene_read_dir(a.input, a.body_dir, &s));
  if (a.make_rules) {
    if (a.output) {
      FMBD_GALLOC(oname = fmbd_strdup(a.output));
    } else {  // the derived name even when standard output is a pipe: the rules go there
      size_t n = strlen(a.input), cut = n;
      for (int i = 0; strip[i]; i++) {
        size_t k = strlen(strip[i]);
        if (n > k && !strcmp(a.input + n - k, strip[i])) cut = n - k;
      }
      FMBD_GALLOC(oname = fmbd_malloc(cut + 8));
      memcpy(oname, a.input, cut);
      strcpy(oname + cut, ".gm.h5");
    }
    FMBD_GCALL(fmbd_scene_make_rules(s, oname, &rules));
    fputs(rules, stdout);
    goto done;
  }
  FMBD_GCALL(fmbd_cli_output_name(a.input, a.output, strip, ".gm.h5", &oname));
  if (a.xdmf) {
    static const char *const h5[] = {".h5", NULL};
    FMBD_GCHECK(strcmp(oname, "-"), FMBD_ERR_USAGE,
                "--xdmf needs a named output beside it, not standard output: give -o OUT.gm.h5");
    FMBD_GCALL(fmbd_cli_derive_name(oname, h5, ".xdmf", &xname));
  }

  // --- the mechanism ---
  double t0 = fmbd_wall_s(), c0 = fmbd_cpu_s(), c_init = 0;
  FMBD_GCALL(fmbd_scene_build(s, &md));
  double c_scene = fmbd_cpu_s() - c0;
  for (int i = 0; i < md->ninputs; i++)
    FMBD_GCALL(fmbd_cli_check_not_input(oname, md->input_name[i]));
  bool any_flex = false;
  for (int i = 0; i < s->nbodies; i++) any_flex |= s->bodies[i].kind == FMBD_SCENE_FLEXIBLE;
  // no initial conditions: fmbd_gm_rigid_reference makes its own configuration consistent
  // (elastic coordinates zero, frames projected) and the linearisation is at zero velocities;
  // this saves fmbd_mbs_init's factorisations of [M Cq'; Cq 0] (bench/README.md, gmsolve)
  fmbd_mbs_settings set = s->solver;
  set.linearise_only = true;
  c_init = fmbd_cpu_s();
  rc = fmbd_mbs_init(md->mbs, &set);
  c_init = fmbd_cpu_s() - c_init;
  if (rc) {
    fmbd_err_context(a.input, "");  // the message names the joint or body
    goto done;
  }
  fmbd_mbs *mbs = md->mbs;
  int64_t n = fmbd_mbs_ncoordinates(mbs);
  int nbm = fmbd_mbs_nbodies(mbs);
  {
    fmbd_mbs_stats stt;
    fmbd_mbs_get_stats(mbs, &stt);
    FMBD_GCHECK(stt.equations + stt.redundant == fmbd_gm_equation_count(s), FMBD_ERR_INTERNAL,
                "%lld equations in the mechanism, %lld counted from the scene",
                (long long)(stt.equations + stt.redundant), (long long)fmbd_gm_equation_count(s));
    if (stt.redundant > 0) {
      fmbd_log(FMBD_LOG_INFO, "%s: %lld redundant constraint equations removed (as fmbd-run does)",
               a.input, (long long)stt.redundant);
    }
  }
  // coordinates: per mbs body [R (3), p (4), modal]; which are not stiffened (frames)
  FMBD_GALLOC(rigid = fmbd_calloc((size_t)n + 1, sizeof(bool)));
  FMBD_GALLOC(bodyoff = fmbd_calloc((size_t)nbm + 1, sizeof(int64_t)));
  for (int b = 0, off = 0; b < nbm; b++) {
    bodyoff[b] = off;
    for (int i = 0; i < 7; i++) rigid[off + i] = true;
    off += 7 + fmbd_mbs_body_nm(mbs, b);
  }
  FMBD_GALLOC(x = fmbd_calloc((size_t)n + 1, sizeof(double)));
  FMBD_GALLOC(xd = fmbd_calloc((size_t)n + 1, sizeof(double)));
  FMBD_GCALL(fmbd_gm_rigid_reference(mbs, s, md, rigid, T, x));
  rc = fmbd_mbs_check_removed(mbs, T, x);  // the redundant equations hold there too
  if (rc) {
    fmbd_err_context(a.input, "");
    goto done;
  }
  FMBD_GCALL(fmbd_mbs_linearise(mbs, T, x, xd, &L));
  // --- the constraint rows used: drivers out unless asked ---
  FMBD_GALLOC(rows = fmbd_calloc((size_t)L.nc + 1, sizeof(int64_t)));
  int64_t m = 0, ndrv = 0;
  for (int64_t r = 0; r < L.nc; r++) {
    bool drv = fmbd_gm_equation_is_driver(s, L.eq[r]);
    ndrv += drv;
    if (drv && !a.keep_drivers) continue;
    rows[m++] = r;
  }
  {
    int64_t *cols = NULL;
    FMBD_GALLOC(cols = fmbd_calloc((size_t)n + 1, sizeof(int64_t)));
    for (int64_t j = 0; j < n; j++) cols[j] = j;
    rc = fmbd_csr_submatrix(L.Cq, m, rows, n, cols, &Cq);
    fmbd_free(cols);
    FMBD_GCALL(rc);
  }
  double t_lin = fmbd_wall_s() - t0, c_lin = fmbd_cpu_s() - c0;

  // --- the global modes ---
  fmbd_gm_opts go;
  fmbd_gm_opts_defaults(&go);
  go.nmodes = a.modes;
  if (a.fmax_hz > 0) go.lambda_max = pow(2 * M_PI * a.fmax_hz, 2);
  go.dense_max = a.dense_max;
  int64_t bad = -1;
  rc = fmbd_gm_solve(L.M, L.K, Cq, rigid, &go, &res, &bad);
  if (rc) {
    char msg[1100], name[600] = "";
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    if (rc == FMBD_ERR_SINGULAR && bad >= 0)
      fmbd_gm_equation_name(s, md, L.eq[rows[bad]], name, sizeof name);
    fmbd_err_context(a.input, "");
    FMBD_GFAIL(rc, "%s%s%s%s", msg, name[0] ? " (" : "", name, name[0] ? ")" : "");
  }
  int64_t f = res.f, nk = res.nflex, ne = f + nk;
  const double *Xf = res.X + n * f;
  if (!any_flex) fmbd_log(FMBD_LOG_WARN, "%s: no flexible body", a.input);

  // --- participation masses: rigid translations of the whole mechanism ---
  FMBD_GALLOC(rt = fmbd_calloc((size_t)(3 * n + 1), sizeof(double)));
  for (int b = 0; b < nbm; b++) {
    for (int c = 0; c < 3; c++) rt[bodyoff[b] + c + n * c] = 1.0;
  }
  FMBD_GALLOC(P = fmbd_calloc((size_t)(3 * ne + 1), sizeof(double)));
  fmbd_gm_participation(L.M, ne, res.X, rt, P);

  // --- write ---
  double t1 = fmbd_wall_s();
  fmbd_err_context(oname, "");
  FMBD_GCALL(fmbd_h5_create(oname, FMBD_GM_FORMAT, FMBD_GM_FORMAT_VERSION, &out));
  if (strcmp(a.input, "-")) FMBD_GCALL(fmbd_h5_add_input(out, a.input, NULL));
  for (int i = 0; i < md->ninputs; i++)
    FMBD_GCALL(fmbd_h5_add_input(out, md->input_name[i], md->input_sha[i]));
  FMBD_GCALL(fmbd_h5_make_group(out, "/global"));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "f", 1, &f));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "mobility", 1, &res.mobility));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "coordinates", 1, &n));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "constraints", 1, &m));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "driver_equations", 1, &ndrv));
  {
    int64_t kd = a.keep_drivers;
    FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "keep_drivers", 1, &kd));
  }
  FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/global", "time", 1, &T));
  FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/global", "zero_bound", 1, &res.zero_bound));
  {
    double ss = isnan(res.eig.sturm_shift) ? NAN : res.eig.sturm_shift;
    FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/global", "sturm_shift", 1, &ss));
    FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "sturm_count", 1, &res.eig.sturm_count));
    int64_t dense = res.eig.dense;
    FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/global", "dense", 1, &dense));
  }
  int64_t d1[1] = {nk};
  FMBD_GCALL(fmbd_h5_write_f64(out, "/global/eigenvalue", 1, d1, res.lambda + f));
  FMBD_GALLOC(fhz = fmbd_calloc((size_t)ne + 1, sizeof(double)));
  for (int64_t k = 0; k < ne; k++) fhz[k] = sqrt(fmax(res.lambda[k], 0.0)) / (2 * M_PI);
  FMBD_GCALL(fmbd_h5_write_f64(out, "/global/frequency_hz", 1, d1, fhz + f));
  FMBD_GCALL(fmbd_h5_write_f64(out, "/global/residual", 1, d1, res.resid + f));
  FMBD_GCALL(fmbd_h5_write_f64_cm(out, "/global/shapes", n, nk, Xf));
  {  // the participation of the flexible modes: P is ne x 3; rows f..ne-1
    double *Pf = NULL;
    FMBD_GALLOC(Pf = fmbd_calloc((size_t)(3 * nk + 1), sizeof(double)));
    for (int c = 0; c < 3; c++) {
      for (int64_t k = 0; k < nk; k++) Pf[k + nk * c] = P[f + k + ne * c];
    }
    rc = fmbd_h5_write_f64_cm(out, "/global/participation_mass", nk, 3, Pf);
    fmbd_free(Pf);
    FMBD_GCALL(rc);
  }
  {
    double *Pr = NULL;
    FMBD_GALLOC(Pr = fmbd_calloc((size_t)(3 * f + 1), sizeof(double)));
    for (int c = 0; c < 3; c++) {
      for (int64_t k = 0; k < f; k++) Pr[k + f * c] = P[k + ne * c];
    }
    rc = fmbd_h5_write_f64_cm(out, "/global/rigid/participation_mass", f, 3, Pr);
    fmbd_free(Pr);
    FMBD_GCALL(rc);
  }
  FMBD_GCALL(fmbd_h5_write_f64_cm(out, "/global/rigid/shapes", n, f, res.X));
  {
    int64_t d0[1] = {f};
    FMBD_GCALL(fmbd_h5_write_f64(out, "/global/rigid/eigenvalue", 1, d0, res.lambda));
  }
  // coordinates: (n, 2) scene body index and coordinate within the body
  FMBD_GALLOC(coord = fmbd_calloc((size_t)(2 * n + 1), sizeof(int64_t)));
  for (int i = 0; i < s->nbodies; i++) {
    int b = md->body_id[i];
    int64_t nb = 7 + fmbd_mbs_body_nm(mbs, b);
    for (int64_t c = 0; c < nb; c++) {
      coord[2 * (bodyoff[b] + c)] = i;
      coord[2 * (bodyoff[b] + c) + 1] = c;
    }
  }
  {
    int64_t d2[2] = {n, 2};
    FMBD_GCALL(fmbd_h5_write_i64(out, "/global/coordinates", 2, d2, coord));
    const char **names = NULL;
    FMBD_GALLOC(names = fmbd_calloc((size_t)s->nbodies + 1, sizeof(char *)));
    for (int i = 0; i < s->nbodies; i++) names[i] = s->bodies[i].name;
    rc = fmbd_h5_write_attr_strv(out, "/global", "bodies", s->nbodies, names);
    fmbd_free(names);
    FMBD_GCALL(rc);
  }
  if (a.matrices) {
    FMBD_GCALL(fmbd_h5_write_csr(out, "/linear/M", L.M));
    FMBD_GCALL(fmbd_h5_write_csr(out, "/linear/K", L.K));
    FMBD_GCALL(fmbd_h5_write_csr(out, "/linear/Cq", Cq));
    int64_t dn[1] = {n};
    FMBD_GCALL(fmbd_h5_write_f64(out, "/linear/x", 1, dn, x));
  }
  FMBD_GCALL(fmbd_h5_make_group(out, "/gms"));
  FMBD_GCALL(fmbd_h5_make_group(out, "/gmc"));
  FMBD_GCALL(fmbd_h5_write_attr_i64(out, "/gms", "modes", 1, &nk));
  FMBD_GCALL(fmbd_h5_write_attr_f64(out, "/gmc", "rank_tolerance", 1, &a.rank_tol));
  int64_t gmc_total = 0;
  for (int i = 0; i < s->nbodies; i++) {
    if (s->bodies[i].kind != FMBD_SCENE_FLEXIBLE) continue;
    const char *sha = NULL;
    for (int k = 0; k < md->ninputs; k++) {
      if (!strcmp(md->input_name[k], s->bodies[i].file)) sha = md->input_sha[k];
    }
    int64_t nc = 0;
    int b = md->body_id[i];
    FMBD_GCALL(fmbd_gm_write_body(out, s, md, i, bodyoff[b], fmbd_mbs_body_nm(mbs, b), n, Xf, nk,
                                  a.rank_tol, sha, &nc));
    gmc_total += nc;
    fmbd_log(FMBD_LOG_INFO, "body '%s': GMc basis of %lld columns (%lld dependent removed)",
             s->bodies[i].name, (long long)nc, (long long)(nk - nc));
  }
  if (a.xdmf) {
    FMBD_GCALL(fmbd_xdmf_create_h5(out, oname, xname, &xw));
    FMBD_GCALL(xdmf_modes(xw, out, s, md, bodyoff, x, n, Xf, nk));
  }
  FMBD_GCALL(fmbd_h5_commit(&out, fmbd_cli_wall_s(), fmbd_cli_cpu_s()));
  if (xw) FMBD_GCALL(fmbd_xdmf_commit(&xw));
  if (a.plot) FMBD_GCALL(plot_modes(a.plot, s, md, bodyoff, x, n, Xf, nk, fhz + f));
  double t_write = fmbd_wall_s() - t1;
  double max_resid = 0.0;
  for (int64_t k = f; k < ne; k++) max_resid = fmax(max_resid, res.resid[k]);
  fmbd_log(
      FMBD_LOG_INFO,
      "%lld coordinates, %lld constraint rows (%lld driver rows %s); null space %lld with %lld "
      "entries in Z; %s eigensolution; Sturm count %lld; max residual of the flexible pairs %.2g, "
      "max |Cq x| %.2g",
      (long long)n, (long long)m, (long long)ndrv, a.keep_drivers ? "kept" : "left out",
      (long long)res.nz, (long long)res.nnz_z, res.eig.dense ? "dense" : "Lanczos",
      (long long)res.eig.sturm_count, max_resid, res.cq_resid);
  fmbd_log(FMBD_LOG_INFO,
           "time: build and linearise %.3g s (cpu %.3g s: scene and bodies %.3g s, fmbd_mbs_init "
           "%.3g s, rigid reference and linearisation %.3g s), null space %.3g s, projection %.3g "
           "s, eigensolution %.3g s, write %.3g s",
           t_lin, c_lin, c_scene, c_init, c_lin - c_scene - c_init, res.t_null_s, res.t_project_s,
           res.t_eig_s, t_write);
  const char *shown = strcmp(oname, "-") ? oname : "(stdout)";
  fmbd_cli_summary("%s: f = %lld rigid-reference modes, %lld flexible global modes %.6g .. %.6g Hz",
                   shown, (long long)f, (long long)nk, fhz[f], fhz[ne - 1]);
  (void)gmc_total;
done:
  fmbd_h5_close(&out);  // an uncommitted write handle is discarded: no output left
  fmbd_mbs_linear_free(&L);
  fmbd_csr_destroy(&Cq);
  fmbd_gm_result_free(&res);
  fmbd_scene_model_destroy(&md);
  fmbd_scene_destroy(&s);
  fmbd_xdmf_close(&xw);
  fmbd_free(xname);
  fmbd_free(oname);
  fmbd_free(rules);
  fmbd_free(rigid);
  fmbd_free(x);
  fmbd_free(xd);
  fmbd_free(rt);
  fmbd_free(P);
  fmbd_free(fhz);
  fmbd_free(rows);
  fmbd_free(coord);
  fmbd_free(bodyoff);
  return fmbd_cli_finish(rc);
}
