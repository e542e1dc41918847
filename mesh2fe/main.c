// mesh2fe/main.c: geometry -> finite-element body (BODY.fe.h5): mesh, K, M, interfaces, clamps
// SPDX-License-Identifier: MIT
//
// A thin command line over common/: fmbd_mesh_read (gmsh, or CGAL through cgal_shim.cpp for
// closed surfaces), fmbd_fe_assemble, fmbd_fe_write. See docs/man/mesh2fe.1.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cgal_shim.h"
#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_mesh.h"

static const char *usage_text =
    "Usage: mesh2fe GEOMETRY [-o BODY.fe.h5] [--order 1|2] [--size H]\n"
    "               [--E PA --nu V --rho KG_M3] [--mass consistent|lumped]\n"
    "               [--interface GROUP[:rbe2|rbe3][@X,Y,Z]]... [--clamp GROUP]...\n"
    "               [--group NAME:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX]...\n"
    "               [--section A,IY,IZ,J | --circle R] [--beam-orientation X,Y,Z]\n"
    "Mesh a geometry and write its finite-element body: mass and stiffness matrices,\n"
    "interface (joint) nodes, clamps, rigid-body properties (an fmbd-fe HDF5 file).\n"
    "\n"
    "GEOMETRY  gmsh .geo, .step/.stp, .brep (meshed by gmsh: tetrahedra when the model has\n"
    "          volumes, 2-node beams when it has only curves), a gmsh .msh (taken as\n"
    "          stored), or a closed triangulated surface .stl/.off (tetrahedra by CGAL).\n"
    "\n"
    "Options:\n"
    "  -o FILE             output (\"-\": standard output). Default: GEOMETRY with its\n"
    "                      ending replaced by .fe.h5, or standard output when that is not\n"
    "                      a terminal\n"
    "  --order 1|2         tet4 or tet10 (default 2; a .msh keeps its own order unless given)\n"
    "  --size H            element size in m (default: the geometry's own mesh sizes; for\n"
    "                      .stl/.off the bounding-box diagonal / 25)\n"
    "  --E PA              Young's modulus (default 210e9, steel)\n"
    "  --nu V              Poisson's ratio, -1 < V < 0.5 (default 0.3)\n"
    "  --rho KG_M3         density (default 7850)\n"
    "  --mass KIND         consistent (default) or lumped (HRZ diagonal)\n"
    "  --interface SPEC    GROUP[:rbe2|rbe3][@X,Y,Z]: one 6-dof node at X,Y,Z (default: the\n"
    "                      group's centroid) tied to the group's nodes, rigidly (rbe2,\n"
    "                      default) or as a weighted average (rbe3); repeatable\n"
    "  --clamp GROUP       remove every dof of the group's nodes (or of the interface node\n"
    "                      if GROUP is an interface); repeatable\n"
    "  --group NAME:BOX    a node group of the nodes inside the box\n"
    "                      XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (m); repeatable. The way to name\n"
    "                      faces of .stl/.off parts, which carry no groups\n"
    "  --section A,IY,IZ,J beam section: area (m^2), second moments about the local y and z\n"
    "                      axes and torsion constant (m^4); required for beam meshes\n"
    "  --circle R          beam section of a solid circle of radius R (A = pi R^2,\n"
    "                      Iy = Iz = pi R^4/4, J = pi R^4/2)\n"
    "  --beam-orientation X,Y,Z  a vector in the beams' local x-z plane (default: global Z,\n"
    "                      or global X for beams along Z)\n"
    "  -q, --quiet         errors only\n"
    "  -v, --verbose       progress and details (-vv: debug)\n"
    "  -h, --help          this help\n"
    "  -V, --version       the version\n"
    "\n"
    "Example:\n"
    "  mesh2fe examples/geometry/rod.geo --size 0.005 --interface end0 --interface end1\n";

