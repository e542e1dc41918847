// common/fmbd_mesh_read.c: reading geometry and meshes (fmbd_mesh_read: the gmsh C API, and STL /
// OFF surfaces filled through the meshing callback). Apart from fmbd_mesh.c so that only the
// programs that mesh (mesh2fe) load gmsh and its libraries: the others link with --as-needed
// and start 0.1 s faster (bench/README.md, cbcheck).
// SPDX-License-Identifier: MIT
//
// gmsh 4.8 C API notes (docs/TOOLCHAIN.md section 3a, gotcha 7): gmshInitialize has no `run`
// argument before 4.9; every returned array is released with gmshFree; node and element tags need
// not be contiguous, so node tags are mapped to indices (a dense table when the tags are dense, a
// sorted table with binary search otherwise).
#include <ctype.h>
#include <errno.h>
#include <gmshc.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_log.h"
#include "fmbd_mesh.h"
#include "fmbd_mesh_impl.h"

// --- gmsh ------------------------------------------------------------------------------------

static void gmsh_init(int *ierr) {
#if GMSH_API_VERSION_MAJOR == 4 && GMSH_API_VERSION_MINOR < 9
  gmshInitialize(0, NULL, 0, ierr);
#else
  gmshInitialize(0, NULL, 0, 0, ierr);
#endif
}

// gmsh's last error message into buf ("" if none)
static void gmsh_last_error(char *buf, size_t n) {
  int ierr = 0;
  char *e = NULL;
  buf[0] = '\0';
  gmshLoggerGetLastError(&e, &ierr);
  if (!ierr && e) {
    snprintf(buf, n, "%s", e);
  }
  if (e) {
    gmshFree(e);
  }
}

// node tag -> index table
typedef struct tag_map {
  int64_t n;
  size_t maxtag;
  int64_t *dense;  // dense[tag] = index or -1 (when tags are dense)
  size_t *stag;    // sorted tags (else)
  int64_t *sidx;   // their indices
} tag_map;

static const size_t *g_sort_tags;  // for the qsort comparator below (single-threaded use)
static int cmp_by_tag(const void *a, const void *b) {
  size_t x = g_sort_tags[*(const int64_t *)a], y = g_sort_tags[*(const int64_t *)b];
  return (x > y) - (x < y);
}

static int tag_map_build(tag_map *tm, const size_t *tags, int64_t n) {
  memset(tm, 0, sizeof *tm);
  tm->n = n;
  size_t mx = 0;
  for (int64_t i = 0; i < n; i++) {
    mx = tags[i] > mx ? tags[i] : mx;
  }
  tm->maxtag = mx;
  if (mx <= (size_t)(4 * n + 1024)) {
    tm->dense = fmbd_malloc((mx + 1) * sizeof *tm->dense);
    if (!tm->dense) {
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    for (size_t t = 0; t <= mx; t++) {
      tm->dense[t] = -1;
    }
    for (int64_t i = 0; i < n; i++) {
      tm->dense[tags[i]] = i;
    }
    return FMBD_OK;
  }
  tm->stag = fmbd_malloc((size_t)(n + 1) * sizeof *tm->stag);
  tm->sidx = fmbd_malloc((size_t)(n + 1) * sizeof *tm->sidx);
  if (!tm->stag || !tm->sidx) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t i = 0; i < n; i++) {
    tm->sidx[i] = i;
  }
  g_sort_tags = tags;
  qsort(tm->sidx, (size_t)n, sizeof *tm->sidx, cmp_by_tag);
  for (int64_t i = 0; i < n; i++) {
    tm->stag[i] = tags[tm->sidx[i]];
  }
  return FMBD_OK;
}

static int64_t tag_map_get(const tag_map *tm, size_t tag) {
  if (tm->dense) {
    return tag <= tm->maxtag ? tm->dense[tag] : -1;
  }
  int64_t lo = 0, hi = tm->n - 1;
  while (lo <= hi) {
    int64_t mid = lo + (hi - lo) / 2;
    if (tm->stag[mid] == tag) {
      return tm->sidx[mid];
    }
    if (tm->stag[mid] < tag) {
      lo = mid + 1;
    } else {
      hi = mid - 1;
    }
  }
  return -1;
}

static void tag_map_free(tag_map *tm) {
  fmbd_free(tm->dense);
  fmbd_free(tm->stag);
  fmbd_free(tm->sidx);
  memset(tm, 0, sizeof *tm);
}

