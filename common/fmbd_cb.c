// common/fmbd_cb.c: Craig-Bampton (and normal-mode) reduction of one FE body, the fmbd-cb file
// SPDX-License-Identifier: MIT
//
// Equations: docs/THEORY.md section 1 (Han et al. 2020 [H10-H22]); the closed form of the reduced
// matrices follows from T0 = [Phi Psi; 0 I] with Ks Phi = Ms Phi Lambda, Phi' Ms Phi = I and
// Ks Psi = -Kc: T0' K T0 = [Lambda, Phi'(Ks Psi + Kc); ., Psi' Ks Psi + 2 sym(Psi' Kc) + Kb]
// = [Lambda 0; 0 Kb + Kc' Psi], and T0' M T0 = [I, Phi'(Ms Psi + Mc); ., Mb_].
#define _DEFAULT_SOURCE  // mkstemp, fdopen, unlink (scratch_file)
#include "fmbd_cb.h"

#include <math.h>
#include <stdio.h>
#include <sys/resource.h>  // getrusage (mem_log)
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>  // malloc_trim: give freed factor memory back before the next large phase
#endif
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

static const char *const DIRNAME[6] = {"ux", "uy", "uz", "rx", "ry", "rz"};

void fmbd_cb_opts_defaults(fmbd_cb_opts *o) {
  memset(o, 0, sizeof *o);
  o->nm = false;
  o->hold = false;
  o->nmodes = 20;
  o->fmax_hz = 0.0;
  o->rigid_rtol = 1e-6;
  o->sym_rtol = 1e-10;
  // 1e-11, not the library's 1e-12: the kept pairs' Ritz values are quadratic in the residual,
  // so /cb/kappa moves in its last bits only (7.8e-16 relative at 51 k dofs, the residual
  // check's 1e-6 bound far away), and the 20-mode run needs one block of 4 fewer (84 -> 80
  // solves at 51 k and 188 k, 640 -> 608 at 100 modes; bench/README.md "The Lanczos stage at
  // 20 modes: the kept pairs' tolerance")
  o->fixed_tol = 1e-11;
  fmbd_eig_opts_defaults(&o->eig);
}

void fmbd_cb_destroy(fmbd_cb **pcb) {
  if (!pcb || !*pcb) return;
  fmbd_cb *cb = *pcb;
  fmbd_free(cb->interior);
  fmbd_free(cb->boundary);
  fmbd_free(cb->held);
  fmbd_free(cb->kappa);
  fmbd_free(cb->Phi);
  fmbd_free(cb->Psi);
  fmbd_free(cb->A);
  fmbd_free(cb->KsinvA);
  fmbd_free(cb->KsinvMsKsinvA);
  fmbd_free(cb->PhitA);
  fmbd_free(cb->Mr);
  fmbd_free(cb->Kr);
  fmbd_free(cb->chibar);
  fmbd_free(cb->Xi);
  fmbd_free(cb->rigid);
  fmbd_free(cb->fe_file);
  fmbd_free(cb);
  *pcb = NULL;
}

// "dof 12 (node 4, uz)" for messages
static const char *dof_label(const int64_t *dofs, int64_t i, char *buf, size_t size) {
  if (dofs && dofs[2 * i + 1] >= 0 && dofs[2 * i + 1] < 6) {
    snprintf(buf, size, "dof %lld (node %lld, %s)", (long long)i, (long long)dofs[2 * i],
             DIRNAME[dofs[2 * i + 1]]);
  } else {
    snprintf(buf, size, "dof %lld", (long long)i);
  }
  return buf;
}

static void *alloc_f64(int64_t n) {
  return fmbd_malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
}

