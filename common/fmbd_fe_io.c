// common/fmbd_fe_io.c: the fmbd-fe file objects (docs/DESIGN.md; docs/FORMAT.md):
// writing, reading with validation, and copying the description into downstream files
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_fe_impl.h"

static int path_of(char *buf, size_t n, const char *prefix, const char *name) {
  FMBD_CHECK(strchr(name, '/') == NULL && name[0] != '\0' && strcmp(name, ".") != 0, FMBD_ERR_VALUE,
             "name \"%s\" cannot be an HDF5 object name (empty or contains '/')", name);
  int k = snprintf(buf, n, "%s/%s", prefix, name);
  FMBD_CHECK(k > 0 && (size_t)k < n, FMBD_ERR_VALUE, "name \"%s\" too long", name);
  return FMBD_OK;
}

int fmbd_fe_write(fmbd_h5 *f, const fmbd_fe_body *b) {
  char path[1024];
  int64_t dims[2];
  // --- /mesh ---
  dims[0] = b->nnodes;
  dims[1] = 3;
  FMBD_CALL(fmbd_h5_write_f64(f, "/mesh/nodes", 2, dims, b->xyz));
  if (b->ntet > 0) {
    dims[0] = b->ntet;
    dims[1] = b->tet_nodes;
    FMBD_CALL(fmbd_h5_write_i64(
        f, b->tet_nodes == 4 ? "/mesh/elements/tet4" : "/mesh/elements/tet10", 2, dims, b->tet));
  }
  if (b->nbeam > 0) {
    dims[0] = b->nbeam;
    dims[1] = 2;
    FMBD_CALL(fmbd_h5_write_i64(f, "/mesh/elements/beam2", 2, dims, b->beam));
    if (b->beam_orientation) {
      dims[1] = 3;
      FMBD_CALL(fmbd_h5_write_f64(f, "/mesh/beam2_orientation", 2, dims, b->beam_orientation));
    }
  }
  FMBD_CALL(fmbd_h5_make_group(f, "/mesh/groups"));
  for (int g = 0; g < b->ngroups; g++) {
    FMBD_CALL(path_of(path, sizeof path, "/mesh/groups", b->group_name[g]));
    dims[0] = b->group_ptr[g + 1] - b->group_ptr[g];
    FMBD_CALL(fmbd_h5_write_i64(f, path, 1, dims, b->group_node + b->group_ptr[g]));
  }
  dims[0] = b->nnodes;
  FMBD_CALL(fmbd_h5_write_f64(f, "/mesh/node_mass", 1, dims, b->node_mass));
  // --- /material ---
  FMBD_CALL(fmbd_h5_make_group(f, "/material"));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "E", 1, &b->E));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "nu", 1, &b->nu));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "rho", 1, &b->rho));
  FMBD_CALL(fmbd_h5_write_attr_str(f, "/material", "mass",
                                   b->mass_kind == FMBD_FE_MASS_LUMPED ? "lumped" : "consistent"));
  if (b->has_section) {
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "area", 1, &b->area));
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "Iy", 1, &b->Iy));
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "Iz", 1, &b->Iz));
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/material", "J", 1, &b->J));
  }
  // --- /dofs, matrices ---
  dims[0] = b->ndof;
  dims[1] = 2;
  FMBD_CALL(fmbd_h5_write_i64(f, "/dofs", 2, dims, b->dofs));
  if (b->K) FMBD_CALL(fmbd_h5_write_csr(f, "/K", b->K));
  // M on K's pattern (mesh2fe assembles both on one): its indices and indptr written once, as
  // hard links to K's (docs/FORMAT.md), so readers inflate them once
  if (b->M && b->K && !b->M->lower && b->M->nrows == b->K->nrows && b->M->ncols == b->K->ncols &&
      fmbd_csr_nnz(b->M) == fmbd_csr_nnz(b->K) &&
      (b->M->indices == b->K->indices ||
       (!memcmp(b->M->indptr, b->K->indptr, (size_t)(b->K->nrows + 1) * sizeof(int64_t)) &&
        !memcmp(b->M->indices, b->K->indices, (size_t)fmbd_csr_nnz(b->K) * sizeof(int64_t)))))
    FMBD_CALL(fmbd_h5_write_csr_like(f, "/M", b->M, "/K"));
  else if (b->M)
    FMBD_CALL(fmbd_h5_write_csr(f, "/M", b->M));
  FMBD_CALL(fmbd_h5_write_csr(f, "/expand", b->expand));
  // --- /interfaces, /clamped ---
  FMBD_CALL(fmbd_h5_make_group(f, "/interfaces"));
  for (int i = 0; i < b->ninterfaces; i++) {
    const fmbd_fe_interface *it = &b->interfaces[i];
    FMBD_CALL(path_of(path, sizeof path, "/interfaces", it->name));
    FMBD_CALL(fmbd_h5_make_group(f, path));
    FMBD_CALL(fmbd_h5_write_attr_i64(f, path, "node", 1, &it->node));
    FMBD_CALL(fmbd_h5_write_attr_str(f, path, "kind", it->kind == FMBD_FE_RBE3 ? "rbe3" : "rbe2"));
    FMBD_CALL(fmbd_h5_write_attr_f64(f, path, "point", 3, it->point));
    char dpath[1100];
    snprintf(dpath, sizeof dpath, "%s/nodes", path);
    dims[0] = it->nnodes;
    FMBD_CALL(fmbd_h5_write_i64(f, dpath, 1, dims, it->nodes));
  }
  FMBD_CALL(fmbd_h5_make_group(f, "/clamped"));
  for (int i = 0; i < b->nclamped; i++) {
    FMBD_CALL(path_of(path, sizeof path, "/clamped", b->clamped[i].name));
    dims[0] = b->clamped[i].nnodes;
    FMBD_CALL(fmbd_h5_write_i64(f, path, 1, dims, b->clamped[i].nodes));
  }
  // --- /body ---
  FMBD_CALL(fmbd_h5_make_group(f, "/body"));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/body", "mass", 1, &b->mass));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/body", "center_of_mass", 3, b->center_of_mass));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/body", "inertia", 9, b->inertia));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/body", "volume", 1, &b->volume));
  return FMBD_OK;
}