// gmsh element types used here
enum { GMSH_LINE2 = 1, GMSH_TET4 = 4, GMSH_POINT = 15, GMSH_LINE3 = 8, GMSH_TET10 = 11 };

// the gmsh side of fmbd_mesh_read; gmsh is initialised and finalised by the caller
static int read_gmsh(const char *path, int is_msh, const fmbd_mesh_opts *opt, fmbd_mesh *m) {
  int rc = FMBD_OK, ierr = 0;
  char gerr[512];
  size_t *ntag = NULL, nn = 0, ncoord = 0, npar = 0;
  double *coord = NULL, *par = NULL;
  int *types = NULL, *pg = NULL;
  size_t ntypes = 0, npg = 0;
  size_t *etag = NULL, ne = 0, *enode = NULL, nen = 0;
  size_t *kept_tag = NULL;  // gmsh tags of the kept elements (messages)
  unsigned char *use = NULL, *keep = NULL;
  int64_t *tmp = NULL;
  char *pname = NULL;
  tag_map tm = {0};

  gmshOpen(path, &ierr);
  if (ierr) {
    gmsh_last_error(gerr, sizeof gerr);
    FMBD_GFAIL(FMBD_ERR_FORMAT, "gmsh cannot read the file%s%s", gerr[0] ? ": " : "", gerr);
  }
  // --- mesh the geometry ---
  if (!is_msh) {
    int dim = gmshModelGetDimension(&ierr);
    if (opt->size > 0) {
      gmshOptionSetNumber("Mesh.MeshSizeMin", opt->size, &ierr);
      gmshOptionSetNumber("Mesh.MeshSizeMax", opt->size, &ierr);
    }
    if (dim == 3) {
      fmbd_progress("meshing %s: 3-D", path);
      gmshModelMeshGenerate(3, &ierr);
      if (!ierr && (opt->order == 0 || opt->order == 2)) {
        fmbd_progress("meshing %s: second order", path);
        gmshModelMeshSetOrder(2, &ierr);
      }
    } else if (dim == 1) {
      fmbd_progress("meshing %s: 1-D (beams)", path);
      gmshModelMeshGenerate(1, &ierr);
    } else if (dim == 2) {
      FMBD_GFAIL(FMBD_ERR_FORMAT,
                 "the geometry has surfaces but no volume: mesh2fe meshes solids (volumes) "
                 "into tetrahedra, or curves alone into beams");
    } else {
      FMBD_GFAIL(FMBD_ERR_FORMAT, "the geometry is empty (dimension %d)", dim);
    }
    fmbd_progress(NULL);
    if (ierr) {
      gmsh_last_error(gerr, sizeof gerr);
      FMBD_GFAIL(FMBD_ERR_EXTERNAL, "gmsh failed to mesh the geometry%s%s", gerr[0] ? ": " : "",
                 gerr);
    }
  }
  // --- nodes ---
  gmshModelMeshGetNodes(&ntag, &nn, &coord, &ncoord, &par, &npar, -1, -1, 0, 0, &ierr);
  if (ierr) {
    gmsh_last_error(gerr, sizeof gerr);
    FMBD_GFAIL(FMBD_ERR_EXTERNAL, "gmsh: cannot get the nodes: %s", gerr);
  }
  FMBD_GCALL(tag_map_build(&tm, ntag, (int64_t)nn));
  // --- element types: tetrahedra, else lines ---
  gmshModelMeshGetElementTypes(&types, &ntypes, -1, -1, &ierr);
  if (ierr) {
    gmsh_last_error(gerr, sizeof gerr);
    FMBD_GFAIL(FMBD_ERR_EXTERNAL, "gmsh: cannot get the element types: %s", gerr);
  }
  int vol_type = 0, line_types = 0, has_surface = 0;
  for (size_t i = 0; i < ntypes; i++) {
    char *name = NULL;
    double *lc = NULL;
    size_t nlc = 0;
    int edim = 0, eorder = 0, enn = 0, nprim = 0;
    gmshModelMeshGetElementProperties(types[i], &name, &edim, &eorder, &enn, &lc, &nlc, &nprim,
                                      &ierr);
    char tname[128];
    snprintf(tname, sizeof tname, "%s", name ? name : "?");
    if (name) {
      gmshFree(name);
    }
    if (lc) {
      gmshFree(lc);
    }
    if (edim == 3) {
      if (types[i] != GMSH_TET4 && types[i] != GMSH_TET10) {
        FMBD_GFAIL(FMBD_ERR_FORMAT,
                   "element type '%s' (gmsh type %d) is not supported: tetrahedra (4 or 10 "
                   "nodes) only",
                   tname, types[i]);
      }
      if (vol_type && vol_type != types[i]) {
        FMBD_GFAIL(FMBD_ERR_FORMAT, "the mesh mixes 4-node and 10-node tetrahedra");
      }
      vol_type = types[i];
    } else if (edim == 2) {
      has_surface = 1;
    } else if (edim == 1) {
      if (types[i] == GMSH_LINE2) {
        line_types |= 1;
      } else if (types[i] == GMSH_LINE3) {
        line_types |= 2;
      } else {
        line_types |= 4;
      }
    }
  }
  if (!vol_type && !line_types) {
    FMBD_GFAIL(FMBD_ERR_FORMAT, "no volume (tetrahedron) or beam (line) elements%s",
               has_surface ? " (surface elements only; a .msh saved with physical groups keeps "
                             "only their elements: add a Physical Volume, or save with "
                             "Mesh.SaveAll=1)"
                           : "");
  }
  if (!vol_type && (line_types & 4)) {
    FMBD_GFAIL(FMBD_ERR_FORMAT, "line elements of order > 2 are not supported (beams are 2-node)");
  }
  // --- mark each node: 3 = on a kept element, 2 = on another element of dimension >= 1,
  //     1 = on point elements only, 0 = on no element ---
  FMBD_GALLOC(use = fmbd_calloc(nn + 1, 1));
  for (size_t i = 0; i < ntypes; i++) {
    int is_kept =
        vol_type ? types[i] == vol_type : (types[i] == GMSH_LINE2 || types[i] == GMSH_LINE3);
    unsigned char level = is_kept ? 3 : types[i] == GMSH_POINT ? 1 : 2;
    gmshModelMeshGetElementsByType(types[i], &etag, &ne, &enode, &nen, -1, 0, 1, &ierr);
    if (ierr) {
      gmsh_last_error(gerr, sizeof gerr);
      FMBD_GFAIL(FMBD_ERR_EXTERNAL, "gmsh: cannot get elements of type %d: %s", types[i], gerr);
    }
    int k = ne ? (int)(nen / ne) : 0;
    if (is_kept) {
      if (vol_type) {
        m->tet_nodes = k;
        m->ntet = (int64_t)ne;
        FMBD_GALLOC(m->tet = fmbd_malloc((nen + 1) * sizeof *m->tet));
        FMBD_GALLOC(kept_tag = fmbd_malloc((ne + 1) * sizeof *kept_tag));
        memcpy(kept_tag, etag, ne * sizeof *kept_tag);
      } else {
        // line2 -> one beam, line3 (ends 0, 1, middle 2) -> two beams
        int nb = k == 3 ? 2 : 1;
        int64_t first = m->nbeam;
        int64_t *b =
            fmbd_realloc(m->beam, (size_t)(2 * (m->nbeam + nb * (int64_t)ne) + 1) * sizeof *b);
        size_t *kt = fmbd_realloc(kept_tag, (size_t)(m->nbeam + nb * (int64_t)ne + 1) * sizeof *kt);
        if (b) {
          m->beam = b;
        }
        if (kt) {
          kept_tag = kt;
        }
        FMBD_GCHECK(b && kt, FMBD_ERR_NOMEM, "out of memory");
        m->nbeam += nb * (int64_t)ne;
        for (size_t e = 0; e < ne; e++) {
          int64_t *bb = m->beam + 2 * (first + nb * (int64_t)e);
          if (nb == 1) {
            bb[0] = (int64_t)enode[2 * e];
            bb[1] = (int64_t)enode[2 * e + 1];
          } else {
            bb[0] = (int64_t)enode[3 * e];
            bb[1] = (int64_t)enode[3 * e + 2];
            bb[2] = (int64_t)enode[3 * e + 2];
            bb[3] = (int64_t)enode[3 * e + 1];
          }
          for (int j = 0; j < nb; j++) {
            kept_tag[first + nb * (int64_t)e + j] = etag[e];
          }
        }
      }
    }
    for (size_t j = 0; j < nen; j++) {
      int64_t p = tag_map_get(&tm, enode[j]);
      if (p < 0) {
        FMBD_GFAIL(FMBD_ERR_FORMAT, "element tag %zu refers to node tag %zu, which does not exist",
                   etag[j / (size_t)k], enode[j]);
      }
      if (use[p] < level) {
        use[p] = level;
      }
      if (is_kept && vol_type) {
        m->tet[j] = p;
      }
    }
    gmshFree(etag);
    gmshFree(enode);
    etag = enode = NULL;
  }
  // beam node tags -> indices (they were stored as tags; all beam types are processed by now)
  for (int64_t i = 0; i < 2 * m->nbeam; i++) {
    m->beam[i] = tag_map_get(&tm, (size_t)m->beam[i]);
  }
  // --- nodes on no kept element ---
  for (size_t p = 0; p < nn; p++) {
    if (use[p] == 0) {
      fmbd_err_contextf(NULL, "node tag %zu", ntag[p]);
      FMBD_GFAIL(FMBD_ERR_VALUE, "the node at (%g, %g, %g) is attached to no element", coord[3 * p],
                 coord[3 * p + 1], coord[3 * p + 2]);
    }
    if (use[p] == 2) {
      fmbd_err_contextf(NULL, "node tag %zu", ntag[p]);
      FMBD_GFAIL(FMBD_ERR_VALUE,
                 "the node at (%g, %g, %g) lies on no %s element (only on lower-dimensional "
                 "ones: a surface or curve outside the solid?)",
                 coord[3 * p], coord[3 * p + 1], coord[3 * p + 2],
                 vol_type ? "tetrahedron" : "line");
    }
  }
  m->nnodes = (int64_t)nn;
  FMBD_GALLOC(m->xyz = fmbd_malloc((3 * nn + 1) * sizeof *m->xyz));
  memcpy(m->xyz, coord, 3 * nn * sizeof *m->xyz);
  // --- physical groups ---
  gmshModelGetPhysicalGroups(&pg, &npg, -1, &ierr);
  FMBD_GALLOC(tmp = fmbd_malloc((nn + 1) * sizeof *tmp));
  for (size_t i = 0; i + 1 < npg; i += 2) {
    int dim = pg[i], tag = pg[i + 1];
    size_t *gt = NULL, ngt = 0, ngc = 0;
    double *gc = NULL;
    gmshModelGetPhysicalName(dim, tag, &pname, &ierr);
    char name[256];
    if (pname && pname[0]) {
      snprintf(name, sizeof name, "%s", pname);
    } else {
      snprintf(name, sizeof name, "p%d_%d", dim, tag);
    }
    if (pname) {
      gmshFree(pname);
      pname = NULL;
    }
    gmshModelMeshGetNodesForPhysicalGroup(dim, tag, &gt, &ngt, &gc, &ngc, &ierr);
    int64_t k = 0;
    for (size_t j = 0; j < ngt; j++) {
      int64_t p = tag_map_get(&tm, gt[j]);
      if (p >= 0 && use[p] == 3) {
        tmp[k++] = p;
      }
    }
    if (gt) {
      gmshFree(gt);
    }
    if (gc) {
      gmshFree(gc);
    }
    if (k == 0) {
      fmbd_log(FMBD_LOG_WARN, "%s: physical group '%s' has no node on the %s elements; ignored",
               path, name, vol_type ? "volume" : "line");
      continue;
    }
    FMBD_GCALL(fmbd_mesh_add_group_(m, name, k, tmp));
  }
  // --- element validation with gmsh tags, then drop point-only nodes ---
  {
    int64_t dropped = 0;
    FMBD_GALLOC(keep = fmbd_malloc(nn + 1));
    for (size_t p = 0; p < nn; p++) {
      keep[p] = use[p] == 3;
      dropped += !keep[p];
    }
    if (dropped) {
      fmbd_log(FMBD_LOG_INFO, "%s: %lld construction point node(s) on no element dropped", path,
               (long long)dropped);
      FMBD_GCALL(fmbd_mesh_compact_nodes(m, keep));
    }
  }
  FMBD_GCALL(fmbd_mesh_check_tagged(m, vol_type ? kept_tag : NULL, vol_type ? NULL : kept_tag));
done:
  if (ntag) gmshFree(ntag);
  if (coord) gmshFree(coord);
  if (par) gmshFree(par);
  if (types) gmshFree(types);
  if (pg) gmshFree(pg);
  if (etag) gmshFree(etag);
  if (enode) gmshFree(enode);
  fmbd_free(kept_tag);
  fmbd_free(use);
  fmbd_free(keep);
  fmbd_free(tmp);
  tag_map_free(&tm);
  return rc;
}