// --- the CGAL mesher as the fmbd_surface_mesher of fmbd_mesh_read ------------------------------
static int cgal_mesher(int64_t nv, const double *xyz, int64_t nf, const int64_t *tri, double size,
                       int64_t *nn, double **nodes, int64_t *nt, int64_t **tet) {
  // facet_distance size/10 and facet_angle 25 are the values of CGAL's own polyhedral
  // examples; edges with a dihedral angle beyond 60 degrees (CGAL's default) stay sharp.
  fmbd_cgal_criteria c = {size, size / 10.0, 25.0, 3.0, 60.0};
  char msg[700];
  int st = fmbd_cgal_mesh_surface(nv, xyz, nf, tri, &c, nn, nodes, nt, tet, msg, sizeof msg);
  if (st == FMBD_CGAL_OK) {
    return FMBD_OK;
  }
  int code = st == FMBD_CGAL_NOMEM         ? FMBD_ERR_NOMEM
             : st == FMBD_CGAL_BAD_SURFACE ? FMBD_ERR_VALUE
                                           : FMBD_ERR_EXTERNAL;
  return fmbd_err_set(code, __FILE__, __LINE__, __func__, "%s", msg);
}

typedef struct box_group {
  char *name;
  double lo[3], hi[3];
} box_group;

typedef struct args {
  const char *input, *output;
  fmbd_mesh_opts mesh;
  fmbd_fe_opts fe;
  int nif, nclamp, nbox;
  fmbd_fe_interface_spec *ifs;
  char **if_group;  // owned copies of the group names
  const char **clamps;
  box_group *boxes;
  int quiet, verbose;
} args;

static void args_free(args *a) {
  for (int i = 0; i < a->nif; i++) {
    fmbd_free(a->if_group[i]);
  }
  for (int i = 0; i < a->nbox; i++) {
    fmbd_free(a->boxes[i].name);
  }
  fmbd_free(a->ifs);
  fmbd_free(a->if_group);
  fmbd_free(a->clamps);
  fmbd_free(a->boxes);
}

// GROUP[:rbe2|rbe3][@X,Y,Z]
static int parse_interface(args *a, const char *text) {
  char *s = fmbd_strdup(text);
  if (!s) {
    return fmbd_cli_usage_error("out of memory");
  }
  fmbd_fe_interface_spec spec = {0};
  spec.kind = FMBD_FE_RBE2;
  char *at = strrchr(s, '@');
  if (at) {
    *at = '\0';
    if (fmbd_cli_numbers("--interface", at + 1, 3, ',', spec.point)) {
      fmbd_free(s);
      return 2;
    }
    spec.has_point = true;
  }
  char *colon = strrchr(s, ':');
  if (colon) {
    if (!strcmp(colon + 1, "rbe2")) {
      spec.kind = FMBD_FE_RBE2;
    } else if (!strcmp(colon + 1, "rbe3")) {
      spec.kind = FMBD_FE_RBE3;
    } else {
      int st =
          fmbd_cli_usage_error("--interface %s: tie '%s' is not rbe2 or rbe3", text, colon + 1);
      fmbd_free(s);
      return st;
    }
    *colon = '\0';
  }
  if (!s[0]) {
    fmbd_free(s);
    return fmbd_cli_usage_error("--interface %s: no group name", text);
  }
  for (int i = 0; i < a->nif; i++) {
    if (!strcmp(a->if_group[i], s)) {
      fmbd_free(s);
      return fmbd_cli_usage_error("--interface %s: group given twice", text);
    }
  }
  fmbd_fe_interface_spec *ifs = fmbd_realloc(a->ifs, (size_t)(a->nif + 1) * sizeof *ifs);
  if (ifs) {
    a->ifs = ifs;
  }
  char **g = fmbd_realloc(a->if_group, (size_t)(a->nif + 1) * sizeof *g);
  if (g) {
    a->if_group = g;
  }
  if (!ifs || !g) {
    fmbd_free(s);
    return fmbd_cli_usage_error("out of memory");
  }
  a->if_group[a->nif] = s;
  a->ifs[a->nif] = spec;
  a->nif++;
  return 0;
}