// --- partition ------------------------------------------------------------------------------
int fmbd_cb_boundary(const fmbd_fe_body *b, int ngroups, const char *const *groups, int64_t *nb,
                     int64_t **boundary) {
  int rc = FMBD_OK;
  char *mark = NULL;
  *nb = 0;
  *boundary = NULL;
  FMBD_GALLOC(mark = fmbd_calloc((size_t)(b->ndof ? b->ndof : 1), 1));
  for (int k = 0; k < b->ninterfaces; k++) {
    for (int d = 0; d < 6; d++) {
      int64_t i = fmbd_fe_dof(b, b->interfaces[k].node, d);
      if (i >= 0) mark[i] = 1;
    }
  }
  for (int g = 0; g < ngroups; g++) {
    int64_t added = 0;
    int k = fmbd_fe_find_interface(b, groups[g]);
    if (k >= 0) {
      for (int d = 0; d < 6; d++) {
        int64_t i = fmbd_fe_dof(b, b->interfaces[k].node, d);
        if (i >= 0) mark[i] = 1, added++;
      }
    } else {
      int gi = -1;
      for (int j = 0; j < b->ngroups; j++) {
        if (!strcmp(b->group_name[j], groups[g])) gi = j;
      }
      FMBD_GCHECK(gi >= 0, FMBD_ERR_VALUE,
                  "--boundary %s: no mesh group or interface of that name in /mesh/groups",
                  groups[g]);
      for (int64_t p = b->group_ptr[gi]; p < b->group_ptr[gi + 1]; p++) {
        for (int d = 0; d < 6; d++) {
          int64_t i = fmbd_fe_dof(b, b->group_node[p], d);
          if (i >= 0) mark[i] = 1, added++;
        }
      }
    }
    if (added == 0) {
      fmbd_log(FMBD_LOG_WARN, "--boundary %s: the group has no active dof (tied or clamped)",
               groups[g]);
    }
  }
  int64_t n = 0;
  for (int64_t i = 0; i < b->ndof; i++) n += mark[i];
  FMBD_GALLOC(*boundary = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
  n = 0;
  for (int64_t i = 0; i < b->ndof; i++) {
    if (mark[i]) (*boundary)[n++] = i;
  }
  *nb = n;
done:
  fmbd_free(mark);
  return rc;
}

int fmbd_cb_check_body(const fmbd_fe_body *b, double sym_rtol) {
  char lab[96];
  const char *name[2] = {"/K", "/M"};
  const fmbd_csr *mat[2] = {b->K, b->M};
  // both symmetry checks in one walk where M holds K's pattern arrays; the messages below in
  // the order of the separate checks
  int64_t sym_bad[2] = {-2, -2};  // -2: not checked yet
  bool square = true;
  for (int k = 0; k < 2; k++) {
    square = square && mat[k] && mat[k]->nrows == b->ndof && mat[k]->ncols == b->ndof;
  }
  if (square && b->M->indices == b->K->indices) {
    fmbd_csr_is_symmetric_pair(b->K, b->M, sym_rtol, sym_bad);
  }
  for (int k = 0; k < 2; k++) {
    const fmbd_csr *A = mat[k];
    if (!A) {
      fmbd_err_context(NULL, name[k]);
      FMBD_FAIL(FMBD_ERR_FORMAT, "missing matrix (an fmbd-fe file holds /K and /M)");
    }
    if (A->nrows != b->ndof || A->ncols != b->ndof) {
      fmbd_err_context(NULL, name[k]);
      FMBD_FAIL(FMBD_ERR_FORMAT, "shape %lld x %lld, expected %lld x %lld (the rows of /dofs)",
                (long long)A->nrows, (long long)A->ncols, (long long)b->ndof, (long long)b->ndof);
    }
    int64_t bad = sym_bad[k];
    if (bad == -2) fmbd_csr_is_symmetric(A, sym_rtol, &bad);
    if (bad >= 0) {
      fmbd_err_context(NULL, name[k]);
      FMBD_FAIL(FMBD_ERR_VALUE,
                "matrix is not symmetric (|A(i,j) - A(j,i)| > %.0e max|A|) at row %s", sym_rtol,
                dof_label(b->dofs, bad, lab, sizeof lab));
    }
    double dmax = 0.0;
    for (int64_t i = 0; i < b->ndof; i++) {
      double d = fmbd_csr_get(A, i, i);
      dmax = fmax(dmax, d);
      if (d < 0.0 || (k == 0 && d == 0.0)) {
        fmbd_err_context(NULL, name[k]);
        FMBD_FAIL(FMBD_ERR_VALUE, "diagonal entry %.6g at %s (%s)", d,
                  dof_label(b->dofs, i, lab, sizeof lab),
                  k == 0 ? "a stiffness matrix has a positive diagonal" : "negative mass");
      }
    }
    if (k == 1 && b->ndof > 0 && !(dmax > 0.0)) {
      // else the eigensolvers fail later with their own codes (ARPACK info -9, dsygvd)
      fmbd_err_context(NULL, name[k]);
      FMBD_FAIL(FMBD_ERR_VALUE, "the mass matrix is zero (no dof has mass: density 0?)");
    }
  }
  return FMBD_OK;
}

// --- reduced problem ---------------------------------------------------------------------------
// Rebuild Mr, Kr of order nd + nb from kappa, PhitA and the boundary blocks of the current
// Mr, Kr (order cb->nr, boundary block at the end), then solve the reduced eigenproblem.
int fmbd_cb_update_reduced(fmbd_cb *cb, double rigid_rtol) {
  int rc = FMBD_OK;
  int64_t nd = cb->nd, nb = cb->nb, nr = nd + nb, old = cb->nr;
  double *Mr = NULL, *Kr = NULL, *Ma = NULL, *Ka = NULL, *w = NULL;
  int64_t *rigid = NULL;
  FMBD_GALLOC(Mr = alloc_f64(nr * nr));
  FMBD_GALLOC(Kr = alloc_f64(nr * nr));
  memset(Mr, 0, (size_t)(nr * nr) * sizeof(double));
  memset(Kr, 0, (size_t)(nr * nr) * sizeof(double));
  for (int64_t k = 0; k < nd; k++) {
    Mr[k + k * nr] = 1.0;
    Kr[k + k * nr] = cb->kappa[k];
  }
  if (nb > 0) {
    FMBD_GCHECK(cb->Mr && cb->Kr && old >= nb, FMBD_ERR_INTERNAL, "no boundary blocks");
    int64_t o = old - nb;
    for (int64_t j = 0; j < nb; j++) {
      for (int64_t i = 0; i < nb; i++) {
        Mr[(nd + i) + (nd + j) * nr] = cb->Mr[(o + i) + (o + j) * old];
        Kr[(nd + i) + (nd + j) * nr] = cb->Kr[(o + i) + (o + j) * old];
      }
      for (int64_t k = 0; k < nd; k++) {
        double v = cb->PhitA[k + j * nd];
        Mr[k + (nd + j) * nr] = v;
        Mr[(nd + j) + k * nr] = v;
      }
    }
  }
  // reduced eigenproblem (LAPACK dsygvd on copies)
  FMBD_GALLOC(Ma = alloc_f64(nr * nr));
  FMBD_GALLOC(Ka = alloc_f64(nr * nr));
  FMBD_GALLOC(w = alloc_f64(nr));
  FMBD_GALLOC(rigid = fmbd_calloc((size_t)(nr ? nr : 1), sizeof(int64_t)));
  memcpy(Ma, Mr, (size_t)(nr * nr) * sizeof(double));
  memcpy(Ka, Kr, (size_t)(nr * nr) * sizeof(double));
  rc = fmbd_dense_sygv(nr, Ka, Ma, w);
  if (rc == FMBD_ERR_SINGULAR) {
    FMBD_GFAIL(rc,
               "reduced mass matrix (%lld x %lld) is not positive definite: a boundary dof "
               "without mass (massless interface node?)",
               (long long)nr, (long long)nr);
  }
  FMBD_GCALL(rc);
  // rigid-body modes: chibar below rigid_rtol of the first fixed-interface eigenvalue (a
  // flexible scale of the body); without modes, 1e-3 rigid_rtol of the largest diagonal ratio
  // K_ii / M_ii of the boundary block before condensation (cb->rigid_scale: an upper scale of
  // the body's eigenvalues; the condensed K_ of one interface is all round-off, eps times it,
  // so its own diagonal cannot serve), else of the condensed block's diagonal ratio
  double scale = 0.0;
  if (nd > 0) {
    scale = cb->kappa[0];
  } else if (cb->rigid_scale > 0.0) {
    scale = cb->rigid_scale;
    rigid_rtol *= 1e-3;
  } else {
    for (int64_t i = 0; i < nr; i++) {
      if (Mr[i + i * nr] > 0.0) scale = fmax(scale, Kr[i + i * nr] / Mr[i + i * nr]);
    }
    rigid_rtol *= 1e-3;
  }
  int64_t nrig = 0;
  for (int64_t i = 0; i < nr; i++) {
    rigid[i] = fabs(w[i]) <= rigid_rtol * scale;
    nrig += rigid[i];
  }
  fmbd_free(cb->Mr);
  fmbd_free(cb->Kr);
  fmbd_free(cb->chibar);
  fmbd_free(cb->Xi);
  fmbd_free(cb->rigid);
  cb->Mr = Mr;
  cb->Kr = Kr;
  cb->chibar = w;
  cb->Xi = Ka;
  cb->rigid = rigid;
  cb->nr = nr;
  cb->n_rigid = nrig;
  Mr = Kr = w = Ka = NULL;
  rigid = NULL;
done:
  fmbd_free(Mr);
  fmbd_free(Kr);
  fmbd_free(Ma);
  fmbd_free(Ka);
  fmbd_free(w);
  fmbd_free(rigid);
  return rc;
}

// K(rows, cols) of the boundary / interior partition
static int sub(const fmbd_csr *A, int64_t nr, const int64_t *r, int64_t nc, const int64_t *c,
               fmbd_csr **out) {
  return fmbd_csr_submatrix(A, nr, r, nc, c, out);
}

// Ms on the pattern of Ks: an fmbd-fe file assembles K and M on one pattern (mesh2fe), so the
// interior blocks' index arrays are equal and Ms can point at Ks's (peak memory: 8 bytes per
// entry, 120 MB at 188 k dofs; bench/README.md). Ms must then be released with release_ms
// before Ks. Different patterns (a lumped mass) keep their own arrays.
static void share_pattern(const fmbd_csr *Ks, fmbd_csr *Ms) {
  int64_t n = Ks->nrows;
  if (Ms->nrows != n || Ms->ncols != Ks->ncols ||
      memcmp(Ms->indptr, Ks->indptr, (size_t)(n + 1) * sizeof(int64_t)) != 0 ||
      memcmp(Ms->indices, Ks->indices, (size_t)fmbd_csr_nnz(Ks) * sizeof(int64_t)) != 0)
    return;
  fmbd_free(Ms->indptr);
  fmbd_free(Ms->indices);
  Ms->indptr = Ks->indptr;
  Ms->indices = Ks->indices;
}

// Ks and Ms as lower triangles (fmbd_csr_keep_lower): half their memory, alive beside the
// factor through the whole reduction (bench/README.md "fe2cb's memory"); the products and the
// factorisations read them as the full matrices
static int keep_lower(fmbd_csr *Ks, fmbd_csr *Ms) {
  bool shared = Ms->indices == Ks->indices;
  FMBD_CALL(fmbd_csr_keep_lower(Ks, shared ? Ms : NULL));
  if (!shared) FMBD_CALL(fmbd_csr_keep_lower(Ms, NULL));
  return FMBD_OK;
}

// destroy *Ms (before Ks), leaving index arrays it shares with Ks to Ks
static void release_ms(fmbd_csr **Ms, const fmbd_csr *Ks) {
  if (*Ms && Ks && (*Ms)->indices == Ks->indices) (*Ms)->indptr = (*Ms)->indices = NULL;
  fmbd_csr_destroy(Ms);
}

static bool increasing(const int64_t *v, int64_t n) {
  for (int64_t k = 1; k < n; k++) {
    if (v[k] <= v[k - 1]) return false;
  }
  return true;
}

// K and M, full, on one pattern (the same index arrays, or equal ones)
static bool one_pattern(const fmbd_csr *K, const fmbd_csr *M) {
  if (K->lower || M->lower || K->nrows != M->nrows || K->ncols != M->ncols ||
      fmbd_csr_nnz(K) != fmbd_csr_nnz(M))
    return false;
  if (K->indptr == M->indptr && K->indices == M->indices) return true;
  return !memcmp(K->indptr, M->indptr, (size_t)(K->nrows + 1) * sizeof(int64_t)) &&
         !memcmp(K->indices, M->indices, (size_t)fmbd_csr_nnz(K) * sizeof(int64_t));
}

// The interior blocks: Ks and Ms as lower triangles (keep_lower's form, Ms on Ks's index
// arrays where they are equal: share_pattern), and Kc, Mc (NULL: not formed). Where K and M
// are on one pattern (an fmbd-fe file assembles both on one: mesh2fe) and the dof lists
// increase, one pass over the interior rows forms all four and allocates only what is kept;
// else each block is cut (sub), the pattern shared and the triangles halved. The same entries,
// in the same order, with the same values either way. The one pass saves the full Ks and Ms
// that the cut makes and the halving shrinks (at 51 k dofs about 0.13 s CPU less and the
// partition's peak 262 -> 189 MB: bench/README.md "fe2cb's fixed costs").
//
// Kt, Mt (not NULL: the caller's K and M, given up; on success *Kt and *Mt are NULL): where K
// and M are on the same index arrays, Ks and Ms are written over K's and M's arrays (the kept
// entries in order: each written at or before the place it is read from) and the arrays shrunk
// (fmbd_realloc: the pool takes the tails), so that the partition allocates only Kc and Mc.
// The boundary blocks must be cut before (they read K and M).
static int interior_blocks(const fmbd_csr *K, const fmbd_csr *M, fmbd_csr **Kt, fmbd_csr **Mt,
                           int64_t ns, const int64_t *interior, int64_t nb, const int64_t *boundary,
                           fmbd_csr **Ks, fmbd_csr **Ms, fmbd_csr **Kc, fmbd_csr **Mc) {
  int rc = FMBD_OK;
  int64_t n = K->nrows, *pos = NULL;
  if (!one_pattern(K, M) || !increasing(interior, ns) || !increasing(boundary, nb)) {
    FMBD_CALL(sub(K, ns, interior, ns, interior, Ks));
    FMBD_CALL(sub(M, ns, interior, ns, interior, Ms));
    share_pattern(*Ks, *Ms);
    FMBD_CALL(keep_lower(*Ks, *Ms));
    if (Kc) FMBD_CALL(sub(K, ns, interior, nb, boundary, Kc));
    if (Mc) FMBD_CALL(sub(M, ns, interior, nb, boundary, Mc));
    return FMBD_OK;
  }
  // pos[j]: k for interior[k], -1 - k for boundary[k], INT64_MIN for neither (held dofs)
  FMBD_GALLOC(pos = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
  for (int64_t j = 0; j < n; j++) pos[j] = INT64_MIN;
  for (int64_t k = 0; k < ns; k++) pos[interior[k]] = k;
  for (int64_t k = 0; k < nb; k++) pos[boundary[k]] = -1 - k;
  int64_t nS = 0, nC = 0;
  for (int64_t r = 0; r < ns; r++) {
    int64_t i = interior[r];
    for (int64_t p = K->indptr[i]; p < K->indptr[i + 1]; p++) {
      int64_t q = pos[K->indices[p]];
      if (q >= 0)
        nS += q <= r;
      else
        nC += q != INT64_MIN;
    }
  }
  bool take =
      Kt && Mt && *Kt == K && *Mt == M && K->indptr == M->indptr && K->indices == M->indices;
  if (!take) {
    FMBD_GCALL(fmbd_csr_create(ns, ns, nS, Ks));
    FMBD_GALLOC(*Ms = fmbd_calloc(1, sizeof **Ms));
    (*Ms)->nrows = (*Ms)->ncols = ns;
    FMBD_GALLOC((*Ms)->data = fmbd_malloc((size_t)(nS ? nS : 1) * sizeof(double)));
    (*Ms)->indptr = (*Ks)->indptr;
    (*Ms)->indices = (*Ks)->indices;
    (*Ks)->lower = (*Ms)->lower = true;
  }
  fmbd_csr *C = NULL, *D = NULL;
  if (Kc) {
    FMBD_GCALL(fmbd_csr_create(ns, nb, nC, Kc));
    C = *Kc;
  }
  if (Mc) {
    FMBD_GCALL(fmbd_csr_create(ns, nb, nC, Mc));
    D = *Mc;
  }
  // taken: written over K's and M's own arrays, Si over K's indices, Sx over K's values, Tx over
  // M's (entry nS at or before the entry p it comes from), Sp over K's row starts (Sp[r + 1]
  // over indptr[r + 1], r + 1 <= interior[r + 1]: the next row's start is read before that
  // write, its end later)
  const int64_t *Kp = K->indptr, *Ki = K->indices;
  const double *Kx = K->data, *Mx = M->data;
  int64_t *Si = take ? (*Kt)->indices : (*Ks)->indices, *Sp = take ? (*Kt)->indptr : (*Ks)->indptr;
  double *Sx = take ? (*Kt)->data : (*Ks)->data, *Tx = take ? (*Mt)->data : (*Ms)->data;
  int64_t start = ns ? Kp[interior[0]] : 0;
  nS = nC = 0;
  Sp[0] = 0;
  for (int64_t r = 0; r < ns; r++) {
    int64_t i = interior[r], end = Kp[i + 1];
    for (int64_t p = start; p < end; p++) {
      int64_t q = pos[Ki[p]];
      if (q >= 0) {
        if (q > r) continue;
        double k = Kx[p], m = Mx[p];
        Si[nS] = q;
        Sx[nS] = k;
        Tx[nS++] = m;
      } else if (q != INT64_MIN) {
        if (C) C->indices[nC] = -1 - q, C->data[nC] = Kx[p];
        if (D) D->indices[nC] = -1 - q, D->data[nC] = Mx[p];
        nC++;
      }
    }
    if (r + 1 < ns) start = Kp[interior[r + 1]];
    Sp[r + 1] = nS;
    if (C) C->indptr[r + 1] = nC;
    if (D) D->indptr[r + 1] = nC;
  }
  if (take) {
    // the tails to the pool (a failed shrink keeps the block as it is)
    fmbd_csr *Kw = *Kt, *Mw = *Mt;
    void *t;
    if ((t = fmbd_realloc(Kw->indices, (size_t)(nS ? nS : 1) * sizeof(int64_t)))) Kw->indices = t;
    if ((t = fmbd_realloc(Kw->data, (size_t)(nS ? nS : 1) * sizeof(double)))) Kw->data = t;
    if ((t = fmbd_realloc(Mw->data, (size_t)(nS ? nS : 1) * sizeof(double)))) Mw->data = t;
    if ((t = fmbd_realloc(Kw->indptr, (size_t)(ns + 1) * sizeof(int64_t)))) Kw->indptr = t;
    *Ks = Kw;
    *Ms = Mw;
    *Kt = *Mt = NULL;
    Kw->nrows = Kw->ncols = Mw->nrows = Mw->ncols = ns;
    Mw->indptr = Kw->indptr;
    Mw->indices = Kw->indices;
    Kw->lower = Mw->lower = true;
  }
done:
  fmbd_free(pos);
  return rc;
}

// An unlinked scratch file in $TMPDIR, else tmpfile(3)'s /tmp (a tmpfs /tmp would keep the
// bytes in memory: TMPDIR can point elsewhere); NULL if neither can be made
static FILE *scratch_file(void) {
  const char *d = getenv("TMPDIR");
  char path[4096];
  if (d && *d && snprintf(path, sizeof path, "%s/fmbd-park-XXXXXX", d) < (int)sizeof path) {
    int fd = mkstemp(path);
    if (fd >= 0) {
      unlink(path);
      FILE *f = fdopen(fd, "w+b");
      if (f) return f;
      close(fd);
    }
  }
  return tmpfile();
}

// Arrays parked in an unlinked temporary file (scratch_file) while a stage that does not read
// them runs, and freed: Ks's and Ms's values and their index array from the moment each
// factorisation has formed its input (fmbd_chol_set_input_hook) until it returns, Ks's values
// from the LL' until the Sturm check (back for the residual check only: ks_back_fn), the Ritz
// vectors and the ns x nb projection blocks as each is finished, until the Sturm check has run.
// Each stage's peak then holds those bytes less (bench/README.md "fe2cb's memory"); the file
// lives in the page cache or on disk, not in the process. No file (neither $TMPDIR nor /tmp
// writable) or a failed write: the arrays stay in memory from then on. A parking holds up to 8
// arrays, read back in the order they were parked.
typedef struct {
  FILE *f;
  bool failed;  // no file, or a write failed: nothing more is parked here
  int n;
  struct {
    double **d;  // one of d, i: where the array's pointer lives
    int64_t **i;
    size_t count;
  } a[8];
} parking;

static void park_arr(parking *pk, double **d, int64_t **i, size_t count) {
  void *p = d ? (void *)*d : (void *)*i;
  if (pk->failed || !p || count == 0 || pk->n == 8) return;
  if (!pk->f) pk->f = scratch_file();
  if (!pk->f || fseek(pk->f, 0, SEEK_END) != 0 || fwrite(p, 8, count, pk->f) != count ||
      fflush(pk->f) != 0) {
    pk->failed = true;
    return;
  }
  pk->a[pk->n].d = d;
  pk->a[pk->n].i = i;
  pk->a[pk->n].count = count;
  pk->n++;
  fmbd_free(p);
  if (d) *d = NULL;
  if (i) *i = NULL;
}
static void park_f64(parking *pk, double **a, size_t count) {
  park_arr(pk, a, NULL, count);
}

// the parked arrays back into memory (those not already there); keep: the file and its list
// are kept, so that drop can free them again without a second write
static int unpark(parking *pk, bool keep) {
  bool ok = pk->n == 0 || fseek(pk->f, 0, SEEK_SET) == 0, mem = true;
  for (int k = 0; k < pk->n && ok && mem; k++) {
    if (pk->a[k].d ? *pk->a[k].d != NULL : *pk->a[k].i != NULL) {
      ok = fseek(pk->f, (long)(pk->a[k].count * 8), SEEK_CUR) == 0;
      continue;
    }
    void *p = fmbd_malloc(pk->a[k].count * 8);
    mem = p != NULL;
    if (pk->a[k].d)
      *pk->a[k].d = p;
    else
      *pk->a[k].i = p;
    ok = mem && fread(p, 8, pk->a[k].count, pk->f) == pk->a[k].count;
  }
  if (!keep) {
    if (pk->f) fclose(pk->f);
    memset(pk, 0, sizeof *pk);
  }
  FMBD_CHECK(mem, FMBD_ERR_NOMEM, "out of memory");
  FMBD_CHECK(ok, FMBD_ERR_IO, "cannot read back the arrays parked in a temporary file");
  return FMBD_OK;
}

// the arrays of a parking unparked with keep, freed again (the file still holds them)
static void drop(parking *pk) {
  for (int k = 0; k < pk->n; k++) {
    if (pk->a[k].d) {
      fmbd_free(*pk->a[k].d);
      *pk->a[k].d = NULL;
    } else {
      fmbd_free(*pk->a[k].i);
      *pk->a[k].i = NULL;
    }
  }
}

static void parking_close(parking *pk) {
  if (pk->f) fclose(pk->f);
  memset(pk, 0, sizeof *pk);
}

// fmbd_eig_opts.need_k: Ks's values back for the residual check, the file kept, so that the
// Sturm check's LDL' can drop them again without a second write.
typedef struct {
  parking *pk;
  fmbd_chol *F;
  bool keep;  // the Sturm check follows: the factor's values are kept for its LDL'
} ks_back;
static int ks_back_fn(void *ctx) {
  ks_back *b = ctx;
  // the factor is not read after the Lanczos run (the projections came first, the Sturm check
  // makes its own): its values go, in place of which Ks's come back; should the eigensolver
  // solve again (a residual above its bound: one more run), fmbd_chol factors Ks again first.
  // With a Sturm check to follow, the values' block is kept for its LDL' (no fresh pages to
  // fault), but for as many bytes as Ks's values, given back (bench/README.md "The LL'
  // factor's block for the LDL'")
  if (b->keep) {
    size_t back = 0;
    for (int i = 0; i < b->pk->n; i++) back += b->pk->a[i].count * sizeof(double);
    FMBD_CALL(fmbd_chol_drop_numeric_keep(b->F, back));
  } else {
    FMBD_CALL(fmbd_chol_drop_numeric(b->F));
  }
  return unpark(b->pk, true);
}

// fmbd_chol_set_input_hook of the LL' of Ks and of the Sturm check's LDL' of Ks - s Ms: once
// the factorisation has formed its input, Ks's values and the index array (Ms's too when
// shared) go to the scratch file, and Ms's values if they are in memory (the LL' is of Ks
// alone: Ms's are parked before it). Parkings already holding an array (unparked with keep)
// are dropped without a second write.
typedef struct {
  fmbd_csr *Ks, *Ms;
  parking *vals, *idx, *msvals;
} inputs_away;
static void inputs_away_fn(void *ctx) {
  inputs_away *w = ctx;
  bool shared = w->Ms->indices == w->Ks->indices;
  size_t nnz = (size_t)fmbd_csr_nnz(w->Ks);
  if (w->vals->n)
    drop(w->vals);
  else
    park_f64(w->vals, &w->Ks->data, nnz);
  if (w->idx->n)
    drop(w->idx);
  else
    park_arr(w->idx, NULL, &w->Ks->indices, nnz);
  if (shared && !w->Ks->indices) w->Ms->indices = NULL;
  if (w->Ms->data && w->msvals->n)
    drop(w->msvals);
  else if (w->Ms->data)
    park_f64(w->msvals, &w->Ms->data, (size_t)fmbd_csr_nnz(w->Ms));
}

// C (nb x m, ldc) += S' X  for a sparse S (ns x nb) and dense X (ns x m, ld ns)
static void csr_tmult(const fmbd_csr *S, int64_t m, const double *X, int64_t ns, double *C,
                      int64_t ldc) {
  for (int64_t i = 0; i < S->nrows; i++) {
    for (int64_t p = S->indptr[i]; p < S->indptr[i + 1]; p++) {
      int64_t j = S->indices[p];
      double v = S->data[p];
      for (int64_t c = 0; c < m; c++) C[j + c * ldc] += v * X[i + c * ns];
    }
  }
}

// --- the boundary block of the reduced matrices (fe2cb and the distributed fe2cb-mpi) ----------
int fmbd_cb_condense_boundary(fmbd_cb *cb, const fmbd_csr *Kc, const fmbd_csr *Mc,
                              const fmbd_csr *Kb, const fmbd_csr *Mb) {
  int rc = FMBD_OK;
  int64_t ns = cb->ns, nb = cb->nb;
  fmbd_free(cb->Kr);
  fmbd_free(cb->Mr);
  cb->Kr = cb->Mr = NULL;
  // boundary blocks Kb + Kc' Psi and Psi' A + Mc' Psi + Mb, symmetrised (exactly symmetric in
  // exact arithmetic: Kc' Psi = -Kc' Ks^-1 Kc)
  FMBD_GALLOC(cb->Kr = alloc_f64(nb * nb));
  FMBD_GALLOC(cb->Mr = alloc_f64(nb * nb));
  memset(cb->Kr, 0, (size_t)(nb * nb) * sizeof(double));
  memset(cb->Mr, 0, (size_t)(nb * nb) * sizeof(double));
  for (int64_t i = 0; i < nb; i++) {
    for (int64_t p = Kb->indptr[i]; p < Kb->indptr[i + 1]; p++)
      cb->Kr[i + Kb->indices[p] * nb] = Kb->data[p];
    for (int64_t p = Mb->indptr[i]; p < Mb->indptr[i + 1]; p++)
      cb->Mr[i + Mb->indices[p] * nb] = Mb->data[p];
    // eigenvalue scale of the body for rigid-mode detection without modes (before the
    // condensation, whose round-off is about eps times these entries)
    double kii = fmbd_csr_get(Kb, i, i), mii = fmbd_csr_get(Mb, i, i);
    if (mii > 0.0 && kii / mii > cb->rigid_scale) cb->rigid_scale = kii / mii;
  }
  csr_tmult(Kc, nb, cb->Psi, ns, cb->Kr, nb);
  csr_tmult(Mc, nb, cb->Psi, ns, cb->Mr, nb);
  if (nb > 0) fmbd_dense_gemm('T', 'N', nb, nb, ns, 1.0, cb->Psi, ns, cb->A, ns, 1.0, cb->Mr, nb);
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < j; i++) {
      double k = 0.5 * (cb->Kr[i + j * nb] + cb->Kr[j + i * nb]);
      double m = 0.5 * (cb->Mr[i + j * nb] + cb->Mr[j + i * nb]);
      cb->Kr[i + j * nb] = cb->Kr[j + i * nb] = k;
      cb->Mr[i + j * nb] = cb->Mr[j + i * nb] = m;
    }
  }
  cb->nr = nb;  // the boundary block alone; fmbd_cb_update_reduced adds the modal part
done:
  return rc;
}