// --- closed surfaces: STL, OFF ------------------------------------------------------------------

typedef struct surface {
  int64_t nv, nf;
  double *xyz;   // (nv, 3)
  int64_t *tri;  // (nf, 3)
} surface;

static void surface_free(surface *s) {
  fmbd_free(s->xyz);
  fmbd_free(s->tri);
  memset(s, 0, sizeof *s);
}

static int read_file(const char *path, char **buf, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    FMBD_FAIL(FMBD_ERR_IO, "cannot open: %s", strerror(errno));
  }
  size_t cap = 1 << 16, n = 0;
  char *b = fmbd_malloc(cap + 1);
  while (b) {
    size_t r = fread(b + n, 1, cap - n, f);
    n += r;
    if (n < cap) {
      break;
    }
    cap *= 2;
    char *nb = fmbd_realloc(b, cap + 1);
    if (!nb) {
      fmbd_free(b);
      b = NULL;
    }
    b = nb;
  }
  int err = ferror(f);
  fclose(f);
  if (!b) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  if (err) {
    fmbd_free(b);
    FMBD_FAIL(FMBD_ERR_IO, "read error");
  }
  b[n] = '\0';
  *buf = b;
  *len = n;
  return FMBD_OK;
}

// Merge vertices with identical coordinates (STL repeats every vertex per triangle).
typedef struct vkey {
  double x, y, z;
  int64_t i;
} vkey;
static int cmp_vkey(const void *a, const void *b) {
  const vkey *p = a, *q = b;
  if (p->x != q->x) return (p->x > q->x) - (p->x < q->x);
  if (p->y != q->y) return (p->y > q->y) - (p->y < q->y);
  return (p->z > q->z) - (p->z < q->z);
}