// NAME:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX
static int parse_box(args *a, const char *text) {
  const char *colon = strrchr(text, ':');
  if (!colon || colon == text) {
    return fmbd_cli_usage_error("--group %s: NAME:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX expected", text);
  }
  double v[6];
  if (fmbd_cli_numbers("--group", colon + 1, 6, ',', v)) {
    return 2;
  }
  for (int k = 0; k < 3; k++) {
    if (v[k] > v[k + 3]) {
      return fmbd_cli_usage_error("--group %s: min %g > max %g in %c", text, v[k], v[k + 3],
                                  "xyz"[k]);
    }
  }
  box_group *b = fmbd_realloc(a->boxes, (size_t)(a->nbox + 1) * sizeof *b);
  if (!b) {
    return fmbd_cli_usage_error("out of memory");
  }
  a->boxes = b;
  box_group *g = &a->boxes[a->nbox];
  g->name = fmbd_malloc((size_t)(colon - text) + 1);
  if (!g->name) {
    return fmbd_cli_usage_error("out of memory");
  }
  memcpy(g->name, text, (size_t)(colon - text));
  g->name[colon - text] = '\0';
  memcpy(g->lo, v, sizeof g->lo);
  memcpy(g->hi, v + 3, sizeof g->hi);
  a->nbox++;
  return 0;
}

enum {
  OPT_OUTPUT = 1,
  OPT_ORDER,
  OPT_SIZE,
  OPT_E,
  OPT_NU,
  OPT_RHO,
  OPT_MASS,
  OPT_INTERFACE,
  OPT_CLAMP,
  OPT_GROUP,
  OPT_SECTION,
  OPT_CIRCLE,
  OPT_BEAM_ORIENTATION
};
static const fmbd_cli_option options[] = {{"--output", 'o', true, OPT_OUTPUT},
                                          {"--order", 0, true, OPT_ORDER},
                                          {"--size", 0, true, OPT_SIZE},
                                          {"--E", 0, true, OPT_E},
                                          {"--nu", 0, true, OPT_NU},
                                          {"--rho", 0, true, OPT_RHO},
                                          {"--mass", 0, true, OPT_MASS},
                                          {"--interface", 0, true, OPT_INTERFACE},
                                          {"--clamp", 0, true, OPT_CLAMP},
                                          {"--group", 0, true, OPT_GROUP},
                                          {"--section", 0, true, OPT_SECTION},
                                          {"--circle", 0, true, OPT_CIRCLE},
                                          {"--beam-orientation", 0, true, OPT_BEAM_ORIENTATION},
                                          {0}};