// Fail with the file and path as context
#define RFAIL(path, ...)                      \
  do {                                        \
    fmbd_err_context(fmbd_h5_name(f), path);  \
    FMBD_GFAIL(FMBD_ERR_FORMAT, __VA_ARGS__); \
  } while (0)

static int check_nodes(fmbd_h5 *f, const char *path, int64_t n, const int64_t *v, int64_t nn) {
  for (int64_t i = 0; i < n; i++) {
    if (v[i] < 0 || v[i] >= nn) {
      fmbd_err_context(fmbd_h5_name(f), path);
      FMBD_FAIL(FMBD_ERR_FORMAT, "entry %lld: node %lld out of range (%lld nodes)", (long long)i,
                (long long)v[i], (long long)nn);
    }
  }
  return FMBD_OK;
}

// what fe_read reads: everything, everything but /K and /M, or /K and /M only
typedef enum { READ_ALL, READ_DESCRIPTION, READ_MATRICES } read_what;

// /K and /M only (ndof from /K's shape): for a caller that checked the file otherwise (cbcheck:
// its SHA-256 is the one fe2cb recorded, so fe2cb read and validated this very file whole)
static int fe_read_matrices(fmbd_h5 *f, fmbd_fe_body *b) {
  int rc = FMBD_OK;
  FMBD_GCALL(fmbd_h5_read_csr(f, "/K", &b->K));
  if (b->K->nrows != b->K->ncols) {
    RFAIL("/K", "shape (%lld, %lld) is not square", (long long)b->K->nrows, (long long)b->K->ncols);
  }
  b->ndof = b->K->nrows;
  // M on K's pattern arrays where the file links them (one pattern in memory, as
  // fmbd_fe_assemble's body; fmbd_fe_body_destroy frees it once)
  FMBD_GCALL(fmbd_h5_read_csr_like(f, "/M", b->K, "/K", true, &b->M));
  if (b->M->nrows != b->ndof || b->M->ncols != b->ndof) {
    RFAIL("/M", "shape (%lld, %lld), expected (%lld, %lld) from /K", (long long)b->M->nrows,
          (long long)b->M->ncols, (long long)b->ndof, (long long)b->ndof);
  }
done:
  return rc;
}

