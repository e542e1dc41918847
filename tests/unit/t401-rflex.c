// tests/unit/t401-rflex.c: the reduced flexible body (common/fmbd_rflex) and the SVG writer
// (common/fmbd_svg): a free beam with two interfaces assembled by fmbd_fe, reduced by fmbd_cb,
// secondary reduction by fmbd_rflex_build; mass normalisation, rflex file round trip
// (bit-exact), accessors, von Mises, wrong-format refusal; SVG output and its errors.
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_est.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_rflex.h"
#include "fmbd_svg.h"

enum { NEL = 12 };

static char dir[512];

static const char *tmp(const char *name) {
  static char buf[4][700];
  static int k = 0;
  k = (k + 1) % 4;
  snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
  return buf[k];
}

int main(void) {
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  snprintf(dir, sizeof dir, "%s/%s/test-tmp/t401-rflex", root ? root : ".",
           build ? build : "build");
  char cmd[700];
  snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
  if (system(cmd) != 0) {
    fprintf(stderr, "cannot create %s\n", dir);
    return 1;
  }
  // --- a free steel beam along x, interfaces at both ends ---------------------------------
  fmbd_mesh mesh = {0};
  mesh.nnodes = NEL + 1;
  mesh.xyz = calloc(3 * (NEL + 1), sizeof(double));
  mesh.nbeam = NEL;
  mesh.beam = calloc(2 * NEL, sizeof(int64_t));
  for (int i = 0; i <= NEL; i++) {
    mesh.xyz[3 * i] = 0.3 * i / NEL;
  }
  for (int e = 0; e < NEL; e++) {
    mesh.beam[2 * e] = e;
    mesh.beam[2 * e + 1] = e + 1;
  }
  mesh.ngroups = 2;
  mesh.group_name = calloc(2, sizeof(char *));
  mesh.group_name[0] = strdup("end0");
  mesh.group_name[1] = strdup("end1");
  mesh.group_ptr = calloc(3, sizeof(int64_t));
  mesh.group_node = calloc(2, sizeof(int64_t));
  mesh.group_ptr[1] = 1;
  mesh.group_ptr[2] = 2;
  mesh.group_node[0] = 0;
  mesh.group_node[1] = NEL;
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  double r = 0.015;
  o.area = M_PI * r * r;
  o.Iy = o.Iz = M_PI * r * r * r * r / 4;
  o.J = 2 * o.Iy;
  fmbd_fe_interface_spec itf[2] = {{"end0", FMBD_FE_RBE2, false, {0, 0, 0}},
                                   {"end1", FMBD_FE_RBE2, false, {0, 0, 0}}};
  o.ninterfaces = 2;
  o.interfaces = itf;
  fmbd_fe_body *b = NULL;
  int rc = fmbd_fe_assemble(&mesh, &o, &b);
  EXPECT(rc == 0, "assemble: %s", fmbd_err_get()->msg);
  if (rc) {
    TEST_EXIT();
  }
  // --- CB reduction, then the modes of the reduced body --------------------------------------
  int64_t nb = 0, *bnd = NULL;
  EXPECT(fmbd_cb_boundary(b, 0, NULL, &nb, &bnd) == 0 && nb == 12, "boundary: %lld dofs",
         (long long)nb);
  fmbd_cb_opts co;
  fmbd_cb_opts_defaults(&co);
  co.nmodes = 8;
  fmbd_cb *cb = NULL;
  EXPECT(fmbd_cb_reduce(b->K, b->M, b->dofs, nb, bnd, &co, &cb) == 0, "reduce: %s",
         fmbd_err_get()->msg);
  int64_t nr = cb->nr, nm = 5, nrig = cb->n_rigid;
  EXPECT(nrig == 6, "%lld rigid-body modes, expected 6", (long long)nrig);
  double chif[5], *Xif = calloc((size_t)(nr * nm), sizeof(double));
  for (int64_t k = 0; k < nm; k++) {
    chif[k] = cb->chibar[nrig + k];
    memcpy(Xif + nr * k, cb->Xi + nr * (nrig + k), sizeof(double) * (size_t)nr);
  }
  fmbd_rflex_input mi = {b,       cb->ns, cb->nb,  cb->interior, cb->boundary, cb->nd,
                         cb->Phi, cb->ns, cb->Psi, nm,           chif,         Xif,
                         nr,      true,   false,   NULL};
  fmbd_rflex *rf = NULL;
  EXPECT(fmbd_rflex_build(&mi, &rf) == 0, "build: %s", fmbd_err_get()->msg);
  // shapes' M shapes = I: T0' M T0 = M_ (closed form) and Xi' M_ Xi = I; round-off of the
  // reduction ~1e-13 on this 78-dof beam; 1e-9 tolerates it, a wrong shape is O(1)
  int64_t n = b->ndof;
  double *MX = calloc((size_t)(n * nm), sizeof(double)), G[25], Kq[25];
  fmbd_csr_matmat(b->M, nm, rf->shapes, n, MX, n);
  fmbd_dense_gemm('T', 'N', nm, nm, n, 1.0, rf->shapes, n, MX, n, 0.0, G, nm);
  fmbd_csr_matmat(b->K, nm, rf->shapes, n, MX, n);
  fmbd_dense_gemm('T', 'N', nm, nm, n, 1.0, rf->shapes, n, MX, n, 0.0, Kq, nm);
  for (int i = 0; i < nm; i++) {
    for (int j = 0; j < nm; j++) {
      EXPECT(fabs(G[i + nm * j] - (i == j)) < 1e-9, "shapes' M shapes (%d,%d) = %g", i, j,
             G[i + nm * j]);
      EXPECT(fabs(Kq[i + nm * j] - (i == j) * chif[i]) < 1e-9 * chif[nm - 1],
             "shapes' K shapes (%d,%d)", i, j);
    }
  }
  // a body for partial inertia coupling: SS not formed (zero, flagged), everything else the same
  {
    mi.no_ss = true;
    fmbd_rflex *rp = NULL;
    EXPECT(fmbd_rflex_build(&mi, &rp) == 0 && rp, "build without SS: %s", fmbd_err_get()->msg);
    if (rp && rf) {
      int nz = 0;
      for (int64_t i = 0; i < 9 * nm * nm; i++) nz += rp->SS[i] != 0.0;
      EXPECT(rp->ss_omitted && !rf->ss_omitted && nz == 0, "SS omitted: %d nonzero", nz);
      EXPECT(!memcmp(rp->S1, rf->S1, sizeof(double) * 3 * nm) &&
                 !memcmp(rp->XS, rf->XS, sizeof(double) * 9 * nm) &&
                 !memcmp(rp->shapes, rf->shapes, sizeof(double) * n * nm),
             "without SS: the other invariants differ");
    }
    fmbd_rflex_destroy(&rp);
    mi.no_ss = false;
  }
  // the first nk modes built alone (fmbd-run's `modes: nk` for a .cb.h5 body): the whole build's
  // first columns. Only the order of the dense products' sums may differ (BLAS blocking by the
  // column count), so each entry agrees to a few ulps of the field's largest entry: 1e-12 of it
  // tolerates that, a wrong or shifted mode is O(1) off. S1 and XS are sums of terms of order
  // sqrt(m) (|S1_k| <= sqrt(m) |X_k|_M) and sqrt(m) times the body's size, cancelling to
  // round-off for free-free modes: their scale is that of the terms, not of the result
  {
    const int64_t nk = nm - 2;
    mi.nm = nk;
    fmbd_rflex *rk = NULL;
    EXPECT(fmbd_rflex_build(&mi, &rk) == 0 && rk && rk->nm == nk, "build of %lld modes: %s",
           (long long)nk, fmbd_err_get()->msg);
    if (rk && rf) {
      double sm = sqrt(rf->mass), size = 0;
      for (int64_t p = 0; p < 3 * rf->nnodes; p++) size = fmax(size, fabs(rf->node_xyz[p]));
#define PREFIX(name, a, b, cnt, scale)                                                         \
  do {                                                                                         \
    double big = (scale), d = 0;                                                               \
    for (int64_t e_ = 0; e_ < (cnt); e_++) {                                                   \
      big = fmax(big, fabs((a)[e_]));                                                          \
      d = fmax(d, fabs((a)[e_] - (b)[e_]));                                                    \
    }                                                                                          \
    EXPECT(d <= 1e-12 * big, "%lld modes alone: %s differs by %g (largest %g)", (long long)nk, \
           name, d, big);                                                                      \
  } while (0)
      PREFIX("shapes", rf->shapes, rk->shapes, n * nk, 0.0);
      PREFIX("S1", rf->S1, rk->S1, 3 * nk, sm);
      PREFIX("XS", rf->XS, rk->XS, 9 * nk, sm * size);
      for (int i = 0; i < rf->ninterfaces; i++) {
        PREFIX("interface translation", rf->interfaces[i].translation,
               rk->interfaces[i].translation, 3 * nk, 0.0);
        PREFIX("interface rotation", rf->interfaces[i].rotation, rk->interfaces[i].rotation, 3 * nk,
               0.0);
      }
      double *ssw = calloc((size_t)(9 * nk * nk), sizeof(double));
      for (int64_t l = 0; l < nk; l++) {
        for (int64_t k = 0; k < nk; k++) {
          memcpy(ssw + 9 * k + 9 * nk * l, rf->SS + 9 * k + 9 * nm * l, 9 * sizeof(double));
        }
      }
      PREFIX("SS", ssw, rk->SS, 9 * nk * nk, 0.0);
      free(ssw);
#undef PREFIX
    }
    fmbd_rflex_destroy(&rk);
    mi.nm = nm;
  }
  // the interior dofs listed in reverse (Phi's and Psi's rows with them): the shapes through the
  // ns x nm copy instead of straight into their rows; the same shapes up to the products'
  // round-off (1e-12 of the largest entry, as above; a misplaced row is O(1) off)
  {
    int64_t ns = cb->ns, nb = cb->nb, nd = cb->nd;
    int64_t *irev = calloc((size_t)ns, sizeof(int64_t));
    double *prev = calloc((size_t)(ns * (nd + nb)), sizeof(double)), *srev = prev + ns * nd;
    for (int64_t i = 0; i < ns; i++) {
      irev[i] = cb->interior[ns - 1 - i];
      for (int64_t j = 0; j < nd; j++) prev[i + ns * j] = cb->Phi[ns - 1 - i + ns * j];
      for (int64_t j = 0; j < nb; j++) srev[i + ns * j] = cb->Psi[ns - 1 - i + ns * j];
    }
    fmbd_rflex_input mr = mi;
    mr.interior_dofs = irev, mr.Phi = prev, mr.Psi = srev, mr.ldphi = ns;
    fmbd_rflex *rr = NULL;
    EXPECT(fmbd_rflex_build(&mr, &rr) == 0 && rr, "build, interior reversed: %s",
           fmbd_err_get()->msg);
    if (rr && rf) {
      double big = 0, d = 0;
      for (int64_t e = 0; e < n * nm; e++) {
        big = fmax(big, fabs(rf->shapes[e]));
        d = fmax(d, fabs(rf->shapes[e] - rr->shapes[e]));
      }
      EXPECT(d <= 1e-12 * big, "interior reversed: shapes differ by %g (largest %g)", d, big);
    }
    fmbd_rflex_destroy(&rr);
    free(irev);
    free(prev);
  }
  // first moment and mass from /body
  EXPECT(rf->mass == b->mass && fabs(rf->first_moment[0] - b->mass * b->center_of_mass[0]) < 1e-15,
         "mass / first moment");
  // --- write, read back: bit-exact ---------------------------------------------------------------
  fmbd_h5 *f = NULL;
  EXPECT(fmbd_h5_create(tmp("beam.rflex.h5"), FMBD_RFLEX_FORMAT, FMBD_RFLEX_VERSION, &f) == 0,
         "create");
  EXPECT(fmbd_fe_write(f, b) == 0, "description");
  EXPECT(fmbd_rflex_write(f, rf) == 0, "write: %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_commit(&f, 0, 0) == 0, "commit");
  fmbd_rflex *rd = NULL;
  EXPECT(fmbd_h5_open(tmp("beam.rflex.h5"), &f) == 0, "open");
  EXPECT(fmbd_rflex_read(f, &rd) == 0, "read: %s", fmbd_err_get()->msg);
  fmbd_h5_close(&f);
  if (rd) {
    EXPECT(rd->nm == nm && rd->ndof == n && rd->nnodes == rf->nnodes && rd->ninterfaces == 2,
           "sizes");
#define SAME(field, count) \
  EXPECT(!memcmp(rd->field, rf->field, sizeof(double) * (size_t)(count)), #field " differs")
    SAME(eigenvalue, nm);
    SAME(frequency_hz, nm);
    SAME(shapes, n * nm);
    // a beam body: modal stress is recovered from solid elements only, so none (not zeros)
    EXPECT(!rf->stress && !rd->stress, "a beam body has no modal stress");
    SAME(node_xyz, 3 * rf->nnodes);
    SAME(node_mass, rf->nnodes);
    SAME(S1, 3 * nm);
    SAME(XS, 9 * nm);
    SAME(SS, 9 * nm * nm);
    SAME(Mff, nm * nm);
    SAME(Kff, nm * nm);
    EXPECT(!memcmp(rd->second_moment, rf->second_moment, sizeof rf->second_moment),
           "second moment");
    EXPECT(rd->mass == rf->mass, "mass");
    for (int i = 0; i < 2; i++) {
      int j = fmbd_rflex_find_interface(rd, rf->interfaces[i].name);
      EXPECT(j >= 0, "interface %s not found", rf->interfaces[i].name);
      if (j >= 0) {
        EXPECT(!memcmp(rd->interfaces[j].translation, rf->interfaces[i].translation,
                       sizeof(double) * 3 * nm),
               "translation of %s", rf->interfaces[i].name);
        EXPECT(rd->interfaces[j].node == rf->interfaces[i].node, "node of %s",
               rf->interfaces[i].name);
        // the accessor gives the same rows of /expand times the shapes
        double x0[3], T[15], R[15];
        EXPECT(fmbd_rflex_node_modes(rd, rd->interfaces[j].node, x0, T, R) == 0, "node_modes");
        for (int q = 0; q < 3 * nm; q++) {
          EXPECT(fabs(T[q] - rd->interfaces[j].translation[q]) <= 1e-15 * fabs(T[q]) &&
                     fabs(R[q] - rd->interfaces[j].rotation[q]) <= 1e-15 * fabs(R[q]),
                 "node_modes of %s entry %d", rf->interfaces[i].name, q);
        }
        double dist;
        EXPECT(fmbd_rflex_nearest_node(rd, x0, &dist) >= 0 && dist == 0, "nearest node");
      }
    }
    EXPECT(fmbd_rflex_find_interface(rd, "nope") == -1, "unknown interface");
    EXPECT(fmbd_rflex_node_modes(rd, rd->nnodes, NULL, NULL, NULL) == FMBD_ERR_VALUE,
           "node out of range");
    double sg[30];
    EXPECT(fmbd_rflex_node_stress(rd, 3, sg) == FMBD_ERR_VALUE, "no stress: an error");
  }
  // a file of another kind is refused
  EXPECT(fmbd_h5_create(tmp("other.h5"), "fmbd-cb", "1.0", &f) == 0, "create other");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == 0, "commit other");
  fmbd_rflex *bad = NULL;
  fmbd_h5_open(tmp("other.h5"), &f);
  EXPECT(fmbd_rflex_read(f, &bad) == FMBD_ERR_FORMAT && !bad, "a fmbd-cb file read as rflex");
  fmbd_h5_close(&f);
  // von Mises: uniaxial sigma -> sigma; pure shear tau -> sqrt(3) tau
  double s1[6] = {100, 0, 0, 0, 0, 0}, s2[6] = {0, 0, 0, 10, 0, 0}, s3[6] = {5, 5, 5, 0, 0, 0};
  EXPECT(fabs(fmbd_von_mises(s1) - 100) < 1e-12 &&
             fabs(fmbd_von_mises(s2) - sqrt(3) * 10) < 1e-12 && fabs(fmbd_von_mises(s3)) < 1e-12,
         "von Mises");
  // --- SVG ---------------------------------------------------------------------------------------
  double x[4] = {1, 2, 3, 4}, y[4] = {1e-5, 0, 3e-3, NAN}, yneg[2] = {-1, 0};
  fmbd_svg_plot p;
  fmbd_svg_plot_defaults(&p);
  p.ylog = true;
  p.title = "a <title> & more";
  fmbd_svg_series s[1] = {{"series", 4, x, y, NULL, FMBD_SVG_CIRCLE, FMBD_SVG_SOLID}};
  EXPECT(fmbd_svg_write(tmp("p.svg"), &p, 1, s) == 0, "svg");
  struct stat st;
  EXPECT(stat(tmp("p.svg"), &st) == 0 && st.st_size > 500 && stat(tmp("p.svg.part"), &st) != 0,
         "svg file");
  FILE *fp = fopen(tmp("p.svg"), "r");
  char text[20000] = {0};
  if (fp) {
    size_t got = fread(text, 1, sizeof text - 1, fp);
    text[got] = 0;
    fclose(fp);
  }
  EXPECT(strstr(text, "a &lt;title&gt; &amp; more") && strstr(text, "</svg>") &&
             strstr(text, ">1e-5<"),
         "svg content (escaped title, closed, decade label 1e-5)");
  fmbd_svg_series sn[1] = {{"neg", 2, x, yneg, NULL, FMBD_SVG_NONE, FMBD_SVG_SOLID}};
  EXPECT(
      fmbd_svg_write(tmp("neg.svg"), &p, 1, sn) == FMBD_ERR_VALUE && stat(tmp("neg.svg"), &st) != 0,
      "a log axis with no positive value must fail and leave no file");
  EXPECT(fmbd_svg_write("/nonexistent-dir/p.svg", &p, 1, s) == FMBD_ERR_IO, "unwritable path");
  fmbd_rflex_destroy(&rd);
  fmbd_rflex_destroy(&rf);
  fmbd_rflex_destroy(&rf);  // NULL is fine
  fmbd_cb_destroy(&cb);
  fmbd_free(bnd);
  free(Xif);
  free(MX);
  fmbd_fe_body_destroy(&b);
  for (int g = 0; g < 2; g++) {
    free(mesh.group_name[g]);
  }
  free(mesh.group_name);
  free(mesh.group_ptr);
  free(mesh.group_node);
  free(mesh.xyz);
  free(mesh.beam);
  TEST_EXIT();
}