static int singular_message(int rc, const fmbd_chol *F, const int64_t *interior,
                            const int64_t *dofs, int64_t nb) {
  int64_t r = fmbd_chol_failed_row(F);
  if (rc != FMBD_ERR_SINGULAR || r < 0) return rc;
  char lab[96];
  fmbd_err_context(NULL, "/K");
  FMBD_FAIL(FMBD_ERR_SINGULAR,
            "the interior stiffness Ks is singular at %s: a region of the body is not held by "
            "the %lld boundary dofs (a floating part, or a mechanism); add an interface or a "
            "--boundary group there",
            dof_label(dofs, interior[r], lab, sizeof lab), (long long)nb);
}

// constraint modes Psi = -Ks^-1 Kc, the projections A = Ms Psi + Mc, Ks^-1 A, Ks^-1 Ms Ks^-1 A
// and the boundary blocks of the reduced matrices, with the factor F of Ks. pk (may be NULL):
// each block is parked there once the steps that read it are done (Psi, A, Ks^-1 A,
// Ks^-1 Ms Ks^-1 A, in that order), so that at most two are in memory beside the factor and
// none beside the Lanczos basis, which comes after (peak memory, bench/README.md "fe2cb's
// memory"); the caller unparks them. The same operations on the same factor, in whichever
// order, so the same numbers.
static int constraint_modes(fmbd_cb *cb, fmbd_chol *F, const fmbd_csr *Ms, const fmbd_csr *Kc,
                            const fmbd_csr *Mc, const fmbd_csr *Kb, const fmbd_csr *Mb,
                            parking *pk) {
  int rc = FMBD_OK;
  int64_t ns = cb->ns, nb = cb->nb;
  size_t blk = (size_t)(ns * nb);
  double t1 = fmbd_wall_s();
  // --- constraint modes Psi = -Ks^-1 Kc: one multi-rhs solve ---
  int64_t s0 = 0;
  {
    fmbd_chol_stats st;
    fmbd_chol_get_stats(F, &st);
    s0 = st.n_solves;
  }
  FMBD_GALLOC(cb->Psi = alloc_f64(ns * nb));
  memset(cb->Psi, 0, blk * sizeof(double));
  for (int64_t i = 0; i < ns; i++) {
    for (int64_t p = Kc->indptr[i]; p < Kc->indptr[i + 1]; p++) {
      cb->Psi[i + Kc->indices[p] * ns] = -Kc->data[p];
    }
  }
  if (nb > 0) {
    if (fmbd_progress_enabled()) fmbd_progress("constraint modes: %lld solves", (long long)nb);
    FMBD_GCALL(fmbd_chol_solve(F, nb, cb->Psi, ns));
  }
  cb->time.constraint = fmbd_wall_s() - t1;

  // --- projections: A, the boundary blocks, Ks^-1 A, Ks^-1 Ms Ks^-1 A ---
  t1 = fmbd_wall_s();
  FMBD_GALLOC(cb->A = alloc_f64(ns * nb));
  if (nb > 0) {
    fmbd_csr_matmat(Ms, nb, cb->Psi, ns, cb->A, ns);
    for (int64_t i = 0; i < ns; i++) {
      for (int64_t p = Mc->indptr[i]; p < Mc->indptr[i + 1]; p++) {
        cb->A[i + Mc->indices[p] * ns] += Mc->data[p];
      }
    }
  }
  // the boundary blocks read Psi and A only (the last step that reads Psi)
  FMBD_GCALL(fmbd_cb_condense_boundary(cb, Kc, Mc, Kb, Mb));
  if (pk) park_f64(pk, &cb->Psi, blk);
  FMBD_GALLOC(cb->KsinvA = alloc_f64(ns * nb));
  memcpy(cb->KsinvA, cb->A, blk * sizeof(double));
  if (pk) park_f64(pk, &cb->A, blk);
  if (nb > 0) {
    if (fmbd_progress_enabled()) fmbd_progress("projections: %lld solves", (long long)(2 * nb));
    FMBD_GCALL(fmbd_chol_solve(F, nb, cb->KsinvA, ns));
  }
  FMBD_GALLOC(cb->KsinvMsKsinvA = alloc_f64(ns * nb));
  if (nb > 0) fmbd_csr_matmat(Ms, nb, cb->KsinvA, ns, cb->KsinvMsKsinvA, ns);
  if (pk) park_f64(pk, &cb->KsinvA, blk);
  if (nb > 0) FMBD_GCALL(fmbd_chol_solve(F, nb, cb->KsinvMsKsinvA, ns));
  if (pk) park_f64(pk, &cb->KsinvMsKsinvA, blk);
  {
    fmbd_chol_stats st;
    fmbd_chol_get_stats(F, &st);
    cb->time.solves += st.n_solves - s0;
  }
  cb->time.projection = fmbd_wall_s() - t1;
done:
  return rc;
}

