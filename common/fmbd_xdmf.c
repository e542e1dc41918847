// common/fmbd_xdmf.c: the deformed flexible bodies of a run as XDMF fields for ParaView
// SPDX-License-Identifier: MIT
#include "fmbd_xdmf.h"

#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"

typedef struct xbody {
  char *name;
  int64_t nn, nm, first;  // nodes, modes used, first node in the concatenation
  double *x0;             // 3 x nn reference positions
  double *T;              // 3 x nm per node: T[a + 3k + 3 nm p]
  double *S;              // 6 x nm per node: S[i + 6k + 6 nm p]
  fmbd_xdmf_field_fn fn;  // instead of T and S: the fields from q (fn(user, q, u, sigma))
  void *user;
  int pose_id, q_id;  // run-file series
} xbody;

struct fmbd_xdmf {
  fmbd_runfile *rf;  // NULL after its commit: only `run` is used then; NULL for create_h5
  fmbd_h5 *h;        // the file the fields go to (the run file's, or create_h5's)
  char *name, *run;  // the XDMF file, the run file's base name (XML-escaped)
  int nb;
  xbody *b;
  int64_t nnodes, ncells;
  int cell_nodes;  // 4 or 10 (0 before the first body)
  int64_t *cells;  // ncells x cell_nodes, global node indices
  double *t;       // frames' times
  int64_t nframes, cap;
  double *pos, *disp, *vm;  // one frame's arrays (N x 3, N x 3, N)
  double *u, *sig;          // a callback body's u (3 x nn) and sigma (6 x nn), largest body
  int64_t nbuf;             // nodes they hold
};

void fmbd_xdmf_close(fmbd_xdmf **xp) {
  fmbd_xdmf *x = *xp;
  if (!x) return;
  for (int i = 0; i < x->nb; i++) {
    fmbd_free(x->b[i].name);
    fmbd_free(x->b[i].x0);
    fmbd_free(x->b[i].T);
    fmbd_free(x->b[i].S);
  }
  fmbd_free(x->b);
  fmbd_free(x->name);
  fmbd_free(x->run);
  fmbd_free(x->cells);
  fmbd_free(x->t);
  fmbd_free(x->pos);
  fmbd_free(x->disp);
  fmbd_free(x->vm);
  fmbd_free(x->u);
  fmbd_free(x->sig);
  fmbd_free(x);
  *xp = NULL;
}

int fmbd_xdmf_create(fmbd_runfile *rf, const char *xdmf_name, fmbd_xdmf **out) {
  *out = NULL;
  FMBD_CHECK(strcmp(fmbd_runfile_name(rf), "-"), FMBD_ERR_USAGE,
             "XDMF fields need a named run file, not standard output (give -o RUN.h5)");
  FMBD_CALL(fmbd_xdmf_create_h5(fmbd_runfile_h5(rf), fmbd_runfile_name(rf), xdmf_name, out));
  (*out)->rf = rf;
  return FMBD_OK;
}