static int merge_vertices(surface *s) {
  vkey *k = fmbd_malloc((size_t)(s->nv + 1) * sizeof *k);
  int64_t *id = fmbd_malloc((size_t)(s->nv + 1) * sizeof *id);
  if (!k || !id) {
    fmbd_free(k);
    fmbd_free(id);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t i = 0; i < s->nv; i++) {
    k[i] = (vkey){s->xyz[3 * i], s->xyz[3 * i + 1], s->xyz[3 * i + 2], i};
  }
  qsort(k, (size_t)s->nv, sizeof *k, cmp_vkey);
  int64_t n = 0;
  for (int64_t i = 0; i < s->nv; i++) {
    if (i == 0 || cmp_vkey(&k[i], &k[i - 1]) != 0) {
      s->xyz[3 * n] = k[i].x;
      s->xyz[3 * n + 1] = k[i].y;
      s->xyz[3 * n + 2] = k[i].z;
      n++;
    }
    id[k[i].i] = n - 1;
  }
  for (int64_t i = 0; i < 3 * s->nf; i++) {
    s->tri[i] = id[s->tri[i]];
  }
  s->nv = n;
  fmbd_free(k);
  fmbd_free(id);
  return FMBD_OK;
}

static int read_stl(const char *path, surface *s) {
  int rc = FMBD_OK;
  char *buf = NULL;
  size_t len = 0;
  FMBD_GCALL(read_file(path, &buf, &len));
  uint32_t nbin = 0;
  if (len >= 84) {
    memcpy(&nbin, buf + 80, 4);  // little-endian hosts (x86-64, aarch64)
  }
  if (len >= 84 && (uint64_t)len == 84 + 50 * (uint64_t)nbin) {
    // binary STL: 80-byte header, uint32 count, per triangle 12 float32 + uint16
    s->nf = nbin;
    s->nv = 3 * (int64_t)nbin;
    FMBD_GALLOC(s->xyz = fmbd_malloc((size_t)(3 * s->nv + 1) * sizeof *s->xyz));
    FMBD_GALLOC(s->tri = fmbd_malloc((size_t)(3 * s->nf + 1) * sizeof *s->tri));
    for (int64_t f = 0; f < s->nf; f++) {
      const char *rec = buf + 84 + 50 * f + 12;  // skip the normal
      for (int a = 0; a < 9; a++) {
        float v;
        memcpy(&v, rec + 4 * a, 4);
        s->xyz[9 * f + a] = v;
      }
      for (int a = 0; a < 3; a++) {
        s->tri[3 * f + a] = 3 * f + a;
      }
    }
  } else {
    // ASCII STL: "solid ... facet normal ... outer loop vertex x y z (x3) endloop endfacet"
    if (strncmp(buf, "solid", 5) != 0) {
      FMBD_GFAIL(FMBD_ERR_FORMAT, "not an STL file (no 'solid' header, and not binary STL)");
    }
    int64_t cap = 0;
    const char *p = buf;
    int line = 1;
    while ((p = strstr(p, "vertex")) != NULL) {
      p += 6;
      char *end;
      double v[3];
      for (int a = 0; a < 3; a++) {
        v[a] = strtod(p, &end);
        if (end == p) {
          // count the line for the message
          for (const char *q = buf; q < p; q++) {
            line += *q == '\n';
          }
          fmbd_err_contextf(NULL, "line %d", line);
          FMBD_GFAIL(FMBD_ERR_FORMAT, "'vertex' without three numbers");
        }
        p = end;
      }
      if (s->nv == cap) {
        cap = cap ? 2 * cap : 1024;
        double *x = fmbd_realloc(s->xyz, (size_t)(3 * cap) * sizeof *x);
        FMBD_GCHECK(x, FMBD_ERR_NOMEM, "out of memory");
        s->xyz = x;
      }
      memcpy(s->xyz + 3 * s->nv, v, sizeof v);
      s->nv++;
    }
    if (s->nv == 0 || s->nv % 3 != 0) {
      FMBD_GFAIL(FMBD_ERR_FORMAT,
                 "ASCII STL with %lld vertices (a positive multiple of 3 expected)",
                 (long long)s->nv);
    }
    s->nf = s->nv / 3;
    FMBD_GALLOC(s->tri = fmbd_malloc((size_t)(3 * s->nf) * sizeof *s->tri));
    for (int64_t i = 0; i < s->nv; i++) {
      s->tri[i] = i;
    }
  }
  if (s->nf == 0) {
    FMBD_GFAIL(FMBD_ERR_FORMAT, "the STL file holds no triangle");
  }
  FMBD_GCALL(merge_vertices(s));
done:
  fmbd_free(buf);
  return rc;
}