static void progress_sink(void *ctx, const char *stage, int64_t solves, int64_t nev) {
  (void)ctx;
  fmbd_progress("%s: %lld solves (%lld pairs sought)", stage, (long long)solves, (long long)nev);
}

// the fixed-interface (or held / free) modes
static int modes(const fmbd_csr *Ks, const fmbd_csr *Ms, fmbd_chol *F, const fmbd_cb_opts *o,
                 int64_t nev, double lambda_max, bool free_body, fmbd_eig_result *er) {
  fmbd_eig_opts eo = o->eig;
  if (!free_body) eo.tol = o->fixed_tol;
  eo.nev = nev;
  eo.lambda_max = lambda_max;
  eo.free_body = free_body;
  if (!eo.progress && fmbd_progress_enabled()) eo.progress = progress_sink;
  return fmbd_eig_solve(Ks, Ms, free_body ? NULL : F, &eo, er);
}

static void take_eig_time(fmbd_cb *cb, const fmbd_eig_result *er) {
  cb->time.factor += er->t_factor_s;
  cb->time.lanczos += er->t_lanczos_s;
  cb->time.sturm += er->t_sturm_s;
  cb->time.residuals += er->t_check_s;
  cb->time.solves += er->n_solves;
  cb->time.eig_passes += er->passes;
  cb->sturm_shift = er->sturm_shift;
  cb->sturm_count = er->sturm_count;
  cb->max_residual = 0.0;
  for (int64_t k = 0; k < er->nev; k++) cb->max_residual = fmax(cb->max_residual, er->resid[k]);
}