// Returns 0 (go on; *done when --help/--version was printed) or 2 (usage error, reported).
static int parse_args(int argc, char **argv, args *a, bool *done) {
  static double section[4];
  bool have_section = false, have_circle = false;
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    const char *val = p.value, *arg = p.opt;
    switch (id) {
      case FMBD_CLI_EXIT:
        *done = p.status == 0;
        return p.status;
      case FMBD_CLI_ARG:
        if (a->input) {
          return fmbd_cli_usage_error("one GEOMETRY expected, got '%s' and '%s'", a->input, val);
        }
        a->input = val;
        break;
      case OPT_OUTPUT:
        a->output = val;
        break;
      case OPT_ORDER: {
        long o;
        if (fmbd_cli_long(&p, 1, 2, &o)) {
          return p.status;
        }
        a->mesh.order = (int)o;
        break;
      }
      case OPT_SIZE:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &a->mesh.size)) {
          return p.status;
        }
        break;
      case OPT_E:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &a->fe.E)) {
          return p.status;
        }
        break;
      case OPT_NU:
        if (fmbd_cli_double(&p, -1, 0.5, FMBD_CLI_OPEN_LO | FMBD_CLI_OPEN_HI, &a->fe.nu)) {
          return p.status;
        }
        break;
      case OPT_RHO:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &a->fe.rho)) {
          return p.status;
        }
        break;
      case OPT_MASS:
        if (!strcmp(val, "consistent")) {
          a->fe.mass = FMBD_FE_MASS_CONSISTENT;
        } else if (!strcmp(val, "lumped")) {
          a->fe.mass = FMBD_FE_MASS_LUMPED;
        } else {
          return fmbd_cli_usage_error("--mass: '%s' is not consistent or lumped", val);
        }
        break;
      case OPT_INTERFACE: {
        int st = parse_interface(a, val);
        if (st) {
          return st;
        }
        break;
      }
      case OPT_CLAMP: {
        const char **c = fmbd_realloc(a->clamps, (size_t)(a->nclamp + 1) * sizeof *c);
        if (!c) {
          return fmbd_cli_usage_error("out of memory");
        }
        a->clamps = c;
        a->clamps[a->nclamp++] = val;
        break;
      }
      case OPT_GROUP: {
        int st = parse_box(a, val);
        if (st) {
          return st;
        }
        break;
      }
      case OPT_SECTION:
        if (fmbd_cli_numbers(arg, val, 4, ',', section)) {
          return 2;
        }
        for (int k = 0; k < 4; k++) {
          if (!(section[k] > 0)) {
            return fmbd_cli_usage_error("--section: %s: A, Iy, Iz and J must all be > 0", val);
          }
        }
        have_section = true;
        break;
      case OPT_CIRCLE: {
        double r;
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &r)) {
          return p.status;
        }
        section[0] = M_PI * r * r;
        section[1] = section[2] = M_PI * r * r * r * r / 4.0;
        section[3] = M_PI * r * r * r * r / 2.0;
        have_circle = true;
        break;
      }
      case OPT_BEAM_ORIENTATION:
        if (fmbd_cli_numbers(arg, val, 3, ',', a->fe.orientation)) {
          return 2;
        }
        if (a->fe.orientation[0] == 0 && a->fe.orientation[1] == 0 && a->fe.orientation[2] == 0) {
          return fmbd_cli_usage_error("--beam-orientation: the zero vector has no direction");
        }
        break;
    }
  }
  a->quiet = p.quiet;
  a->verbose = p.verbose;
  if (have_section && have_circle) {
    return fmbd_cli_usage_error("--section and --circle are exclusive");
  }
  if (have_section || have_circle) {
    a->fe.area = section[0];
    a->fe.Iy = section[1];
    a->fe.Iz = section[2];
    a->fe.J = section[3];
  }
  if (!a->input) {
    return fmbd_cli_usage_error("no GEOMETRY given");
  }
  if (!strcmp(a->input, "-")) {
    return fmbd_cli_usage_error("GEOMETRY cannot be standard input: give a file name");
  }
  for (int i = 0; i < a->nif; i++) {
    a->ifs[i].group = a->if_group[i];
  }
  a->fe.interfaces = a->ifs;
  a->fe.ninterfaces = a->nif;
  a->fe.clamps = a->clamps;
  a->fe.nclamps = a->nclamp;
  return 0;
}

// Every group named on the command line must exist (names listed in the message), and an
// RBE3 group must hold three non-collinear nodes.
static int check_groups(const args *a, const fmbd_mesh *m) {
  char list[1024] = "";
  size_t len = 0;
  for (int g = 0; g < m->ngroups && len + 8 < sizeof list; g++) {
    len += (size_t)snprintf(list + len, sizeof list - len, "%s%s", g ? ", " : "", m->group_name[g]);
  }
  if (len >= sizeof list) {
    strcpy(list + sizeof list - 5, "...");
  }
  for (int i = 0; i < a->nif; i++) {
    int g = fmbd_mesh_find_group(m, a->ifs[i].group);
    fmbd_err_contextf(a->input, "--interface %s", a->ifs[i].group);
    if (g < 0) {
      FMBD_FAIL(FMBD_ERR_VALUE, "physical group '%s' not found (groups: %s)", a->ifs[i].group,
                m->ngroups ? list : "none");
    }
    if (a->ifs[i].kind == FMBD_FE_RBE3) {
      int d = fmbd_mesh_group_affine_dim(m, g);
      if (d < 2) {
        FMBD_FAIL(FMBD_ERR_VALUE,
                  "RBE3 interface '%s' cannot carry rotation: its %lld node(s) are %s (three "
                  "non-collinear nodes needed; use rbe2)",
                  a->ifs[i].group, (long long)(m->group_ptr[g + 1] - m->group_ptr[g]),
                  d == 0 ? "one point" : "collinear");
      }
    }
  }
  for (int i = 0; i < a->nclamp; i++) {
    bool is_if = false;
    for (int j = 0; j < a->nif; j++) {
      is_if = is_if || !strcmp(a->clamps[i], a->ifs[j].group);
    }
    fmbd_err_contextf(a->input, "--clamp %s", a->clamps[i]);
    if (!is_if && fmbd_mesh_find_group(m, a->clamps[i]) < 0) {
      FMBD_FAIL(FMBD_ERR_VALUE, "physical group '%s' not found (groups: %s)", a->clamps[i],
                m->ngroups ? list : "none");
    }
  }
  fmbd_err_context(a->input, "");
  return FMBD_OK;
}