// next token of an OFF file (skips blanks and # comments); NULL at the end
static char *off_token(char **p, int *line) {
  char *q = *p;
  for (;;) {
    while (*q && isspace((unsigned char)*q)) {
      *line += *q == '\n';
      q++;
    }
    if (*q == '#') {
      while (*q && *q != '\n') {
        q++;
      }
      continue;
    }
    break;
  }
  if (!*q) {
    *p = q;
    return NULL;
  }
  char *t = q;
  while (*q && !isspace((unsigned char)*q)) {
    q++;
  }
  *p = q;
  return t;
}

static int off_number(char **p, int *line, double *v, const char *what) {
  char *t = off_token(p, line), *end;
  if (!t) {
    fmbd_err_contextf(NULL, "line %d", *line);
    FMBD_FAIL(FMBD_ERR_FORMAT, "unexpected end of file: %s expected", what);
  }
  *v = strtod(t, &end);
  if (end == t || (*end && !isspace((unsigned char)*end))) {
    fmbd_err_contextf(NULL, "line %d", *line);
    FMBD_FAIL(FMBD_ERR_FORMAT, "'%.*s' is not a number (%s expected)", (int)(strcspn(t, " \t\r\n")),
              t, what);
  }
  return FMBD_OK;
}

static int read_off(const char *path, surface *s) {
  int rc = FMBD_OK, line = 1;
  char *buf = NULL;
  size_t len = 0;
  FMBD_GCALL(read_file(path, &buf, &len));
  char *p = buf;
  char *t = off_token(&p, &line);
  if (!t || strncmp(t, "OFF", 3) != 0 || (t[3] && !isspace((unsigned char)t[3]))) {
    FMBD_GFAIL(FMBD_ERR_FORMAT, "not an OFF file (first word 'OFF' expected)");
  }
  double nv, nf, ne;
  FMBD_GCALL(off_number(&p, &line, &nv, "vertex count"));
  FMBD_GCALL(off_number(&p, &line, &nf, "face count"));
  FMBD_GCALL(off_number(&p, &line, &ne, "edge count"));
  if (!(nv >= 3 && nf >= 1 && nv == floor(nv) && nf == floor(nf) && nv < 1e9 && nf < 1e9)) {
    fmbd_err_contextf(NULL, "line %d", line);
    FMBD_GFAIL(FMBD_ERR_FORMAT, "bad vertex/face counts %g %g", nv, nf);
  }
  s->nv = (int64_t)nv;
  FMBD_GALLOC(s->xyz = fmbd_malloc((size_t)(3 * s->nv) * sizeof *s->xyz));
  for (int64_t i = 0; i < 3 * s->nv; i++) {
    FMBD_GCALL(off_number(&p, &line, &s->xyz[i], "a vertex coordinate"));
  }
  int64_t cap = 2 * (int64_t)nf;
  FMBD_GALLOC(s->tri = fmbd_malloc((size_t)(3 * cap) * sizeof *s->tri));
  for (int64_t f = 0; f < (int64_t)nf; f++) {
    double k;
    FMBD_GCALL(off_number(&p, &line, &k, "a face's vertex count"));
    if (!(k >= 3 && k <= 64 && k == floor(k))) {
      fmbd_err_contextf(NULL, "line %d", line);
      FMBD_GFAIL(FMBD_ERR_FORMAT, "face %lld has %g vertices (3 to 64 expected)", (long long)f, k);
    }
    int64_t v[64];
    for (int a = 0; a < (int)k; a++) {
      double x;
      FMBD_GCALL(off_number(&p, &line, &x, "a vertex index"));
      if (!(x >= 0 && x < nv && x == floor(x))) {
        fmbd_err_contextf(NULL, "line %d", line);
        FMBD_GFAIL(FMBD_ERR_FORMAT, "face %lld: vertex index %g out of range [0, %lld)",
                   (long long)f, x, (long long)s->nv);
      }
      v[a] = (int64_t)x;
    }
    // skip anything else on the face's line (colours)
    while (*p && *p != '\n') {
      p++;
    }
    // fan triangulation of a (convex, planar) polygon
    for (int a = 1; a + 1 < (int)k; a++) {
      if (s->nf == cap) {
        cap *= 2;
        int64_t *nt = fmbd_realloc(s->tri, (size_t)(3 * cap) * sizeof *nt);
        FMBD_GCHECK(nt, FMBD_ERR_NOMEM, "out of memory");
        s->tri = nt;
      }
      s->tri[3 * s->nf] = v[0];
      s->tri[3 * s->nf + 1] = v[a];
      s->tri[3 * s->nf + 2] = v[a + 1];
      s->nf++;
    }
  }
  FMBD_GCALL(merge_vertices(s));
done:
  fmbd_free(buf);
  return rc;
}