// current and peak resident memory in MB (Linux /proc; -1 elsewhere): -vv diagnostics
static void mem_log(const char *where) {
  if (fmbd_log_level() < FMBD_LOG_DEBUG) return;
  FILE *f = fopen("/proc/self/status", "r");
  if (!f) return;
  char line[256];
  double rss = -1, hwm = -1;
  while (fgets(line, sizeof line, f)) {
    if (!strncmp(line, "VmHWM:", 6)) hwm = atof(line + 6) / 1024.0;
    if (!strncmp(line, "VmRSS:", 6)) rss = atof(line + 6) / 1024.0;
  }
  fclose(f);
  // process CPU seconds so far (all threads): the stage split in CPU, not only wall
  // (bench/README.md)
  struct rusage ru;
  long flt = getrusage(RUSAGE_SELF, &ru) == 0 ? ru.ru_minflt : -1;
  fmbd_log(FMBD_LOG_DEBUG, "memory %s: %.0f MB resident, %.0f MB peak; %.2f s cpu, %ld page faults",
           where, rss, hwm, fmbd_cpu_s(), flt);
}

static double hz(double lambda) {
  return sqrt(fabs(lambda)) / (2.0 * M_PI);
}

// nm free-free: the lowest flexible modes of the whole body (rigid-body modes removed)
static int reduce_free(const fmbd_csr *K, const fmbd_csr *M, const fmbd_cb_opts *o, fmbd_cb *cb) {
  int rc = FMBD_OK;
  int64_t n = K->nrows;
  fmbd_eig_result er = {0};
  double lmax = o->fmax_hz > 0.0 ? pow(2.0 * M_PI * o->fmax_hz, 2) : 0.0;
  // rigid-body eigenvalues are zeros up to round-off: the leading group of eigenvalues
  // followed by a jump of more than 1e5 (no flexible spectrum has such a gap between
  // neighbours; round-off zeros lie ~1e-8 below the first flexible one)
  double rig_thr = 0.0;
  int64_t extra = 6;  // rigid-body modes expected at most (more: a mechanism, asked again)
  for (int round = 0;; round++) {
    int64_t nev = o->nmodes + extra;
    if (lmax <= 0.0 && nev > n) nev = n;
    fmbd_eig_result_free(&er);
    FMBD_GCALL(modes(K, M, NULL, o, nev, lmax, true, &er));
    int64_t nrig = 0;
    double mk = er.nev > 0 ? fabs(er.lambda[0]) : 0.0;
    for (int64_t k = 1; k < er.nev; k++) {
      if (er.lambda[k] > 1e5 * mk) {
        nrig = k;
        rig_thr = mk;
        break;
      }
      mk = fmax(mk, fabs(er.lambda[k]));
    }
    int64_t nflex = er.nev - nrig;
    if (lmax <= 0.0 && nflex < o->nmodes && nev < n && round < 4) {
      extra = nrig + 6;
      continue;
    }
    if (lmax <= 0.0) {
      FMBD_GCHECK(nflex >= o->nmodes, FMBD_ERR_VALUE,
                  "%lld free-free flexible modes asked for, "
                  "but the body has only %lld (%lld rigid-body modes among %lld dofs)",
                  (long long)o->nmodes, (long long)nflex, (long long)nrig, (long long)n);
      nflex = o->nmodes;
    }
    FMBD_GCHECK(nflex > 0, FMBD_ERR_VALUE,
                "--fmax %g Hz lies below the first flexible mode "
                "(%.6g Hz)",
                o->fmax_hz, isnan(er.next_lambda) ? NAN : hz(er.next_lambda));
    take_eig_time(cb, &er);
    cb->n_rigid_removed = nrig;
    cb->nd = nflex;
    FMBD_GALLOC(cb->kappa = alloc_f64(nflex));
    FMBD_GALLOC(cb->Phi = alloc_f64(n * nflex));
    memcpy(cb->kappa, er.lambda + nrig, (size_t)nflex * sizeof(double));
    memcpy(cb->Phi, er.X + nrig * n, (size_t)(n * nflex) * sizeof(double));
    cb->kappa_next = nrig + nflex < er.nev ? er.lambda[nrig + nflex] : er.next_lambda;
    if (nrig > 0) {
      fmbd_log(FMBD_LOG_INFO,
               "free-free body: %lld rigid-body modes removed (|lambda| <= %.3g, "
               "first flexible %.6g Hz)",
               (long long)nrig, rig_thr, hz(cb->kappa[0]));
    }
    if (nrig > 6) {
      fmbd_log(FMBD_LOG_WARN, "%lld zero-frequency modes: the body is a mechanism",
               (long long)nrig);
    }
    break;
  }
done:
  fmbd_eig_result_free(&er);
  return rc;
}

static int reduce_impl(const fmbd_csr *K, const fmbd_csr *M, fmbd_csr **Kt, fmbd_csr **Mt,
                       const int64_t *dofs, int64_t nb, const int64_t *boundary,
                       const fmbd_cb_opts *oin, fmbd_cb **out);

int fmbd_cb_reduce(const fmbd_csr *K, const fmbd_csr *M, const int64_t *dofs, int64_t nb,
                   const int64_t *boundary, const fmbd_cb_opts *o, fmbd_cb **out) {
  return reduce_impl(K, M, NULL, NULL, dofs, nb, boundary, o, out);
}

int fmbd_cb_reduce_take(fmbd_csr **K, fmbd_csr **M, const int64_t *dofs, int64_t nb,
                        const int64_t *boundary, const fmbd_cb_opts *o, fmbd_cb **out) {
  return reduce_impl(*K, *M, K, M, dofs, nb, boundary, o, out);
}