int main(int argc, char **argv) {
  fmbd_cli_init("mesh2fe", argc, argv);
  args a = {0};
  fmbd_mesh_opts_defaults(&a.mesh);
  a.mesh.surface_mesher = cgal_mesher;
  fmbd_fe_opts_defaults(&a.fe);
  bool done_early = false;
  int st = parse_args(argc, argv, &a, &done_early);
  fmbd_cli_set_verbosity(a.quiet, a.verbose);
  if (st || done_early) {
    args_free(&a);
    return fmbd_cli_finish(st);
  }

  int rc = FMBD_OK;
  fmbd_mesh mesh = {0};
  fmbd_fe_body *body = NULL;
  fmbd_h5 *out = NULL;
  char *outname = NULL;
  static const char *const strip[] = {".geo", ".step", ".stp", ".brep",
                                      ".msh", ".stl",  ".off", NULL};
  FMBD_GCALL(fmbd_cli_output_name(a.input, a.output, strip, ".fe.h5", &outname));

  // --- mesh ---
  double t0 = fmbd_wall_s(), c0 = fmbd_cpu_s();
  FMBD_GCALL(fmbd_mesh_read(a.input, &a.mesh, &mesh));
  for (int i = 0; i < a.nbox; i++) {
    fmbd_err_contextf(a.input, "--group %s", a.boxes[i].name);
    FMBD_GCALL(fmbd_mesh_add_box_group(&mesh, a.boxes[i].name, a.boxes[i].lo, a.boxes[i].hi));
  }
  fmbd_log(FMBD_LOG_INFO,
           "%s: %lld nodes, %lld %s, %lld beam2, %d groups, meshing %.3f s wall, %.3f s cpu",
           a.input, (long long)mesh.nnodes, (long long)mesh.ntet,
           mesh.tet_nodes == 4    ? "tet4"
           : mesh.tet_nodes == 10 ? "tet10"
                                  : "tet",
           (long long)mesh.nbeam, mesh.ngroups, fmbd_wall_s() - t0, fmbd_cpu_s() - c0);
  if (mesh.ntet > 0) {
    fmbd_mesh_quality_stats q;
    fmbd_mesh_quality(&mesh, &q);
    fmbd_log(FMBD_LOG_INFO,
             "%s: element shape: worst aspect ratio %.3g (element %lld), smallest scaled "
             "Jacobian %.3g (element %lld), smallest det J over its straight-sided value %.3g "
             "(element %lld)",
             a.input, q.worst_ar, (long long)q.worst_ar_elem, q.min_sj, (long long)q.min_sj_elem,
             q.min_cr, (long long)q.min_cr_elem);
    if (q.n_ar_bad > 0 || q.n_sj_bad > 0) {
      bool by_ar = q.n_ar_bad > 0;
      int64_t e = by_ar ? q.worst_ar_elem : q.min_sj_elem;
      const int64_t *w = mesh.tet + e * mesh.tet_nodes;
      fmbd_log(FMBD_LOG_WARN,
               "%s: %lld tetrahedra with an aspect ratio above %g, %lld with a scaled Jacobian "
               "below %g; the worst: element %lld (0-based, corner at (%.6g, %.6g, %.6g)), "
               "aspect ratio %.3g, scaled Jacobian %.3g: K is ill-conditioned (fe2cb's "
               "residuals show by how much) and slivers act as stiff penalties between their "
               "nodes (docs/STABILITY.md, element shape)",
               a.input, (long long)q.n_ar_bad, FMBD_MESH_AR_WARN, (long long)q.n_sj_bad,
               FMBD_MESH_SJ_WARN, (long long)e, mesh.xyz[3 * w[0]], mesh.xyz[3 * w[0] + 1],
               mesh.xyz[3 * w[0] + 2], by_ar ? q.worst_ar : q.min_sj_ar,
               by_ar ? q.worst_ar_sj : q.min_sj);
    }
  }
  FMBD_GCALL(check_groups(&a, &mesh));
  if (mesh.nbeam > 0 && !(a.fe.area > 0)) {
    fmbd_err_context(a.input, "");
    FMBD_GFAIL(FMBD_ERR_USAGE,
               "the mesh has %lld beam elements: give their section with --section A,Iy,Iz,J or "
               "--circle R",
               (long long)mesh.nbeam);
  }

  // --- assemble ---
  t0 = fmbd_wall_s();
  c0 = fmbd_cpu_s();
  fmbd_progress("assembling %lld nodes", (long long)mesh.nnodes);
  fmbd_err_context(a.input, "");
  rc = fmbd_fe_assemble(&mesh, &a.fe, &body);
  fmbd_progress(NULL);
  if (rc) {
    goto done;
  }
  fmbd_log(FMBD_LOG_INFO, "assembly %.3f s wall, %.3f s cpu: %lld dofs, nnz(K) %lld, nnz(M) %lld",
           fmbd_wall_s() - t0, fmbd_cpu_s() - c0, (long long)body->ndof,
           (long long)fmbd_csr_nnz(body->K), (long long)fmbd_csr_nnz(body->M));

  // --- write ---
  t0 = fmbd_wall_s();
  c0 = fmbd_cpu_s();
  fmbd_progress("writing %s", strcmp(outname, "-") ? outname : "(stdout)");
  rc = fmbd_h5_create(outname, FMBD_FE_FORMAT, FMBD_FE_FORMAT_VERSION, &out);
  if (!rc) {
    rc = fmbd_h5_add_input(out, a.input, NULL);
  }
  if (!rc) {
    rc = fmbd_fe_write(out, body);
  }
  if (!rc) {
    rc = fmbd_h5_commit(&out, fmbd_cli_wall_s(), fmbd_cli_cpu_s());
  }
  fmbd_progress(NULL);
  if (rc) {
    goto done;
  }
  fmbd_log(FMBD_LOG_INFO, "writing %.3f s wall, %.3f s cpu", fmbd_wall_s() - t0, fmbd_cpu_s() - c0);
  {
    char elems[96] = "";
    if (body->ntet > 0) {
      snprintf(elems, sizeof elems, "%lld tet%d", (long long)body->ntet, body->tet_nodes);
    }
    if (body->nbeam > 0) {
      snprintf(elems + strlen(elems), sizeof elems - strlen(elems), "%s%lld beam2",
               elems[0] ? " + " : "", (long long)body->nbeam);
    }
    fmbd_cli_summary("%s: %lld nodes, %s, %d interfaces, %lld dofs, mass %.6g kg",
                     strcmp(outname, "-") ? outname : "(stdout)", (long long)body->nnodes, elems,
                     body->ninterfaces, (long long)body->ndof, body->mass);
  }
done:
  fmbd_h5_close(&out);
  fmbd_fe_body_destroy(&body);
  fmbd_mesh_destroy(&mesh);
  fmbd_free(outname);
  args_free(&a);
  return fmbd_cli_finish(rc);
}