static int mesh_surface(const char *path, const fmbd_mesh_opts *opt, const surface *s,
                        fmbd_mesh *m) {
  // --- the surface's own checks: finite coordinates, no zero-area triangle ---
  for (int64_t i = 0; i < 3 * s->nv; i++) {
    if (!isfinite(s->xyz[i])) {
      FMBD_FAIL(FMBD_ERR_FORMAT, "vertex %lld has a non-finite coordinate", (long long)(i / 3));
    }
  }
  double diag = fmbd_mesh_bbox_diagonal(s->nv, s->xyz);
  for (int64_t f = 0; f < s->nf; f++) {
    const int64_t *t = s->tri + 3 * f;
    double a[3], b[3], c[3];
    for (int k = 0; k < 3; k++) {
      a[k] = s->xyz[3 * t[1] + k] - s->xyz[3 * t[0] + k];
      b[k] = s->xyz[3 * t[2] + k] - s->xyz[3 * t[0] + k];
    }
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
    double area2 = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(area2 > 1e-14 * diag * diag)) {
      FMBD_FAIL(FMBD_ERR_VALUE, "triangle %lld (vertices %lld %lld %lld) has zero area",
                (long long)f, (long long)t[0], (long long)t[1], (long long)t[2]);
    }
  }
  if (!opt->surface_mesher) {
    FMBD_FAIL(FMBD_ERR_USAGE, "no tetrahedral mesher for closed surfaces in this program");
  }
  double size = opt->size > 0 ? opt->size : diag / 25.0;
  fmbd_progress("meshing %s with CGAL (size %g)", path, size);
  int rc = opt->surface_mesher(s->nv, s->xyz, s->nf, s->tri, size, &m->nnodes, &m->xyz, &m->ntet,
                               &m->tet);
  fmbd_progress(NULL);
  if (rc) {
    return rc;
  }
  m->tet_nodes = 4;
  // CGAL's cells are positively oriented; make sure (swap 1 and 2 if not)
  for (int64_t e = 0; e < m->ntet; e++) {
    static const double c[3] = {0.25, 0.25, 0.25};
    if (fmbd_mesh_tet_detj(m->xyz, 4, m->tet + 4 * e, c) < 0) {
      int64_t t = m->tet[4 * e + 1];
      m->tet[4 * e + 1] = m->tet[4 * e + 2];
      m->tet[4 * e + 2] = t;
    }
  }
  FMBD_CALL(fmbd_mesh_check_tagged(m, NULL, NULL));
  if (opt->order == 0 || opt->order == 2) {
    FMBD_CALL(fmbd_mesh_elevate(m));
  }
  return FMBD_OK;
}