static int fe_read(fmbd_h5 *f, read_what what, fmbd_fe_body **out) {
  const bool matrices = what != READ_DESCRIPTION;
  int rc = FMBD_OK;
  fmbd_fe_body *b = NULL;
  int nnames = 0;
  char **names = NULL;
  char *str = NULL;
  char path[1024];
  int64_t dims[2];
  FMBD_GALLOC(b = fmbd_calloc(1, sizeof *b));
  if (what == READ_MATRICES) {
    FMBD_GCALL(fe_read_matrices(f, b));
    goto out;
  }
  // --- /mesh ---
  dims[0] = -1;
  dims[1] = 3;
  FMBD_GCALL(fmbd_h5_read_f64(f, "/mesh/nodes", 2, dims, &b->xyz));
  b->nnodes = dims[0];
  bool t4 = fmbd_h5_exists(f, "/mesh/elements/tet4"),
       t10 = fmbd_h5_exists(f, "/mesh/elements/tet10");
  if (t4 && t10)
    RFAIL("/mesh/elements", "both tet4 and tet10 elements (mixed orders are not supported)");
  if (t4 || t10) {
    const char *p = t4 ? "/mesh/elements/tet4" : "/mesh/elements/tet10";
    dims[0] = -1;
    dims[1] = t4 ? 4 : 10;
    FMBD_GCALL(fmbd_h5_read_i64(f, p, 2, dims, &b->tet));
    b->ntet = dims[0];
    b->tet_nodes = t4 ? 4 : 10;
    FMBD_GCALL(check_nodes(f, p, b->ntet * b->tet_nodes, b->tet, b->nnodes));
  }
  if (fmbd_h5_exists(f, "/mesh/elements/beam2")) {
    dims[0] = -1;
    dims[1] = 2;
    FMBD_GCALL(fmbd_h5_read_i64(f, "/mesh/elements/beam2", 2, dims, &b->beam));
    b->nbeam = dims[0];
    FMBD_GCALL(check_nodes(f, "/mesh/elements/beam2", 2 * b->nbeam, b->beam, b->nnodes));
    if (fmbd_h5_exists(f, "/mesh/beam2_orientation")) {
      dims[0] = b->nbeam;
      dims[1] = 3;
      FMBD_GCALL(fmbd_h5_read_f64(f, "/mesh/beam2_orientation", 2, dims, &b->beam_orientation));
    }
  }
  FMBD_GCALL(fmbd_h5_list(f, "/mesh/groups", &nnames, &names));
  b->ngroups = nnames;
  FMBD_GALLOC(b->group_ptr = fmbd_calloc((size_t)nnames + 1, sizeof *b->group_ptr));
  FMBD_GALLOC(b->group_name = fmbd_calloc((size_t)nnames + 1, sizeof *b->group_name));
  FMBD_GALLOC(b->group_node = fmbd_malloc(sizeof *b->group_node));
  for (int g = 0; g < nnames; g++) {
    int64_t *v = NULL;
    b->group_name[g] = names[g];
    names[g] = NULL;
    FMBD_GCALL(path_of(path, sizeof path, "/mesh/groups", b->group_name[g]));
    dims[0] = -1;
    FMBD_GCALL(fmbd_h5_read_i64(f, path, 1, dims, &v));
    b->group_ptr[g + 1] = b->group_ptr[g] + dims[0];
    int64_t *grown = fmbd_realloc(b->group_node, (size_t)(b->group_ptr[g + 1] + 1) * sizeof *grown);
    if (!grown) {
      fmbd_free(v);
      FMBD_GFAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    b->group_node = grown;
    memcpy(b->group_node + b->group_ptr[g], v, (size_t)dims[0] * sizeof *v);
    fmbd_free(v);
    FMBD_GCALL(check_nodes(f, path, dims[0], b->group_node + b->group_ptr[g], b->nnodes));
  }
  fmbd_free(names);
  names = NULL;
  nnames = 0;
  dims[0] = b->nnodes;
  FMBD_GCALL(fmbd_h5_read_f64(f, "/mesh/node_mass", 1, dims, &b->node_mass));
  // --- /material ---
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "E", 1, &b->E));
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "nu", 1, &b->nu));
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "rho", 1, &b->rho));
  if (!(b->E > 0 && isfinite(b->E))) RFAIL("/material", "E = %g must be positive", b->E);
  if (!(b->nu > -1 && b->nu < 0.5)) RFAIL("/material", "nu = %g must lie in (-1, 0.5)", b->nu);
  if (!(b->rho > 0 && isfinite(b->rho))) RFAIL("/material", "rho = %g must be positive", b->rho);
  FMBD_GCALL(fmbd_h5_read_attr_str(f, "/material", "mass", &str));
  if (strcmp(str, "consistent") == 0) {
    b->mass_kind = FMBD_FE_MASS_CONSISTENT;
  } else if (strcmp(str, "lumped") == 0) {
    b->mass_kind = FMBD_FE_MASS_LUMPED;
  } else {
    RFAIL("/material", "attribute mass = \"%s\" (consistent or lumped)", str);
  }
  fmbd_free(str);
  str = NULL;
  if (fmbd_h5_has_attr(f, "/material", "area")) {
    b->has_section = true;
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "area", 1, &b->area));
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "Iy", 1, &b->Iy));
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "Iz", 1, &b->Iz));
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/material", "J", 1, &b->J));
  } else if (b->nbeam > 0) {
    RFAIL("/material", "beam elements but no section attributes area, Iy, Iz, J");
  }
  // --- /dofs ---
  dims[0] = -1;
  dims[1] = 2;
  FMBD_GCALL(fmbd_h5_read_i64(f, "/dofs", 2, dims, &b->dofs));
  b->ndof = dims[0];
  rc = fmbd_fe_index_dofs(b);
  if (rc) {
    fmbd_err_context(fmbd_h5_name(f), "/dofs");
    goto done;
  }
  // --- matrices ---
  if (matrices && fmbd_h5_exists(f, "/K")) {
    FMBD_GCALL(fmbd_h5_read_csr(f, "/K", &b->K));
    if (b->K->nrows != b->ndof || b->K->ncols != b->ndof) {
      RFAIL("/K", "shape (%lld, %lld), expected (%lld, %lld) from /dofs", (long long)b->K->nrows,
            (long long)b->K->ncols, (long long)b->ndof, (long long)b->ndof);
    }
  }
  if (matrices && fmbd_h5_exists(f, "/M")) {
    // M on K's pattern arrays here too (fe2cb: 33 MB of fresh pages less at 51 k dofs, the
    // read's peak 143 -> 113 MB; its reduction releases M before K; fmbd-run and gmsolve only
    // read them; bench/README.md "fe2cb's fixed costs")
    FMBD_GCALL(fmbd_h5_read_csr_like(f, "/M", b->K, "/K", true, &b->M));
    if (b->M->nrows != b->ndof || b->M->ncols != b->ndof) {
      RFAIL("/M", "shape (%lld, %lld), expected (%lld, %lld) from /dofs", (long long)b->M->nrows,
            (long long)b->M->ncols, (long long)b->ndof, (long long)b->ndof);
    }
  }
  FMBD_GCALL(fmbd_h5_read_csr(f, "/expand", &b->expand));
  if (b->expand->nrows != 6 * b->nnodes || b->expand->ncols != b->ndof) {
    RFAIL("/expand", "shape (%lld, %lld), expected (%lld, %lld)", (long long)b->expand->nrows,
          (long long)b->expand->ncols, (long long)(6 * b->nnodes), (long long)b->ndof);
  }
  // --- /interfaces ---
  FMBD_GCALL(fmbd_h5_list(f, "/interfaces", &nnames, &names));
  b->nmesh_nodes = b->nnodes;
  if (nnames > 0) FMBD_GALLOC(b->interfaces = fmbd_calloc((size_t)nnames, sizeof *b->interfaces));
  for (int i = 0; i < nnames; i++) {
    fmbd_fe_interface *it = &b->interfaces[i];
    it->name = names[i];
    names[i] = NULL;
    b->ninterfaces = i + 1;
    FMBD_GCALL(path_of(path, sizeof path, "/interfaces", it->name));
    FMBD_GCALL(fmbd_h5_read_attr_i64(f, path, "node", 1, &it->node));
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, path, "point", 3, it->point));
    FMBD_GCALL(fmbd_h5_read_attr_str(f, path, "kind", &str));
    if (strcmp(str, "rbe2") == 0) {
      it->kind = FMBD_FE_RBE2;
    } else if (strcmp(str, "rbe3") == 0) {
      it->kind = FMBD_FE_RBE3;
    } else {
      RFAIL(path, "attribute kind = \"%s\" (rbe2 or rbe3)", str);
    }
    fmbd_free(str);
    str = NULL;
    if (it->node < 0 || it->node >= b->nnodes) {
      RFAIL(path, "attribute node = %lld out of range (%lld nodes)", (long long)it->node,
            (long long)b->nnodes);
    }
    if (it->node < b->nmesh_nodes) b->nmesh_nodes = it->node;
    char dpath[1100];
    snprintf(dpath, sizeof dpath, "%s/nodes", path);
    dims[0] = -1;
    FMBD_GCALL(fmbd_h5_read_i64(f, dpath, 1, dims, &it->nodes));
    it->nnodes = dims[0];
    FMBD_GCALL(check_nodes(f, dpath, it->nnodes, it->nodes, b->nnodes));
  }
  fmbd_free(names);
  names = NULL;
  nnames = 0;
  // --- /clamped ---
  FMBD_GCALL(fmbd_h5_list(f, "/clamped", &nnames, &names));
  if (nnames > 0) FMBD_GALLOC(b->clamped = fmbd_calloc((size_t)nnames, sizeof *b->clamped));
  for (int i = 0; i < nnames; i++) {
    fmbd_fe_clamp *c = &b->clamped[i];
    c->name = names[i];
    names[i] = NULL;
    b->nclamped = i + 1;
    FMBD_GCALL(path_of(path, sizeof path, "/clamped", c->name));
    dims[0] = -1;
    FMBD_GCALL(fmbd_h5_read_i64(f, path, 1, dims, &c->nodes));
    c->nnodes = dims[0];
    FMBD_GCALL(check_nodes(f, path, c->nnodes, c->nodes, b->nnodes));
  }
  // --- /body ---
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/body", "mass", 1, &b->mass));
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/body", "center_of_mass", 3, b->center_of_mass));
  FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/body", "inertia", 9, b->inertia));
  if (!(b->mass > 0 && isfinite(b->mass))) RFAIL("/body", "mass = %g must be positive", b->mass);
  {
    const char *why = NULL;
    if (!fmbd_dense_inertia_ok(b->inertia, &why))
      RFAIL("/body", "inertia is not physical: %s", why);
  }
  if (fmbd_h5_has_attr(f, "/body", "volume")) {
    FMBD_GCALL(fmbd_h5_read_attr_f64(f, "/body", "volume", 1, &b->volume));
  }