static int reduce_impl(const fmbd_csr *K, const fmbd_csr *M, fmbd_csr **Kt, fmbd_csr **Mt,
                       const int64_t *dofs, int64_t nb, const int64_t *boundary,
                       const fmbd_cb_opts *oin, fmbd_cb **out) {
  int rc = FMBD_OK;
  fmbd_cb_opts o;
  if (oin) {
    o = *oin;
  } else {
    fmbd_cb_opts_defaults(&o);
  }
  fmbd_cb *cb = NULL;
  fmbd_csr *Ks = NULL, *Kc = NULL, *Kb = NULL, *Ms = NULL, *Mc = NULL, *Mb = NULL;
  fmbd_chol *F = NULL;
  fmbd_eig_result er = {0};
  char *mark = NULL;
  int64_t *perm = NULL;
  // parked arrays: Ks's values, the index array of Ks (and Ms), Ms's values, the projection
  // blocks, the Ritz vectors
  parking pk_ks = {0}, pk_idx = {0}, pk_ms = {0}, pk_blocks = {0}, pk_x = {0};
  *out = NULL;
  int64_t n = K->nrows;
  FMBD_CHECK(o.nmodes >= 0, FMBD_ERR_VALUE, "negative number of modes");
  FMBD_GALLOC(cb = fmbd_calloc(1, sizeof *cb));
  snprintf(cb->method, sizeof cb->method, "%s", o.nm ? "nm" : "cb");
  cb->ndof = n;
  cb->kappa_next = NAN;
  cb->sturm_shift = NAN;
  cb->sturm_count = -1;
  double t0 = fmbd_wall_s();

  // --- partition ---
  FMBD_GALLOC(mark = fmbd_calloc((size_t)(n ? n : 1), 1));
  for (int64_t k = 0; k < nb; k++) {
    FMBD_GCHECK(boundary[k] >= 0 && boundary[k] < n && (k == 0 || boundary[k] > boundary[k - 1]),
                FMBD_ERR_VALUE, "boundary dof list not sorted, unique and in range at %lld",
                (long long)k);
    mark[boundary[k]] = 1;
  }
  if (o.nm && !o.hold) {
    // free-free normal modes of the whole body
    cb->ns = n;
    FMBD_GALLOC(cb->interior = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
    for (int64_t i = 0; i < n; i++) cb->interior[i] = i;
    FMBD_GALLOC(cb->boundary = fmbd_malloc(sizeof(int64_t)));
    cb->nb = 0;
    cb->time.partition = fmbd_wall_s() - t0;
    FMBD_GCALL(reduce_free(K, M, &o, cb));
    FMBD_GCALL(fmbd_cb_update_reduced(cb, o.rigid_rtol));
    *out = cb;
    cb = NULL;
    goto done;
  }
  int64_t ns = n - nb;
  FMBD_GCHECK(ns > 0, FMBD_ERR_VALUE, "every dof of the body is a boundary dof: nothing to reduce");
  cb->ns = ns;
  FMBD_GALLOC(cb->interior = fmbd_malloc((size_t)ns * sizeof(int64_t)));
  FMBD_GALLOC(cb->boundary = fmbd_malloc((size_t)(nb ? nb : 1) * sizeof(int64_t)));
  for (int64_t i = 0, a = 0, b = 0; i < n; i++) {
    if (mark[i])
      cb->boundary[b++] = i;
    else
      cb->interior[a++] = i;
  }
  cb->nb = nb;
  FMBD_GCALL(sub(K, nb, cb->boundary, nb, cb->boundary, &Kb));
  FMBD_GCALL(sub(M, nb, cb->boundary, nb, cb->boundary, &Mb));
  FMBD_GCALL(interior_blocks(K, M, Kt, Mt, ns, cb->interior, nb, cb->boundary, &Ks, &Ms, &Kc, &Mc));
  bool shared = Ms->indices == Ks->indices;
  if (Kt && Mt) {
    // the caller's full matrices are not needed any more: free them (peak memory); M may be
    // on K's index arrays (fmbd_h5_read_csr_like, fmbd_fe_assemble)
    release_ms(Mt, *Kt);
    fmbd_csr_destroy(Kt);
    K = M = NULL;
  }
  cb->time.partition = fmbd_wall_s() - t0;
  if (o.fmax_hz <= 0.0) {
    mem_log("after the partition");
    FMBD_GCHECK(o.nmodes <= ns, FMBD_ERR_VALUE,
                "%lld modes asked for, but the body has only %lld interior dofs (%lld dofs, %lld "
                "on the boundary)",
                (long long)o.nmodes, (long long)ns, (long long)n, (long long)nb);
  }

  // --- the factor of Ks, once ---
  FMBD_GCALL(fmbd_chol_analyze(Ks, NULL, FMBD_CHOL_LLT, &F));
  mem_log("after the analysis");
  // the LL' is of Ks alone: Ms's values parked; Ks's values and the index array too once the
  // LL' input (tril(P Ks P'), fmbd_chol.c) is formed
  park_f64(&pk_ms, &Ms->data, (size_t)fmbd_csr_nnz(Ms));
  inputs_away away = {Ks, Ms, &pk_ks, &pk_idx, &pk_ms};
  fmbd_chol_set_input_hook(inputs_away_fn, &away);
  rc = fmbd_chol_factor(F, 0.0);
  fmbd_chol_set_input_hook(NULL, NULL);
  if (rc) FMBD_GCALL(singular_message(rc, F, cb->interior, dofs, nb));
  fmbd_chol_release_matrix(F);  // factored once: the matrix copy is not needed for solves
  // the index array back (kept in the file: dropped again without a write at the Sturm check)
  FMBD_GCALL(unpark(&pk_idx, true));
  if (shared) Ms->indices = Ks->indices;
  FMBD_GCALL(unpark(&pk_ms, true));  // kept too
  mem_log("after the factorisation");
  {
    fmbd_chol_stats st;
    fmbd_chol_get_stats(F, &st);
    cb->time.ordering = st.t_analyze_s;
    cb->time.factor = st.t_factor_s;
    cb->time.ordering_name = st.ordering;
    cb->time.nnz_l = st.nnz_l;
  }

  double t1;
  if (o.nm) {
    // held normal modes: the boundary dofs are held, not reduced coordinates
    cb->held = cb->boundary;
    cb->nheld = nb;
    cb->nb = nb = 0;
    cb->boundary = NULL;
    FMBD_GALLOC(cb->boundary = fmbd_malloc(sizeof(int64_t)));
    cb->nr = 0;
  }

  // --- fixed-interface modes (the constraint modes and projections first, each block parked
  // as it is finished; then Lanczos with the same factor, whose values are dropped at the
  // residual check; the Sturm check after the factor is freed, since its LDL' factor is as
  // large) ---
  if (o.fmax_hz > 0.0 || o.nmodes > 0) {
    double lmax = o.fmax_hz > 0.0 ? pow(2.0 * M_PI * o.fmax_hz, 2) : 0.0;
    int64_t nev = o.fmax_hz > 0.0 ? (o.nmodes > 0 ? o.nmodes : 20) : o.nmodes;
    fmbd_cb_opts o2 = o;
    o2.eig.sturm = false;
    // below 60 pairs the Lanczos run takes blocks of 4 (fmbd_eig.c), so the widest solves are
    // the Ritz vectors' back solve (nev + a few columns) and the projections (nb): by 8
    // columns, CHOLMOD's two n x w workspaces stay small beside the factor and the basis, for
    // a few more passes over the factor (peak memory: bench/README.md "fe2cb's memory")
    // the projections' solves of nb columns in one pass over the factor while no basis is
    // alive (CHOLMOD's two n x nb workspaces: 36 MB at 188 k dofs and 12 boundary dofs)
    if (nev < 60) fmbd_chol_set_solve_width(F, nb > 8 && nb <= 16 ? nb : 8);
    if (!o.nm) FMBD_GCALL(constraint_modes(cb, F, Ms, Kc, Mc, Kb, Mb, &pk_blocks));
    fmbd_chol_release_workspace(F);
    if (nev < 60) fmbd_chol_set_solve_width(F, 8);
    mem_log("after the constraint modes and projections");
    // Ks's values are not read by the Lanczos iterations (fmbd_eig_opts.need_k: back for the
    // residual check) nor by the projections: parked since the LL' until the Sturm check; the
    // dense path and an iteration over almost all of Ks's spectrum read them
    ks_back kb = {&pk_ks, F, o.eig.sturm};
    if (!(ns > o.eig.dense_max && (o.fmax_hz > 0.0 || nev + 2 < ns)))
      FMBD_GCALL(unpark(&pk_ks, false));
    if (pk_ks.n) {
      o2.eig.need_k = ks_back_fn;
      o2.eig.need_k_ctx = &kb;
    }
    // Ks's values stay in memory from the residual check on (beside the factor's values when
    // the Sturm check follows: ks_back_fn), and the Sturm check reads them
    FMBD_GCALL(modes(Ks, Ms, F, &o2, nev, lmax, false, &er));
    if (o.fmax_hz > 0.0 && er.nev == 0) {
      FMBD_GFAIL(FMBD_ERR_VALUE, "--fmax %g Hz lies below the first fixed-interface mode (%.6g Hz)",
                 o.fmax_hz, hz(er.next_lambda));
    }
    // the Ritz vectors' wide back solve left CHOLMOD's workspaces n x (pairs) large
    fmbd_chol_release_workspace(F);
#ifdef __GLIBC__
    malloc_trim(0);  // the eigensolver's freed work arrays
#endif
    mem_log("after the Lanczos run");
    // the Ritz vectors are read again only after the Sturm check (Phi' A, the output)
    park_f64(&pk_x, &er.X, (size_t)(ns * er.nev));
    if (o.eig.sturm && !er.dense) {
      FMBD_GALLOC(perm = fmbd_malloc((size_t)ns * sizeof(int64_t)));
      FMBD_GCALL(fmbd_chol_get_perm(F, perm));
      // the factor's values go, their block kept for the Sturm check's LDL', which takes it
      // with the analysis (the same pattern and ordering: fmbd_chol_analyze_like)
      FMBD_GCALL(fmbd_chol_drop_numeric_keep(F, 0));
#ifdef __GLIBC__
      malloc_trim(0);  // the factor's freed blocks below glibc's mmap threshold stay resident
#endif
      // Ks's values back (the file kept); the LDL' puts Ks - s Ms into its factor first, then
      // Ks's and Ms's arrays go to the file until it returns (inputs_away_fn)
      if (!Ks->data) FMBD_GCALL(unpark(&pk_ks, true));
      // the pages fmbd_alloc's pool keeps go back too: the LDL' stage's new memory is
      // mostly the LL' block's given-back tail, which the pool cannot supply, so its idle pages
      // would add to the stage's peak (51 k dofs: 268 against 258 MB by -vv)
      fmbd_alloc_pool_trim();
      mem_log("after the Lanczos iterations, the factor freed");
      bool ok = false;
      if (fmbd_progress_enabled())
        fmbd_progress("Sturm check: LDL' factorisation (%lld dofs)", (long long)ns);
      fmbd_chol_set_input_hook(inputs_away_fn, &away);
      rc = fmbd_eig_sturm_check(Ks, Ms, F, &er, &ok);
      fmbd_chol_set_input_hook(NULL, NULL);
      fmbd_chol_destroy(&F);
      FMBD_GCALL(rc);
      if (!ok) {
        // Ks and Ms back, the Ritz vectors dropped (solved again)
        FMBD_GCALL(unpark(&pk_ks, false));
        FMBD_GCALL(unpark(&pk_idx, false));
        if (shared) Ms->indices = Ks->indices;
        FMBD_GCALL(unpark(&pk_ms, false));
        parking_close(&pk_x);
        // a skipped mode, or no gap to place the shift: again with the full checked solver
        fmbd_log(FMBD_LOG_INFO,
                 "Sturm count %lld below %.6g Hz, Lanczos found %lld: solving again "
                 "with the in-loop checks",
                 (long long)er.sturm_count, isnan(er.sturm_shift) ? NAN : hz(er.sturm_shift),
                 (long long)er.nev);
        take_eig_time(cb, &er);
        fmbd_eig_result_free(&er);
        FMBD_GCALL(fmbd_chol_analyze_perm(Ks, NULL, FMBD_CHOL_LLT, perm, &F));
        FMBD_GCALL(fmbd_chol_factor(F, 0.0));
        FMBD_GCALL(modes(Ks, Ms, F, &o, nev, lmax, false, &er));
      }
      mem_log("after the Sturm check");
    }
    FMBD_GCALL(unpark(&pk_x, false));
    FMBD_GCALL(unpark(&pk_blocks, false));
    take_eig_time(cb, &er);
    cb->nd = er.nev;
    cb->kappa = er.lambda;
    cb->Phi = er.X;
    cb->kappa_next = er.next_lambda;
    er.lambda = er.X = NULL;
  } else {
    FMBD_GCALL(unpark(&pk_ks, false));
    if (!o.nm) FMBD_GCALL(constraint_modes(cb, F, Ms, Kc, Mc, Kb, Mb, NULL));
    FMBD_GALLOC(cb->kappa = alloc_f64(0));
    FMBD_GALLOC(cb->Phi = alloc_f64(0));
  }
  fmbd_csr_destroy(&Kc);
  fmbd_csr_destroy(&Mc);
  fmbd_csr_destroy(&Kb);
  fmbd_csr_destroy(&Mb);
  mem_log("after the modes");
  int64_t nd = cb->nd;
  FMBD_GALLOC(cb->PhitA = alloc_f64(nd * nb));
  if (nb > 0 && nd > 0) {
    fmbd_dense_gemm('T', 'N', nd, nb, ns, 1.0, cb->Phi, ns, cb->A, ns, 0.0, cb->PhitA, nd);
  }

  // --- reduced eigensolution ---
  t1 = fmbd_wall_s();
  FMBD_GCALL(fmbd_cb_update_reduced(cb, o.rigid_rtol));
  cb->time.reduced_eig = fmbd_wall_s() - t1;
  if (cb->n_rigid > 0) {
    int64_t first = -1, last = -1;
    for (int64_t i = 0; i < cb->nr; i++) {
      if (cb->rigid[i]) {
        if (first < 0) first = i;
        last = i;
      }
    }
    fmbd_log(FMBD_LOG_INFO,
             "reduced problem: %lld rigid-body modes (modes %lld..%lld, "
             "|chibar| <= %.3g = %.0e kappa_1)",
             (long long)cb->n_rigid, (long long)first + 1, (long long)last + 1,
             o.rigid_rtol * (nd > 0 ? cb->kappa[0] : 0.0), o.rigid_rtol);
  }
  *out = cb;
  cb = NULL;
done:
  fmbd_cb_destroy(&cb);
  release_ms(&Ms, Ks);
  fmbd_csr_destroy(&Ks);
  fmbd_csr_destroy(&Kc);
  fmbd_csr_destroy(&Kb);
  fmbd_csr_destroy(&Mc);
  fmbd_csr_destroy(&Mb);
  fmbd_chol_destroy(&F);
  fmbd_eig_result_free(&er);
  fmbd_free(mark);
  fmbd_free(perm);
  fmbd_chol_set_input_hook(NULL, NULL);
  parking_close(&pk_ks);
  parking_close(&pk_idx);
  parking_close(&pk_ms);
  parking_close(&pk_blocks);
  parking_close(&pk_x);
  return rc;
}

// --- extension of the mode set (cbcheck) --------------------------------------------------------
int fmbd_cb_extend(const fmbd_csr *K, const fmbd_csr *M, fmbd_cb *cb, int64_t nd_new,
                   const fmbd_eig_opts *eig) {
  int rc = FMBD_OK;
  fmbd_csr *Ks = NULL, *Ms = NULL;
  fmbd_chol *F = NULL;
  fmbd_eig_result er = {0};
  double *mx = NULL;
  int64_t ns = cb->ns, nd = cb->nd;
  FMBD_CHECK(!(cb->method[0] == 'n' && cb->nheld == 0), FMBD_ERR_VALUE,
             "free-free normal modes cannot be extended as fixed-interface modes");
  FMBD_CHECK(K->nrows == cb->ndof && M->nrows == cb->ndof, FMBD_ERR_VALUE,
             "FE matrices have %lld dofs, the reduced body %lld", (long long)K->nrows,
             (long long)cb->ndof);
  FMBD_CHECK(nd_new >= 0 && nd_new <= ns, FMBD_ERR_VALUE,
             "%lld modes asked for, but the body has only %lld interior dofs", (long long)nd_new,
             (long long)ns);
  if (nd_new <= nd) {
    // truncation: the lowest nd_new modes stay as they are
    if (nd_new < nd) cb->kappa_next = cb->kappa[nd_new];
    cb->nd = nd_new;
    if (cb->nb > 0) {
      double *P = NULL;
      FMBD_GALLOC(P = alloc_f64(nd_new * cb->nb));
      for (int64_t j = 0; j < cb->nb; j++) {
        for (int64_t k = 0; k < nd_new; k++) P[k + j * nd_new] = cb->PhitA[k + j * nd];
      }
      fmbd_free(cb->PhitA);
      cb->PhitA = P;
    }
    FMBD_GCALL(fmbd_cb_update_reduced(cb, 1e-6));
    goto done;
  }
  FMBD_GCALL(interior_blocks(K, M, NULL, NULL, ns, cb->interior, cb->nb, cb->boundary, &Ks, &Ms,
                             NULL, NULL));
  FMBD_GCALL(fmbd_chol_analyze(Ks, NULL, FMBD_CHOL_LLT, &F));
  rc = fmbd_chol_factor(F, 0.0);
  if (rc) FMBD_GCALL(singular_message(rc, F, cb->interior, NULL, cb->nb));
  fmbd_cb_opts o;
  fmbd_cb_opts_defaults(&o);
  if (eig) o.eig = *eig;
  FMBD_GCALL(modes(Ks, Ms, F, &o, nd_new, 0.0, false, &er));
  FMBD_GCHECK(er.nev == nd_new, FMBD_ERR_CONVERGE, "%lld of %lld modes computed", (long long)er.nev,
              (long long)nd_new);
  // the old modes must be reproduced (ARPACK tol 1e-12: eigenvalues agree far below 1e-8)
  FMBD_GALLOC(mx = alloc_f64(ns));
  for (int64_t k = 0; k < nd; k++) {
    FMBD_GCHECK(fabs(er.lambda[k] - cb->kappa[k]) <= 1e-8 * fabs(cb->kappa[k]), FMBD_ERR_CONVERGE,
                "extending the mode set: mode %lld comes out at %.12g, was %.12g (the FE matrices "
                "do not belong to this reduced body?)",
                (long long)k + 1, er.lambda[k], cb->kappa[k]);
    fmbd_csr_matvec(Ms, cb->Phi + k * ns, mx);
    double s = 0.0;
    for (int64_t i = 0; i < ns; i++) s += mx[i] * er.X[i + k * ns];
    if (s < 0.0) {
      for (int64_t i = 0; i < ns; i++) er.X[i + k * ns] = -er.X[i + k * ns];
    }
  }
  fmbd_free(cb->kappa);
  fmbd_free(cb->Phi);
  cb->kappa = er.lambda;
  cb->Phi = er.X;
  er.lambda = er.X = NULL;
  cb->kappa_next = er.next_lambda;
  cb->nd = nd_new;
  cb->sturm_shift = er.sturm_shift;
  cb->sturm_count = er.sturm_count;
  if (cb->nb > 0) {
    fmbd_free(cb->PhitA);
    cb->PhitA = NULL;
    FMBD_GALLOC(cb->PhitA = alloc_f64(nd_new * cb->nb));
    fmbd_dense_gemm('T', 'N', nd_new, cb->nb, ns, 1.0, cb->Phi, ns, cb->A, ns, 0.0, cb->PhitA,
                    nd_new);
  }
  FMBD_GCALL(fmbd_cb_update_reduced(cb, 1e-6));
done:
  release_ms(&Ms, Ks);
  fmbd_csr_destroy(&Ks);
  fmbd_chol_destroy(&F);
  fmbd_eig_result_free(&er);
  fmbd_free(mx);
  return rc;
}

// --- file I/O -----------------------------------------------------------------------------------
static int write_vec(fmbd_h5 *f, const char *path, int64_t n, const double *v) {
  return fmbd_h5_write_f64(f, path, 1, &n, v);
}
static int write_ivec(fmbd_h5 *f, const char *path, int64_t n, const int64_t *v) {
  return fmbd_h5_write_i64(f, path, 1, &n, v);
}

int fmbd_cb_write(fmbd_h5 *f, const fmbd_cb *cb) {
  int rc = FMBD_OK;
  double *fr = NULL;
  int64_t ns = cb->ns, nb = cb->nb, nd = cb->nd, nr = cb->nr;
  FMBD_GCALL(fmbd_h5_make_group(f, "/cb"));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/cb", "method", cb->method));
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, "/cb", "n_rigid", 1, &cb->n_rigid));
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, "/cb", "n_rigid_removed", 1, &cb->n_rigid_removed));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/cb", "fe_file", cb->fe_file ? cb->fe_file : ""));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/cb", "fe_sha256", cb->fe_sha256));
  // unknown values (NaN) are left out: readers refuse non-finite numbers
  if (isfinite(cb->kappa_next)) {
    FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/cb", "kappa_next", 1, &cb->kappa_next));
  }
  if (isfinite(cb->sturm_shift)) {
    FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/cb", "sturm_shift", 1, &cb->sturm_shift));
    FMBD_GCALL(fmbd_h5_write_attr_i64(f, "/cb", "sturm_count", 1, &cb->sturm_count));
  }
  FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/cb", "max_residual", 1, &cb->max_residual));
  FMBD_GCALL(write_ivec(f, "/cb/interior_dofs", ns, cb->interior));
  FMBD_GCALL(write_ivec(f, "/cb/boundary_dofs", nb, cb->boundary));
  if (cb->nheld > 0) FMBD_GCALL(write_ivec(f, "/cb/held_dofs", cb->nheld, cb->held));
  FMBD_GCALL(write_vec(f, "/cb/kappa", nd, cb->kappa));
  FMBD_GALLOC(fr = alloc_f64(nr > nd ? nr : nd));
  for (int64_t k = 0; k < nd; k++) fr[k] = hz(cb->kappa[k]);
  FMBD_GCALL(write_vec(f, "/cb/frequency_hz", nd, fr));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/Phi", ns, nd, cb->Phi));
  if (strcmp(cb->method, "cb") == 0) {
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/Psi", ns, nb, cb->Psi));
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/A", ns, nb, cb->A));
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/KsinvA", ns, nb, cb->KsinvA));
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/KsinvMsKsinvA", ns, nb, cb->KsinvMsKsinvA));
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cb/PhitA", nd, nb, cb->PhitA));
  }
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/reduced/M", nr, nr, cb->Mr));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/reduced/K", nr, nr, cb->Kr));
  FMBD_GCALL(write_vec(f, "/reduced/eigenvalues", nr, cb->chibar));
  for (int64_t k = 0; k < nr; k++) fr[k] = cb->rigid[k] ? 0.0 : hz(cb->chibar[k]);
  FMBD_GCALL(write_vec(f, "/reduced/frequency_hz", nr, fr));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/reduced/eigenvectors", nr, nr, cb->Xi));
  FMBD_GCALL(write_ivec(f, "/reduced/rigid", nr, cb->rigid));