// --- the entry point -----------------------------------------------------------------------------

int fmbd_mesh_read(const char *path, const fmbd_mesh_opts *opt, fmbd_mesh *m) {
  int rc = FMBD_OK;
  fmbd_mesh_opts defaults;
  if (!opt) {
    fmbd_mesh_opts_defaults(&defaults);
    opt = &defaults;
  }
  memset(m, 0, sizeof *m);
  fmbd_err_context(path, "");
  if (opt->order != 0 && opt->order != 1 && opt->order != 2) {
    FMBD_FAIL(FMBD_ERR_USAGE, "element order %d (1 or 2 expected)", opt->order);
  }
  int is_msh = fmbd_mesh_ends_with(path, ".msh");
  int is_geo = fmbd_mesh_ends_with(path, ".geo") || fmbd_mesh_ends_with(path, ".step") ||
               fmbd_mesh_ends_with(path, ".stp") || fmbd_mesh_ends_with(path, ".brep");
  int is_stl = fmbd_mesh_ends_with(path, ".stl");
  int is_off = fmbd_mesh_ends_with(path, ".off");
  if (!is_msh && !is_geo && !is_stl && !is_off) {
    const char *dot = strrchr(path, '.');
    FMBD_FAIL(FMBD_ERR_USAGE,
              "unknown geometry type '%s' (expected .geo, .step, .stp, .brep, .msh, .stl or .off)",
              dot && !strchr(dot, '/') ? dot : "(no extension)");
  }
  // gmsh reports an unreadable file poorly: check first
  struct stat st;
  if (stat(path, &st) != 0) {
    FMBD_FAIL(FMBD_ERR_IO, "cannot open: %s", strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) {
    FMBD_FAIL(FMBD_ERR_IO, "not a regular file");
  }
  FILE *f = fopen(path, "rb");
  if (!f) {
    FMBD_FAIL(FMBD_ERR_IO, "cannot open: %s", strerror(errno));
  }
  fclose(f);

  if (is_stl || is_off) {
    surface s = {0};
    rc = is_stl ? read_stl(path, &s) : read_off(path, &s);
    if (!rc) {
      fmbd_err_context(path, "");
      rc = mesh_surface(path, opt, &s, m);
    }
    surface_free(&s);
  } else {
    int ierr = 0;
    gmsh_init(&ierr);
    if (ierr) {
      FMBD_FAIL(FMBD_ERR_EXTERNAL, "cannot initialise gmsh");
    }
    gmshOptionSetNumber("General.Terminal", opt->gmsh_verbose ? 1 : 0, &ierr);
    gmshOptionSetNumber("General.Verbosity", opt->gmsh_verbose ? 5 : 1, &ierr);
    rc = read_gmsh(path, is_msh, opt, m);
    gmshFinalize(&ierr);
    if (!rc && is_msh && opt->order == 2) {
      rc = fmbd_mesh_elevate(m);
    } else if (!rc && opt->order == 1) {
      rc = fmbd_mesh_reduce_to_tet4(m);
    }
  }
  if (rc) {
    fmbd_mesh_destroy(m);
    return rc;
  }
  fmbd_err_context("", "");
  return FMBD_OK;
}