out:
  *out = b;
  b = NULL;
done:
  if (names) {
    for (int i = 0; i < nnames; i++) fmbd_free(names[i]);
  }
  fmbd_free(names);
  fmbd_free(str);
  fmbd_fe_body_destroy(&b);
  return rc;
}

int fmbd_fe_read(fmbd_h5 *f, fmbd_fe_body **out) {
  return fe_read(f, READ_ALL, out);
}

int fmbd_fe_read_description(fmbd_h5 *f, fmbd_fe_body **out) {
  return fe_read(f, READ_DESCRIPTION, out);
}

int fmbd_fe_read_matrices(fmbd_h5 *f, fmbd_fe_body **out) {
  return fe_read(f, READ_MATRICES, out);
}

int fmbd_fe_copy_description(fmbd_h5 *src, fmbd_h5 *dst) {
  // required: a missing one fails with "missing object to copy" naming src and the path
  static const char *const required[] = {"/mesh", "/dofs", "/material", "/body", "/expand"};
  static const char *const optional[] = {"/interfaces", "/clamped"};
  for (size_t i = 0; i < sizeof required / sizeof *required; i++) {
    FMBD_CALL(fmbd_h5_copy(src, required[i], dst));
  }
  for (size_t i = 0; i < sizeof optional / sizeof *optional; i++) {
    if (fmbd_h5_exists(src, optional[i])) FMBD_CALL(fmbd_h5_copy(src, optional[i], dst));
  }
  return FMBD_OK;
}