int fmbd_xdmf_create_h5(fmbd_h5 *h, const char *h5_name, const char *xdmf_name, fmbd_xdmf **out) {
  *out = NULL;
  fmbd_xdmf *x = fmbd_calloc(1, sizeof *x);
  FMBD_CHECK(x, FMBD_ERR_NOMEM, "out of memory");
  x->h = h;
  x->name = fmbd_strdup(xdmf_name);
  // the h5 file by its base name (the XDMF file lies beside it), & < > " ' escaped for XML
  const char *run = h5_name, *slash = strrchr(run, '/');
  run = slash ? slash + 1 : run;
  x->run = fmbd_malloc(6 * strlen(run) + 1);
  if (x->run) {
    char *w = x->run;
    for (const char *c = run; *c; c++) {
      const char *e = *c == '&'    ? "&amp;"
                      : *c == '<'  ? "&lt;"
                      : *c == '>'  ? "&gt;"
                      : *c == '"'  ? "&quot;"
                      : *c == '\'' ? "&apos;"
                                   : NULL;
      if (e) {
        strcpy(w, e);
        w += strlen(e);
      } else {
        *w++ = *c;
      }
    }
    *w = '\0';
  }
  if (!x->name || !x->run) {
    fmbd_xdmf_close(&x);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  *out = x;
  return FMBD_OK;
}

// The common part of adding a body: checks, the cells (from f), the run file's record and series.
// *out is the new body (x0 allocated, T/S/fn left to the caller).
static int add_common(fmbd_xdmf *x, const char *name, const char *file, int64_t nn, fmbd_h5 *f,
                      int64_t nq, xbody **out) {
  int rc = FMBD_OK;
  int64_t *el = NULL;
  FMBD_CHECK(x->nframes == 0, FMBD_ERR_VALUE, "body '%s' added after the first frame", name);
  // the elements: tet10 or tet4, one kind for the whole run
  int k = fmbd_h5_exists(f, "/mesh/elements/tet10")  ? 10
          : fmbd_h5_exists(f, "/mesh/elements/tet4") ? 4
                                                     : 0;
  FMBD_CHECK(k, FMBD_ERR_VALUE,
             "body '%s': %s has no solid elements (/mesh/elements/tet4 or tet10): "
             "the XDMF fields show solid bodies only",
             name, file);
  FMBD_CHECK(!x->cell_nodes || x->cell_nodes == k, FMBD_ERR_VALUE,
             "body '%s': tet%d elements, the bodies before it tet%d: one XDMF grid holds one "
             "element kind",
             name, k, x->cell_nodes);
  int64_t dims[2] = {-1, k};
  FMBD_GCALL(
      fmbd_h5_read_i64(f, k == 10 ? "/mesh/elements/tet10" : "/mesh/elements/tet4", 2, dims, &el));
  int64_t ne = dims[0];
  xbody *nb = fmbd_realloc(x->b, sizeof(xbody) * (size_t)(x->nb + 1));
  FMBD_GCHECK(nb, FMBD_ERR_NOMEM, "out of memory");
  x->b = nb;
  xbody *b = &x->b[x->nb];
  memset(b, 0, sizeof *b);
  x->nb++;
  b->nn = nn;
  b->nm = nq;
  b->first = x->nnodes;
  FMBD_GALLOC(b->name = fmbd_strdup(name));
  FMBD_GALLOC(b->x0 = fmbd_malloc(sizeof(double) * (size_t)(3 * nn + 1)));
  // the cells, in XDMF's node order (Tetrahedron_10: edges 01 12 20 03 13 23; the gmsh order of
  // the fe file has 30 32 31 for the last three: its local nodes 8 and 9 swap)
  for (int64_t e = 0; e < ne; e++) {
    for (int j = 0; j < k; j++) {
      int64_t v = el[e * k + j];
      FMBD_GCHECK(v >= 0 && v < nn, FMBD_ERR_FORMAT, "%s:/mesh/elements: node %lld of %lld", file,
                  (long long)v, (long long)nn);
    }
    if (k == 10) {
      int64_t s = el[e * k + 8];
      el[e * k + 8] = el[e * k + 9];
      el[e * k + 9] = s;
    }
  }
  int64_t *nc = fmbd_realloc(x->cells, sizeof(int64_t) * (size_t)((x->ncells + ne) * k));
  FMBD_GCHECK(nc, FMBD_ERR_NOMEM, "out of memory");
  x->cells = nc;
  for (int64_t i = 0; i < ne * k; i++) x->cells[x->ncells * k + i] = el[i] + b->first;
  // the file: the body's record, and in a run file its series
  fmbd_h5 *h = x->h;
  char path[600];
  snprintf(path, sizeof path, "/fields/body/%s", name);
  FMBD_GCALL(fmbd_h5_make_group(h, path));
  FMBD_GCALL(fmbd_h5_write_attr_str(h, path, "file", file));
  int64_t iv[4] = {b->first, nn, x->ncells, ne};
  const char *in[4] = {"first_node", "nodes", "first_cell", "cells"};
  for (int i = 0; i < 4; i++) FMBD_GCALL(fmbd_h5_write_attr_i64(h, path, in[i], 1, &iv[i]));
  if (x->rf) {
    snprintf(path, sizeof path, "/fields/body/%s/pose", name);
    FMBD_GCALL(fmbd_runfile_series(x->rf, path, 12, "m, 1", 0, &b->pose_id));
    snprintf(path, sizeof path, "/fields/body/%s/q", name);
    FMBD_GCALL(fmbd_runfile_series(x->rf, path, (int)(nq ? nq : 1), "1", 0, &b->q_id));
  }
  x->ncells += ne;
  x->nnodes += nn;
  x->cell_nodes = k;
  *out = b;
done:
  fmbd_free(el);
  return rc;
}

int fmbd_xdmf_add_body(fmbd_xdmf *x, const char *name, const char *file, const fmbd_rflex *r,
                       fmbd_h5 *f, int64_t nm) {
  FMBD_CHECK(r->stress, FMBD_ERR_VALUE,
             "body '%s': %s has no modal stress (/modes/stress): the XDMF fields need it "
             "(cbcheck without --no-stress)",
             name, file);
  FMBD_CHECK(nm >= 0 && nm <= r->nm, FMBD_ERR_VALUE, "body '%s': %lld modes of %lld", name,
             (long long)nm, (long long)r->nm);
  xbody *b = NULL;
  int64_t nn = r->nnodes;
  FMBD_CALL(add_common(x, name, file, nn, f, nm, &b));
  double *Tp = fmbd_malloc(sizeof(double) * (size_t)(3 * r->nm + 1));
  b->T = fmbd_malloc(sizeof(double) * (size_t)(3 * nm * nn + 1));
  b->S = fmbd_malloc(sizeof(double) * (size_t)(6 * nm * nn + 1));
  int rc = Tp && b->T && b->S
               ? FMBD_OK
               : fmbd_err_set(FMBD_ERR_NOMEM, __FILE__, __LINE__, __func__, "out of memory");
  for (int64_t p = 0; p < nn && !rc; p++) {
    rc = fmbd_rflex_node_modes(r, p, b->x0 + 3 * p, Tp, NULL);
    for (int64_t m = 0; m < nm && !rc; m++) {
      for (int a = 0; a < 3; a++) b->T[a + 3 * m + 3 * nm * p] = Tp[a + 3 * m];
      for (int i = 0; i < 6; i++) b->S[i + 6 * m + 6 * nm * p] = r->stress[i + 6 * p + 6 * nn * m];
    }
  }
  fmbd_free(Tp);
  return rc;
}

int fmbd_xdmf_add_body_fn(fmbd_xdmf *x, const char *name, const char *file, int64_t nnodes,
                          const double *x0, fmbd_h5 *f, int64_t nq, fmbd_xdmf_field_fn fn,
                          void *user) {
  xbody *b = NULL;
  FMBD_CALL(add_common(x, name, file, nnodes, f, nq, &b));
  memcpy(b->x0, x0, sizeof(double) * (size_t)(3 * nnodes));
  b->fn = fn;
  b->user = user;
  if (nnodes > x->nbuf) {
    fmbd_free(x->u);
    fmbd_free(x->sig);
    x->u = fmbd_malloc(sizeof(double) * (size_t)(3 * nnodes));
    x->sig = fmbd_malloc(sizeof(double) * (size_t)(6 * nnodes));
    x->nbuf = x->u && x->sig ? nnodes : 0;
    FMBD_CHECK(x->nbuf, FMBD_ERR_NOMEM, "out of memory");
  }
  return FMBD_OK;
}

// The concatenated reference nodes and cells, written before the first frame.
static int write_mesh(fmbd_xdmf *x) {
  fmbd_h5 *h = x->h;
  double *xyz = fmbd_malloc(sizeof(double) * (size_t)(3 * x->nnodes + 1));
  FMBD_CHECK(xyz, FMBD_ERR_NOMEM, "out of memory");
  for (int i = 0; i < x->nb; i++)
    memcpy(xyz + 3 * x->b[i].first, x->b[i].x0, sizeof(double) * (size_t)(3 * x->b[i].nn));
  int64_t d[2] = {x->nnodes, 3};
  int rc = fmbd_h5_write_f64(h, "/fields/nodes", 2, d, xyz);
  fmbd_free(xyz);
  FMBD_CALL(rc);
  int64_t c[2] = {x->ncells, x->cell_nodes};
  FMBD_CALL(fmbd_h5_write_i64(h, "/fields/cells", 2, c, x->cells));
  FMBD_CHECK(x->pos = fmbd_malloc(sizeof(double) * (size_t)(3 * x->nnodes + 1)), FMBD_ERR_NOMEM,
             "out of memory");
  FMBD_CHECK(x->disp = fmbd_malloc(sizeof(double) * (size_t)(3 * x->nnodes + 1)), FMBD_ERR_NOMEM,
             "out of memory");
  FMBD_CHECK(x->vm = fmbd_malloc(sizeof(double) * (size_t)(x->nnodes + 1)), FMBD_ERR_NOMEM,
             "out of memory");
  return FMBD_OK;
}

int fmbd_xdmf_frame(fmbd_xdmf *x, double t, const double *const *R, const double *const *A,
                    const double *const *q) {
  FMBD_CHECK(x->nb > 0, FMBD_ERR_VALUE, "XDMF fields without a flexible body");
  if (x->nframes == 0) FMBD_CALL(write_mesh(x));
  if (x->nframes == x->cap) {
    int64_t cap = x->cap ? 2 * x->cap : 256;
    double *p = fmbd_realloc(x->t, sizeof(double) * (size_t)cap);
    FMBD_CHECK(p, FMBD_ERR_NOMEM, "out of memory");
    x->t = p;
    x->cap = cap;
  }
  for (int i = 0; i < x->nb; i++) {
    const xbody *b = &x->b[i];
    const double *Ab = A[i], *Rb = R[i], *qb = q[i];
    if (b->fn) FMBD_CALL(b->fn(b->user, qb, x->u, x->sig));
    for (int64_t p = 0; p < b->nn; p++) {
      double u[3] = {0, 0, 0}, s[6] = {0, 0, 0, 0, 0, 0};
      if (b->fn) {
        memcpy(u, x->u + 3 * p, sizeof u);
        memcpy(s, x->sig + 6 * p, sizeof s);
      } else {
        const double *T = b->T + 3 * b->nm * p, *S = b->S + 6 * b->nm * p;
        for (int64_t m = 0; m < b->nm; m++) {
          for (int a = 0; a < 3; a++) u[a] += T[a + 3 * m] * qb[m];
          for (int j = 0; j < 6; j++) s[j] += S[j + 6 * m] * qb[m];
        }
      }
      double y[3], *pos = x->pos + 3 * (b->first + p), *disp = x->disp + 3 * (b->first + p);
      for (int a = 0; a < 3; a++) y[a] = b->x0[3 * p + a] + u[a];
      for (int a = 0; a < 3; a++) {
        pos[a] = Rb[a] + Ab[3 * a] * y[0] + Ab[3 * a + 1] * y[1] + Ab[3 * a + 2] * y[2];
        disp[a] = u[a];
      }
      x->vm[b->first + p] = fmbd_von_mises(s);
    }
    if (!x->rf) continue;
    double pose[12];
    memcpy(pose, Rb, 3 * sizeof(double));
    memcpy(pose + 3, Ab, 9 * sizeof(double));
    FMBD_CALL(fmbd_runfile_put(x->rf, b->pose_id, pose));
    double zero = 0;
    FMBD_CALL(fmbd_runfile_put(x->rf, b->q_id, b->nm ? qb : &zero));
  }
  fmbd_h5 *h = x->h;
  char path[128];
  int64_t d[2] = {x->nnodes, 3};
  snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/position", x->nframes);
  FMBD_CALL(fmbd_h5_write_f64(h, path, 2, d, x->pos));
  snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/displacement", x->nframes);
  FMBD_CALL(fmbd_h5_write_f64(h, path, 2, d, x->disp));
  snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/von_mises", x->nframes);
  FMBD_CALL(fmbd_h5_write_f64(h, path, 1, d, x->vm));
  x->t[x->nframes++] = t;
  return FMBD_OK;
}

// One HDF5 data item of the run file.
static void item(FILE *o, const char *h5, const char *path, int64_t rows, int cols, bool integer) {
  fprintf(o, "          <DataItem Dimensions=\"%" PRId64, rows);
  if (cols) fprintf(o, " %d", cols);
  fprintf(o, "\" NumberType=\"%s\" Precision=\"8\" Format=\"HDF\">%s:%s</DataItem>\n",
          integer ? "Int" : "Float", h5, path);
}

int fmbd_xdmf_commit(fmbd_xdmf **xp) {
  fmbd_xdmf *x = *xp;
  int rc = FMBD_OK;
  char *part = NULL;
  FILE *o = NULL;
  const char *h5 = x->run;
  FMBD_GALLOC(part = fmbd_malloc(strlen(x->name) + 6));
  sprintf(part, "%s.part", x->name);
  fmbd_err_context(x->name, "");
  o = fopen(part, "w");
  FMBD_GCHECK(o, FMBD_ERR_IO, "cannot write %s", part);
  fprintf(o,
          "<?xml version=\"1.0\" ?>\n"
          "<!-- the flexible bodies of the run file beside it (docs/FORMAT.md, /fields); "
          "no file name here: a comment cannot hold a double dash -->\n"
          "<Xdmf Version=\"3.0\">\n"
          "  <Domain>\n"
          "    <Grid Name=\"flexible bodies\" GridType=\"Collection\" "
          "CollectionType=\"Temporal\">\n");
  for (int64_t k = 0; k < x->nframes; k++) {
    char path[128];
    fprintf(o, "      <Grid Name=\"frame %" PRId64 "\" GridType=\"Uniform\">\n", k);
    fprintf(o, "        <Time Value=\"%.17g\"/>\n", x->t[k]);
    fprintf(o,
            "        <Topology TopologyType=\"%s\" NumberOfElements=\"%" PRId64
            "\" NodesPerElement=\"%d\">\n",
            x->cell_nodes == 10 ? "Tetrahedron_10" : "Tetrahedron", x->ncells, x->cell_nodes);
    item(o, h5, "/fields/cells", x->ncells, x->cell_nodes, true);
    fprintf(o, "        </Topology>\n        <Geometry GeometryType=\"XYZ\">\n");
    snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/position", k);
    item(o, h5, path, x->nnodes, 3, false);
    fprintf(o, "        </Geometry>\n");
    fprintf(o,
            "        <Attribute Name=\"displacement\" AttributeType=\"Vector\" "
            "Center=\"Node\">\n");
    snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/displacement", k);
    item(o, h5, path, x->nnodes, 3, false);
    fprintf(o, "        </Attribute>\n");
    fprintf(o, "        <Attribute Name=\"von_mises\" AttributeType=\"Scalar\" Center=\"Node\">\n");
    snprintf(path, sizeof path, "/fields/frames/%" PRId64 "/von_mises", k);
    item(o, h5, path, x->nnodes, 0, false);
    fprintf(o, "        </Attribute>\n      </Grid>\n");
  }
  fprintf(o, "    </Grid>\n  </Domain>\n</Xdmf>\n");
  bool bad = ferror(o) != 0;
  bad = fclose(o) != 0 || bad;
  o = NULL;
  FMBD_GCHECK(!bad, FMBD_ERR_IO, "write error on %s", part);
  FMBD_GCHECK(rename(part, x->name) == 0, FMBD_ERR_IO, "cannot rename %s to %s", part, x->name);
  fmbd_err_context("", "");
done:
  if (o) fclose(o);
  if (rc && part) remove(part);
  fmbd_free(part);
  fmbd_xdmf_close(xp);
  return rc;
}