done:
  fmbd_free(fr);
  return rc;
}

static int read_ivec(fmbd_h5 *f, const char *path, int64_t *n, int64_t **v) {
  int64_t d = -1;
  FMBD_CALL(fmbd_h5_read_i64(f, path, 1, &d, v));
  *n = d;
  return FMBD_OK;
}

static int read_cm(fmbd_h5 *f, const char *path, int64_t rows, int64_t cols, double **A) {
  int64_t r = rows, c = cols;
  return fmbd_h5_read_f64_cm(f, path, &r, &c, A);
}

// basis_only: what a body of the modes needs (fmbd_cb_read_basis), not cbcheck's /cb/A,
// KsinvA, KsinvMsKsinvA, PhitA and /reduced/M, K
static int cb_read(fmbd_h5 *f, bool basis_only, fmbd_cb **out) {
  int rc = FMBD_OK;
  fmbd_cb *cb = NULL;
  char *method = NULL;
  *out = NULL;
  FMBD_GCALL(fmbd_h5_check_format(f, FMBD_CB_FORMAT, FMBD_CB_FORMAT_MAJOR));
  FMBD_GALLOC(cb = fmbd_calloc(1, sizeof *cb));
  FMBD_GCALL(fmbd_h5_read_attr_str(f, "/cb", "method", &method));
  FMBD_GCHECK(!strcmp(method, "cb") || !strcmp(method, "nm"), FMBD_ERR_FORMAT,
              "/cb method \"%s\" is neither cb nor nm", method);
  snprintf(cb->method, sizeof cb->method, "%s", method);
  FMBD_GCALL(fmbd_h5_read_attr_i64(f, "/cb", "n_rigid", 1, &cb->n_rigid));
  cb->kappa_next = NAN;
  cb->sturm_shift = NAN;
  cb->sturm_count = -1;
  if (fmbd_h5_has_attr(f, "/cb", "kappa_next")) {
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/cb", "kappa_next", 1, &cb->kappa_next));
  }
  if (fmbd_h5_has_attr(f, "/cb", "n_rigid_removed")) {
    FMBD_GCALL(fmbd_h5_read_attr_i64(f, "/cb", "n_rigid_removed", 1, &cb->n_rigid_removed));
  }
  if (fmbd_h5_has_attr(f, "/cb", "fe_file")) {
    FMBD_GCALL(fmbd_h5_read_attr_str(f, "/cb", "fe_file", &cb->fe_file));
  }
  if (fmbd_h5_has_attr(f, "/cb", "fe_sha256")) {
    char *s = NULL;
    FMBD_GCALL(fmbd_h5_read_attr_str(f, "/cb", "fe_sha256", &s));
    snprintf(cb->fe_sha256, sizeof cb->fe_sha256, "%s", s);
    fmbd_free(s);
  }
  if (fmbd_h5_has_attr(f, "/cb", "max_residual")) {
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/cb", "max_residual", 1, &cb->max_residual));
  }
  if (fmbd_h5_has_attr(f, "/cb", "sturm_shift")) {
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/cb", "sturm_shift", 1, &cb->sturm_shift));
    FMBD_GCALL(fmbd_h5_read_attr_i64(f, "/cb", "sturm_count", 1, &cb->sturm_count));
  }
  FMBD_GCALL(read_ivec(f, "/cb/interior_dofs", &cb->ns, &cb->interior));
  FMBD_GCALL(read_ivec(f, "/cb/boundary_dofs", &cb->nb, &cb->boundary));
  if (fmbd_h5_exists(f, "/cb/held_dofs")) {
    FMBD_GCALL(read_ivec(f, "/cb/held_dofs", &cb->nheld, &cb->held));
  }
  cb->ndof = cb->ns + cb->nb + cb->nheld;
  int64_t ns = cb->ns, nb = cb->nb;
  // interior, boundary and held dofs partition the rows of /dofs: each exactly once
  if (fmbd_h5_exists(f, "/dofs")) {
    int64_t dd[2] = {-1, 2};
    int64_t *rows = NULL;
    rc = fmbd_h5_read_i64(f, "/dofs", 2, dd, &rows);
    fmbd_free(rows);
    FMBD_GCALL(rc);
    fmbd_err_context(fmbd_h5_name(f), "/cb");
    FMBD_GCHECK(dd[0] == cb->ndof, FMBD_ERR_FORMAT,
                "%lld interior + %lld boundary + %lld held dofs, but /dofs has %lld rows",
                (long long)ns, (long long)nb, (long long)cb->nheld, (long long)dd[0]);
  }
  {
    int64_t *seen = NULL;
    FMBD_GALLOC(seen = fmbd_calloc((size_t)cb->ndof + 1, sizeof *seen));
    const char *lists[3] = {"/cb/interior_dofs", "/cb/boundary_dofs", "/cb/held_dofs"};
    const int64_t *v[3] = {cb->interior, cb->boundary, cb->held}, n[3] = {ns, nb, cb->nheld};
    for (int l = 0; l < 3 && rc == FMBD_OK; l++) {
      for (int64_t k = 0; k < n[l]; k++) {
        int64_t d = v[l][k];
        if (d < 0 || d >= cb->ndof) {
          fmbd_err_context(fmbd_h5_name(f), lists[l]);
          rc = fmbd_err_set(FMBD_ERR_FORMAT, __FILE__, __LINE__, __func__,
                            "entry %lld = %lld out of range 0..%lld (the interior, boundary and "
                            "held dofs number %lld)",
                            (long long)k, (long long)d, (long long)cb->ndof - 1,
                            (long long)cb->ndof);
          break;
        }
        if (seen[d]) {
          fmbd_err_context(fmbd_h5_name(f), lists[l]);
          rc = fmbd_err_set(FMBD_ERR_FORMAT, __FILE__, __LINE__, __func__,
                            "entry %lld: dof %lld is also in %s (the lists must not overlap)",
                            (long long)k, (long long)d, lists[seen[d] - 1]);
          break;
        }
        seen[d] = l + 1;
      }
    }
    fmbd_free(seen);
    FMBD_GCALL(rc);
    fmbd_err_context("", "");
  }
  {
    int64_t d = -1;
    FMBD_GCALL(fmbd_h5_read_f64(f, "/cb/kappa", 1, &d, &cb->kappa));
    cb->nd = d;
  }
  int64_t nd = cb->nd, nr = nd + nb;
  cb->nr = nr;
  FMBD_GCALL(read_cm(f, "/cb/Phi", ns, nd, &cb->Phi));
  if (!strcmp(cb->method, "cb")) {
    FMBD_GCALL(read_cm(f, "/cb/Psi", ns, nb, &cb->Psi));
  }
  if (!strcmp(cb->method, "cb") && !basis_only) {
    FMBD_GCALL(read_cm(f, "/cb/A", ns, nb, &cb->A));
    FMBD_GCALL(read_cm(f, "/cb/KsinvA", ns, nb, &cb->KsinvA));
    FMBD_GCALL(read_cm(f, "/cb/KsinvMsKsinvA", ns, nb, &cb->KsinvMsKsinvA));
    FMBD_GCALL(read_cm(f, "/cb/PhitA", nd, nb, &cb->PhitA));
  }
  if (!basis_only) {
    FMBD_GCALL(read_cm(f, "/reduced/M", nr, nr, &cb->Mr));
    FMBD_GCALL(read_cm(f, "/reduced/K", nr, nr, &cb->Kr));
  }
  {
    int64_t d = nr;
    FMBD_GCALL(fmbd_h5_read_f64(f, "/reduced/eigenvalues", 1, &d, &cb->chibar));
    d = nr;
    FMBD_GCALL(fmbd_h5_read_i64(f, "/reduced/rigid", 1, &d, &cb->rigid));
  }
  FMBD_GCALL(read_cm(f, "/reduced/eigenvectors", nr, nr, &cb->Xi));
  // counts that later arithmetic relies on (a corrupt attribute would otherwise surface as a
  // negative "at most N modes" far downstream)
  {
    int64_t nrig = 0;
    for (int64_t i = 0; i < nr; i++) nrig += cb->rigid[i] != 0;
    fmbd_err_context(fmbd_h5_name(f), "/cb");
    FMBD_GCHECK(cb->n_rigid == nrig, FMBD_ERR_FORMAT,
                "attribute n_rigid = %lld, but /reduced/rigid "
                "flags %lld modes",
                (long long)cb->n_rigid, (long long)nrig);
    FMBD_GCHECK(cb->n_rigid_removed >= 0 && cb->n_rigid_removed <= 6, FMBD_ERR_FORMAT,
                "attribute n_rigid_removed = %lld (0 to 6)", (long long)cb->n_rigid_removed);
    FMBD_GCHECK(nd <= ns, FMBD_ERR_FORMAT,
                "%lld fixed-interface modes (/cb/kappa) for %lld "
                "interior dofs",
                (long long)nd, (long long)ns);
    fmbd_err_context("", "");
  }
  *out = cb;
  cb = NULL;
done:
  fmbd_free(method);
  fmbd_cb_destroy(&cb);
  return rc;
}

int fmbd_cb_read(fmbd_h5 *f, fmbd_cb **out) {
  return cb_read(f, false, out);
}

int fmbd_cb_read_basis(fmbd_h5 *f, fmbd_cb **out) {
  return cb_read(f, true, out);
}
