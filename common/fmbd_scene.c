// common/fmbd_scene.c: reading the YAML scene of fmbd-run into plain structs (docs/SCENE.md)
// SPDX-License-Identifier: MIT
//
// libyaml's document API loads the whole file into a node tree whose nodes keep their start
// marks (0-based line and column); every check below reports through fail_at(), which sets
// the error context "LINE:COLUMN" (1-based) and the scene file name.
#include "fmbd_scene.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <yaml.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

typedef struct ctx {
  yaml_document_t doc;
  const char *file;
  const char *body_dir;  // folder of body files (fe, cb, rflex); NULL: the scene's folder
  fmbd_scene *s;
} ctx;

static fmbd_scene_loc loc_of(const yaml_node_t *n) {
  fmbd_scene_loc l = {(int)n->start_mark.line + 1, (int)n->start_mark.column + 1};
  return l;
}

void fmbd_scene_context(const fmbd_scene *s, fmbd_scene_loc loc) {
  fmbd_err_contextf(s ? s->file : NULL, "%d:%d", loc.line, loc.column);
}

// Record a scene error at node n; returns FMBD_ERR_SCENE.
#define fail_at(c, n, ...)                                                  \
  (fmbd_err_contextf((c)->file, "%d:%d", loc_of(n).line, loc_of(n).column), \
   fmbd_err_set(FMBD_ERR_SCENE, __FILE__, __LINE__, __func__, __VA_ARGS__))

#define TRY(expr)        \
  do {                   \
    int rc_ = (expr);    \
    if (rc_) return rc_; \
  } while (0)

static yaml_node_t *node(ctx *c, int idx) {
  return yaml_document_get_node(&c->doc, idx);
}

static const char *kind_name(const yaml_node_t *n) {
  switch (n->type) {
    case YAML_SCALAR_NODE:
      return "a scalar";
    case YAML_SEQUENCE_NODE:
      return "a list";
    case YAML_MAPPING_NODE:
      return "a mapping";
    default:
      return "empty";
  }
}

static const char *scalar(const yaml_node_t *n) {
  return (const char *)n->data.scalar.value;
}

// --- mappings: allowed keys and lookup -----------------------------------------------------
static int check_map(ctx *c, yaml_node_t *m, const char *what, const char *const *allowed) {
  if (m->type != YAML_MAPPING_NODE) {
    return fail_at(c, m, "%s must be a mapping (key: value lines), not %s", what, kind_name(m));
  }
  for (yaml_node_pair_t *p = m->data.mapping.pairs.start; p < m->data.mapping.pairs.top; p++) {
    yaml_node_t *k = node(c, p->key);
    if (k->type != YAML_SCALAR_NODE) return fail_at(c, k, "a key in %s is not a name", what);
    bool ok = false;
    for (int i = 0; allowed[i]; i++) {
      if (strcmp(allowed[i], scalar(k)) == 0) ok = true;
    }
    if (!ok) return fail_at(c, k, "unknown key '%s' in %s", scalar(k), what);
    for (yaml_node_pair_t *q = m->data.mapping.pairs.start; q < p; q++) {
      yaml_node_t *k2 = node(c, q->key);
      if (k2->type == YAML_SCALAR_NODE && strcmp(scalar(k2), scalar(k)) == 0) {
        return fail_at(c, k, "duplicate key '%s' in %s (first at line %d)", scalar(k), what,
                       loc_of(k2).line);
      }
    }
  }
  return 0;
}

static yaml_node_t *get(ctx *c, yaml_node_t *m, const char *key) {
  if (!m || m->type != YAML_MAPPING_NODE) return NULL;
  for (yaml_node_pair_t *p = m->data.mapping.pairs.start; p < m->data.mapping.pairs.top; p++) {
    yaml_node_t *k = node(c, p->key);
    if (k->type == YAML_SCALAR_NODE && strcmp(scalar(k), key) == 0) return node(c, p->value);
  }
  return NULL;
}

// --- scalars -------------------------------------------------------------------------------
static int as_double(ctx *c, yaml_node_t *n, const char *what, double *v) {
  if (n->type != YAML_SCALAR_NODE) {
    return fail_at(c, n, "%s must be a number, not %s", what, kind_name(n));
  }
  const char *t = scalar(n);
  char *end = NULL;
  errno = 0;
  double x = strtod(t, &end);
  while (end && isspace((unsigned char)*end)) end++;
  if (end == t || *end || errno == ERANGE || !isfinite(x)) {
    return fail_at(c, n, "%s: '%s' is not a finite number", what, t);
  }
  *v = x;
  return 0;
}

static int as_int(ctx *c, yaml_node_t *n, const char *what, int64_t lo, int64_t *v) {
  if (n->type != YAML_SCALAR_NODE) {
    return fail_at(c, n, "%s must be an integer, not %s", what, kind_name(n));
  }
  const char *t = scalar(n);
  char *end = NULL;
  errno = 0;
  long long x = strtoll(t, &end, 10);
  if (end == t || *end || errno == ERANGE)
    return fail_at(c, n, "%s: '%s' is not an integer", what, t);
  if (x < lo) return fail_at(c, n, "%s must be >= %lld, not %lld", what, (long long)lo, x);
  *v = x;
  return 0;
}

static int as_bool(ctx *c, yaml_node_t *n, const char *what, bool *v) {
  if (n->type == YAML_SCALAR_NODE) {
    const char *t = scalar(n);
    if (!strcmp(t, "true") || !strcmp(t, "yes") || !strcmp(t, "on")) {
      *v = true;
      return 0;
    }
    if (!strcmp(t, "false") || !strcmp(t, "no") || !strcmp(t, "off")) {
      *v = false;
      return 0;
    }
  }
  return fail_at(c, n, "%s must be true or false", what);
}

static int as_str(ctx *c, yaml_node_t *n, const char *what, const char **v) {
  if (n->type != YAML_SCALAR_NODE || !scalar(n)[0]) {
    return fail_at(c, n, "%s must be a non-empty text, not %s", what, kind_name(n));
  }
  *v = scalar(n);
  return 0;
}

static int dup_str(ctx *c, yaml_node_t *n, const char *what, char **v) {
  const char *t;
  TRY(as_str(c, n, what, &t));
  fmbd_free(*v);
  *v = fmbd_strdup(t);
  if (!*v) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  return 0;
}

static int nitems(const yaml_node_t *n) {
  return (int)(n->data.sequence.items.top - n->data.sequence.items.start);
}

// A list of numbers, flattening one level of nesting ([[a,b,c],[d,e,f]]). want = 0: any
// count up to max; else exactly want (or one of the counts in alt).
static int as_numbers(ctx *c, yaml_node_t *n, const char *what, int max, double *v, int *count) {
  if (n->type != YAML_SEQUENCE_NODE) {
    return fail_at(c, n, "%s must be a list of numbers [a, b, ...], not %s", what, kind_name(n));
  }
  int k = 0;
  for (yaml_node_item_t *it = n->data.sequence.items.start; it < n->data.sequence.items.top; it++) {
    yaml_node_t *e = node(c, *it);
    if (e->type == YAML_SEQUENCE_NODE) {
      for (yaml_node_item_t *jt = e->data.sequence.items.start; jt < e->data.sequence.items.top;
           jt++) {
        if (k >= max) return fail_at(c, n, "%s has more than %d numbers", what, max);
        TRY(as_double(c, node(c, *jt), what, &v[k++]));
      }
    } else {
      if (k >= max) return fail_at(c, n, "%s has more than %d numbers", what, max);
      TRY(as_double(c, e, what, &v[k++]));
    }
  }
  *count = k;
  return 0;
}

static int as_vec3(ctx *c, yaml_node_t *n, const char *what, double v[3]) {
  double w[3];
  int k = 0;
  TRY(as_numbers(c, n, what, 3, w, &k));
  if (k != 3) return fail_at(c, n, "%s must have 3 components, not %d", what, k);
  memcpy(v, w, sizeof w);
  return 0;
}

static int as_unit(ctx *c, yaml_node_t *n, const char *what, double v[3]) {
  TRY(as_vec3(c, n, what, v));
  double r = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (!(r > 0)) return fail_at(c, n, "%s must not be the zero vector", what);
  for (int i = 0; i < 3; i++) v[i] /= r;
  return 0;
}

// An axis: x | y | z | -x ... or a vector.
static int as_axis(ctx *c, yaml_node_t *n, const char *what, double v[3]) {
  if (n->type == YAML_SCALAR_NODE) {
    const char *t = scalar(n);
    double sgn = 1;
    if (t[0] == '-' || t[0] == '+') {
      sgn = t[0] == '-' ? -1 : 1;
      t++;
    }
    if (t[0] >= 'x' && t[0] <= 'z' && !t[1]) {
      v[0] = v[1] = v[2] = 0;
      v[t[0] - 'x'] = sgn;
      return 0;
    }
    return fail_at(c, n, "%s must be x, y, z (optionally signed) or a vector [a, b, c]", what);
  }
  return as_unit(c, n, what, v);
}

// --- time functions ------------------------------------------------------------------------
static int parse_fn(ctx *c, yaml_node_t *n, const char *what, fmbd_mbs_fn *f) {
  memset(f, 0, sizeof *f);
  if (n->type == YAML_SCALAR_NODE) {
    f->kind = FMBD_MBS_FN_CONSTANT;
    return as_double(c, n, what, &f->value);
  }
  static const char *const keys[] = {
      "type",  "value",     "t0",     "t1", "v0", "v1",     "smooth", "amplitude", "frequency_hz",
      "phase", "phase_deg", "offset", "t",  "v",  "points", "rate",   "speed",     NULL};
  char buf[160];
  snprintf(buf, sizeof buf, "function of %s", what);
  TRY(check_map(c, n, buf, keys));
  yaml_node_t *ty = get(c, n, "type");
  if (!ty)
    return fail_at(c, n, "%s: missing key 'type' (constant, linear, ramp, spinup, sine or table)",
                   buf);
  const char *t;
  TRY(as_str(c, ty, "function type", &t));
  // keys each type accepts
  static const char *const kconst[] = {"type", "value", NULL};
  static const char *const kramp[] = {"type", "t0", "t1", "v0", "v1", "smooth", NULL};
  static const char *const ksine[] = {"type",   "amplitude", "frequency_hz", "phase", "phase_deg",
                                      "offset", NULL};
  static const char *const ktable[] = {"type", "t", "v", "points", NULL};
  static const char *const klinear[] = {"type", "t0", "v0", "rate", NULL};
  static const char *const kspinup[] = {"type", "t0", "t1", "v0", "speed", NULL};
  yaml_node_t *x;
  if (!strcmp(t, "constant")) {
    f->kind = FMBD_MBS_FN_CONSTANT;
    TRY(check_map(c, n, "a constant function", kconst));
    if (!(x = get(c, n, "value"))) return fail_at(c, n, "constant function: missing key 'value'");
    TRY(as_double(c, x, "value", &f->value));
  } else if (!strcmp(t, "ramp")) {
    f->kind = FMBD_MBS_FN_RAMP;
    TRY(check_map(c, n, "a ramp function", kramp));
    f->t0 = 0;
    f->v0 = 0;
    f->v1 = 1;
    if ((x = get(c, n, "t0"))) TRY(as_double(c, x, "t0", &f->t0));
    if (!(x = get(c, n, "t1"))) return fail_at(c, n, "ramp function: missing key 't1'");
    TRY(as_double(c, x, "t1", &f->t1));
    if (!(f->t1 > f->t0)) return fail_at(c, x, "ramp function: t1 must be later than t0");
    if ((x = get(c, n, "v0"))) TRY(as_double(c, x, "v0", &f->v0));
    if ((x = get(c, n, "v1"))) TRY(as_double(c, x, "v1", &f->v1));
    if ((x = get(c, n, "smooth"))) TRY(as_bool(c, x, "smooth", &f->smooth));
  } else if (!strcmp(t, "sine")) {
    f->kind = FMBD_MBS_FN_SINE;
    TRY(check_map(c, n, "a sine function", ksine));
    if (!(x = get(c, n, "amplitude")))
      return fail_at(c, n, "sine function: missing key 'amplitude'");
    TRY(as_double(c, x, "amplitude", &f->amplitude));
    if (!(x = get(c, n, "frequency_hz"))) {
      return fail_at(c, n, "sine function: missing key 'frequency_hz'");
    }
    TRY(as_double(c, x, "frequency_hz", &f->frequency_hz));
    if ((x = get(c, n, "phase"))) TRY(as_double(c, x, "phase", &f->phase));
    if ((x = get(c, n, "phase_deg"))) {
      if (get(c, n, "phase")) return fail_at(c, x, "give phase or phase_deg, not both");
      TRY(as_double(c, x, "phase_deg", &f->phase));
      f->phase *= M_PI / 180;
    }
    if ((x = get(c, n, "offset"))) TRY(as_double(c, x, "offset", &f->offset));
  } else if (!strcmp(t, "linear")) {
    f->kind = FMBD_MBS_FN_LINEAR;
    TRY(check_map(c, n, "a linear function", klinear));
    if (!(x = get(c, n, "rate"))) return fail_at(c, n, "linear function: missing key 'rate'");
    TRY(as_double(c, x, "rate", &f->rate));
    if ((x = get(c, n, "t0"))) TRY(as_double(c, x, "t0", &f->t0));
    if ((x = get(c, n, "v0"))) TRY(as_double(c, x, "v0", &f->v0));
  } else if (!strcmp(t, "spinup")) {
    f->kind = FMBD_MBS_FN_SPINUP;
    TRY(check_map(c, n, "a spinup function", kspinup));
    if (!(x = get(c, n, "speed"))) return fail_at(c, n, "spinup function: missing key 'speed'");
    TRY(as_double(c, x, "speed", &f->rate));
    if ((x = get(c, n, "t0"))) TRY(as_double(c, x, "t0", &f->t0));
    if (!(x = get(c, n, "t1"))) return fail_at(c, n, "spinup function: missing key 't1'");
    TRY(as_double(c, x, "t1", &f->t1));
    if (!(f->t1 > f->t0)) return fail_at(c, x, "spinup function: t1 must be later than t0");
    if ((x = get(c, n, "v0"))) TRY(as_double(c, x, "v0", &f->v0));
  } else if (!strcmp(t, "table")) {
    f->kind = FMBD_MBS_FN_TABLE;
    TRY(check_map(c, n, "a table function", ktable));
    yaml_node_t *pts = get(c, n, "points"), *tn = get(c, n, "t"), *vn = get(c, n, "v");
    if (pts && (tn || vn))
      return fail_at(c, pts, "table function: give points or t and v, not both");
    int m;
    if (pts) {
      if (pts->type != YAML_SEQUENCE_NODE)
        return fail_at(c, pts, "points must be a list of [t, v] pairs");
      m = nitems(pts);
    } else {
      if (!tn || !vn) return fail_at(c, n, "table function: missing key 'points' (or 't' and 'v')");
      if (tn->type != YAML_SEQUENCE_NODE) return fail_at(c, tn, "t must be a list of numbers");
      m = nitems(tn);
    }
    if (m < 2) return fail_at(c, pts ? pts : tn, "table function needs at least 2 points");
    // the points are the scene's (fmbd_scene_destroy frees them); fmbd_mbs_fn borrows them
    double *ft = fmbd_malloc(sizeof(double) * (size_t)m);
    double *fv = fmbd_malloc(sizeof(double) * (size_t)m);
    f->n = m;
    f->t = ft;
    f->v = fv;
    if (!ft || !fv) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    if (pts) {
      int i = 0;
      for (yaml_node_item_t *it = pts->data.sequence.items.start; it < pts->data.sequence.items.top;
           it++, i++) {
        double tv[2];
        int k = 0;
        yaml_node_t *e = node(c, *it);
        if (e->type != YAML_SEQUENCE_NODE)
          return fail_at(c, e, "a table point must be a pair [t, v]");
        TRY(as_numbers(c, e, "table point", 2, tv, &k));
        if (k != 2) return fail_at(c, e, "a table point must be a pair [t, v]");
        ft[i] = tv[0];
        fv[i] = tv[1];
      }
    } else {
      int k = 0;
      TRY(as_numbers(c, tn, "t", m, ft, &k));
      if (vn->type != YAML_SEQUENCE_NODE || nitems(vn) != m) {
        return fail_at(c, vn, "v must be a list of %d numbers, as many as t", m);
      }
      TRY(as_numbers(c, vn, "v", m, fv, &k));
    }
    for (int i = 1; i < m; i++) {
      if (!(ft[i] > ft[i - 1])) {
        return fail_at(c, pts ? pts : tn, "table function: times must increase (point %d)", i + 1);
      }
    }
  } else {
    return fail_at(c, ty,
                   "unknown function type '%s' (constant, linear, ramp, spinup, sine or table)", t);
  }
  return 0;
}

// --- names -------------------------------------------------------------------------------
static const char *const joint_names[] = {"spherical",   "revolute", "universal", "prismatic",
                                          "cylindrical", "fixed",    NULL};
const char *fmbd_scene_joint_name(int kind) {
  return kind >= 0 && kind <= FMBD_MBS_FIXED ? joint_names[kind] : "?";
}

int fmbd_scene_find_body(const fmbd_scene *s, const char *name) {
  for (int i = 0; i < s->nbodies; i++) {
    if (s->bodies[i].name && !strcmp(s->bodies[i].name, name)) return i;
  }
  return -1;
}

static int check_name(ctx *c, yaml_node_t *n, const char *what, char **name) {
  TRY(dup_str(c, n, what, name));
  for (const char *p = *name; *p; p++) {
    if (!(isalnum((unsigned char)*p) || *p == '_' || *p == '-' || *p == '.')) {
      return fail_at(c, n, "%s '%s': use letters, digits, '_', '-' and '.' only", what, *name);
    }
  }
  return 0;
}

// A body reference: a body name or "ground".
static int body_ref(ctx *c, yaml_node_t *n, const char *what, int *idx) {
  const char *t;
  TRY(as_str(c, n, what, &t));
  if (!strcmp(t, "ground")) {
    *idx = -1;
    return 0;
  }
  *idx = fmbd_scene_find_body(c->s, t);
  if (*idx < 0)
    return fail_at(c, n, "%s: no body named '%s' (bodies are declared under 'bodies')", what, t);
  return 0;
}

// --- rotation ------------------------------------------------------------------------------
static int parse_orientation(ctx *c, yaml_node_t *n, const char *what, double R[9]) {
  static const char *const keys[] = {"axis", "angle", "angle_deg", "matrix", NULL};
  TRY(check_map(c, n, what, keys));
  yaml_node_t *ax = get(c, n, "axis"), *an = get(c, n, "angle"), *ad = get(c, n, "angle_deg"),
              *mx = get(c, n, "matrix");
  if (mx) {
    if (ax || an || ad) return fail_at(c, mx, "%s: give matrix or axis and angle, not both", what);
    int k = 0;
    TRY(as_numbers(c, mx, "orientation matrix", 9, R, &k));
    if (k != 9) return fail_at(c, mx, "orientation matrix must have 9 numbers (3 rows of 3)");
    for (int i = 0; i < 3; i++) {
      for (int j = 0; j < 3; j++) {
        double d = 0;
        for (int l = 0; l < 3; l++) d += R[3 * l + i] * R[3 * l + j];
        if (fabs(d - (i == j)) > 1e-6) {
          return fail_at(c, mx, "orientation matrix is not a rotation (R'R differs from I by %.2g)",
                         fabs(d - (i == j)));
        }
      }
    }
    double det = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) +
                 R[2] * (R[3] * R[7] - R[4] * R[6]);
    if (det < 0) return fail_at(c, mx, "orientation matrix is a reflection (det = -1)");
    return 0;
  }
  if (!ax)
    return fail_at(c, n, "%s: missing key 'axis' (with 'angle' or 'angle_deg') or 'matrix'", what);
  double a[3], th = 0;
  TRY(as_axis(c, ax, "orientation axis", a));
  if (an && ad) return fail_at(c, ad, "%s: give angle or angle_deg, not both", what);
  if (!an && !ad) return fail_at(c, n, "%s: missing key 'angle' or 'angle_deg'", what);
  if (an) TRY(as_double(c, an, "angle", &th));
  if (ad) {
    TRY(as_double(c, ad, "angle_deg", &th));
    th *= M_PI / 180;
  }
  fmbd_mbs_rotation_axis_angle(a, th, R);
  return 0;
}

// --- attachments -------------------------------------------------------------------------
// Reads point / interface / node / nearest from mapping n (which may hold other keys too).
static int parse_at_keys(ctx *c, yaml_node_t *n, const char *what, fmbd_scene_at *at) {
  yaml_node_t *pt = get(c, n, "point"), *itf = get(c, n, "interface"), *nd = get(c, n, "node"),
              *ne = get(c, n, "nearest");
  int given = !!pt + !!itf + !!nd + !!ne;
  if (given > 1) {
    yaml_node_t *second = itf && pt ? itf : nd && (pt || itf) ? nd : ne;
    return fail_at(c, second, "%s: give one of point, interface, node or nearest", what);
  }
  at->kind = FMBD_AT_DEFAULT;
  at->loc = loc_of(n);
  if (pt) {
    at->kind = FMBD_AT_POINT;
    at->loc = loc_of(pt);
    TRY(as_vec3(c, pt, "point", at->p));
  } else if (itf) {
    at->kind = FMBD_AT_INTERFACE;
    at->loc = loc_of(itf);
    TRY(dup_str(c, itf, "interface", &at->interface));
  } else if (nd) {
    at->kind = FMBD_AT_NODE;
    at->loc = loc_of(nd);
    TRY(as_int(c, nd, "node", 0, &at->node));
  } else if (ne) {
    at->kind = FMBD_AT_NEAREST;
    at->loc = loc_of(ne);
    TRY(as_vec3(c, ne, "nearest", at->p));
  }
  return 0;
}

// --- sections ----------------------------------------------------------------------------
static int grow(void **arr, int n, size_t size) {
  void *p = fmbd_realloc(*arr, size * (size_t)(n + 1));
  if (!p) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  *arr = p;
  memset((char *)p + size * (size_t)n, 0, size);
  return 0;
}

static int parse_solver(ctx *c, yaml_node_t *n) {
  static const char *const keys[] = {"t_end",      "rho_inf",  "step",      "first_step",
                                     "max_step",   "min_step", "tolerance", "newton_tol",
                                     "newton_max", NULL};
  TRY(check_map(c, n, "solver", keys));
  fmbd_mbs_settings *v = &c->s->solver;
  yaml_node_t *x;
  if (!(x = get(c, n, "t_end"))) return fail_at(c, n, "solver: missing key 't_end' (end time, s)");
  TRY(as_double(c, x, "t_end", &v->t_end));
  if (!(v->t_end > 0)) return fail_at(c, x, "t_end must be positive");
  if ((x = get(c, n, "rho_inf"))) {
    TRY(as_double(c, x, "rho_inf", &v->rho_inf));
    if (v->rho_inf < 0 || v->rho_inf > 1) return fail_at(c, x, "rho_inf must be in [0, 1]");
  }
  if ((x = get(c, n, "step"))) {
    v->fixed = true;
    TRY(as_double(c, x, "step", &v->step));
    if (!(v->step > 0)) return fail_at(c, x, "step must be positive");
    static const char *const vk[] = {"first_step", "max_step", "tolerance", NULL};
    for (int i = 0; vk[i]; i++) {
      yaml_node_t *y = get(c, n, vk[i]);
      if (y) return fail_at(c, y, "'%s' is for variable steps; a fixed 'step' is given", vk[i]);
    }
  }
  struct {
    const char *k;
    double *p;
  } pos[] = {{"first_step", &v->first_step},
             {"max_step", &v->max_step},
             {"min_step", &v->min_step},
             {"tolerance", &v->tolerance},
             {"newton_tol", &v->newton_tol}};
  for (size_t i = 0; i < sizeof pos / sizeof pos[0]; i++) {
    if ((x = get(c, n, pos[i].k))) {
      TRY(as_double(c, x, pos[i].k, pos[i].p));
      if (!(*pos[i].p > 0)) return fail_at(c, x, "%s must be positive", pos[i].k);
    }
  }
  if ((x = get(c, n, "newton_max"))) {
    int64_t k;
    TRY(as_int(c, x, "newton_max", 1, &k));
    v->newton_max = (int)k;
  }
  if (!v->fixed && v->first_step > v->max_step) {
    return fail_at(c, get(c, n, "first_step") ? get(c, n, "first_step") : n,
                   "first_step %g is larger than max_step %g", v->first_step, v->max_step);
  }
  return 0;
}

static void cylinder_inertia(double m, double r, double L, const double a[3], double I[9]) {
  double Ia = m * r * r / 2, It = m * (3 * r * r + L * L) / 12;
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) I[3 * i + j] = It * (i == j) + (Ia - It) * a[i] * a[j];
  }
}

static int parse_geometry(ctx *c, yaml_node_t *n, fmbd_scene_body *b, const char *what) {
  static const char *const keys[] = {"shape", "length", "radius", "size", "density",
                                     "mass",  "axis",   "center", NULL};
  TRY(check_map(c, n, what, keys));
  yaml_node_t *sh = get(c, n, "shape"), *x;
  if (!sh) return fail_at(c, n, "%s: missing key 'shape' (cylinder, box or sphere)", what);
  const char *shape;
  TRY(as_str(c, sh, "shape", &shape));
  double vol = 0, rho = 0, m = 0, r = 0, L = 0, sz[3] = {0, 0, 0}, a[3] = {1, 0, 0};
  int kind;
  if (!strcmp(shape, "cylinder")) {
    kind = 0;
  } else if (!strcmp(shape, "box")) {
    kind = 1;
  } else if (!strcmp(shape, "sphere")) {
    kind = 2;
  } else {
    return fail_at(c, sh, "unknown shape '%s' (cylinder, box or sphere)", shape);
  }
  const char *need[3][3] = {
      {"length", "radius", NULL}, {"size", NULL, NULL}, {"radius", NULL, NULL}};
  for (int i = 0; need[kind][i]; i++) {
    if (!get(c, n, need[kind][i]))
      return fail_at(c, n, "%s: a %s needs key '%s'", what, shape, need[kind][i]);
  }
  const char *other[3][3] = {
      {"size", NULL}, {"length", "radius", "axis"}, {"length", "size", "axis"}};
  for (int i = 0; i < 3 && other[kind][i]; i++) {
    if ((x = get(c, n, other[kind][i])))
      return fail_at(c, x, "key '%s' does not apply to a %s", other[kind][i], shape);
  }
  if ((x = get(c, n, "length"))) TRY(as_double(c, x, "length", &L));
  if ((x = get(c, n, "radius"))) TRY(as_double(c, x, "radius", &r));
  if ((x = get(c, n, "size"))) TRY(as_vec3(c, x, "size", sz));
  if ((x = get(c, n, "axis"))) TRY(as_axis(c, x, "axis", a));
  if (kind == 0) {
    if (!(L > 0) || !(r > 0)) return fail_at(c, n, "%s: length and radius must be positive", what);
    vol = M_PI * r * r * L;
  } else if (kind == 1) {
    if (!(sz[0] > 0 && sz[1] > 0 && sz[2] > 0))
      return fail_at(c, n, "%s: size must be positive", what);
    vol = sz[0] * sz[1] * sz[2];
  } else {
    if (!(r > 0)) return fail_at(c, n, "%s: radius must be positive", what);
    vol = 4 * M_PI * r * r * r / 3;
  }
  yaml_node_t *dn = get(c, n, "density"), *mn = get(c, n, "mass");
  if (dn && mn) return fail_at(c, mn, "%s: give density or mass, not both", what);
  if (!dn && !mn) return fail_at(c, n, "%s: missing key 'density' (kg/m^3) or 'mass' (kg)", what);
  if (dn) {
    TRY(as_double(c, dn, "density", &rho));
    m = rho * vol;
  } else {
    TRY(as_double(c, mn, "mass", &m));
  }
  if (!(m > 0)) {
    return fail_at(c, dn ? dn : mn,
                   "%s: the mass must be positive (a massless body makes the mass matrix singular)",
                   what);
  }
  b->mass = m;
  memset(b->com, 0, sizeof b->com);
  if ((x = get(c, n, "center"))) TRY(as_vec3(c, x, "center", b->com));
  if (kind == 0) {
    cylinder_inertia(m, r, L, a, b->inertia);
  } else {
    memset(b->inertia, 0, sizeof b->inertia);
    if (kind == 1) {
      b->inertia[0] = m * (sz[1] * sz[1] + sz[2] * sz[2]) / 12;
      b->inertia[4] = m * (sz[0] * sz[0] + sz[2] * sz[2]) / 12;
      b->inertia[8] = m * (sz[0] * sz[0] + sz[1] * sz[1]) / 12;
    } else {
      b->inertia[0] = b->inertia[4] = b->inertia[8] = 0.4 * m * r * r;
    }
  }
  return 0;
}

static int parse_inertia(ctx *c, yaml_node_t *n, double I[9]) {
  double v[9];
  int k = 0;
  TRY(as_numbers(c, n, "inertia", 9, v, &k));
  memset(I, 0, 9 * sizeof(double));
  if (k == 3) {
    I[0] = v[0], I[4] = v[1], I[8] = v[2];
  } else if (k == 6) {  // xx yy zz xy yz zx
    I[0] = v[0], I[4] = v[1], I[8] = v[2];
    I[1] = I[3] = v[3];
    I[5] = I[7] = v[4];
    I[2] = I[6] = v[5];
  } else if (k == 9) {
    memcpy(I, v, sizeof v);
    for (int i = 0; i < 3; i++) {
      for (int j = 0; j < i; j++) {
        if (fabs(I[3 * i + j] - I[3 * j + i]) > 1e-12 * (fabs(I[0]) + fabs(I[4]) + fabs(I[8]))) {
          return fail_at(c, n, "inertia matrix is not symmetric");
        }
      }
    }
  } else {
    return fail_at(c, n, "inertia: give 3 (principal), 6 (xx yy zz xy yz zx) or 9 numbers, not %d",
                   k);
  }
  // positive definite (Sylvester) and the triangle inequality of principal moments
  double d1 = I[0], d2 = I[0] * I[4] - I[1] * I[3];
  double d3 = I[0] * (I[4] * I[8] - I[5] * I[7]) - I[1] * (I[3] * I[8] - I[5] * I[6]) +
              I[2] * (I[3] * I[7] - I[4] * I[6]);
  if (!(d1 > 0 && d2 > 0 && d3 > 0)) {
    return fail_at(c, n, "inertia is not positive definite (the mass matrix would be singular)");
  }
  if (k == 3 && (I[0] > I[4] + I[8] * (1 + 1e-12) || I[4] > I[0] + I[8] * (1 + 1e-12) ||
                 I[8] > I[0] + I[4] * (1 + 1e-12))) {
    return fail_at(c, n, "principal moments of inertia violate the triangle inequality");
  }
  return 0;
}

static int parse_body(ctx *c, yaml_node_t *n, int idx) {
  fmbd_scene_body *b = &c->s->bodies[idx];
  char what[160];
  snprintf(what, sizeof what, "body %d", idx + 1);
  if (n->type != YAML_MAPPING_NODE)
    return fail_at(c, n, "%s must be a mapping, not %s", what, kind_name(n));
  b->loc = loc_of(n);
  yaml_node_t *x = get(c, n, "name");
  if (!x) return fail_at(c, n, "%s: missing key 'name'", what);
  TRY(check_name(c, x, "body name", &b->name));
  if (!strcmp(b->name, "ground"))
    return fail_at(c, x, "'ground' is reserved for the fixed world frame");
  for (int i = 0; i < idx; i++) {
    if (!strcmp(c->s->bodies[i].name, b->name)) {
      return fail_at(c, x, "a second body named '%s' (the first is at line %d)", b->name,
                     c->s->bodies[i].loc.line);
    }
  }
  snprintf(what, sizeof what, "body '%s'", b->name);
  static const char *const keys[] = {"name",
                                     "type",
                                     "mass",
                                     "com",
                                     "inertia",
                                     "geometry",
                                     "file",
                                     "modes",
                                     "damping_ratio",
                                     "make",
                                     "position",
                                     "orientation",
                                     "velocity",
                                     "angular_velocity",
                                     "basis",
                                     "basis_body",
                                     "basis_kind",
                                     "inertia_coupling",
                                     NULL};
  TRY(check_map(c, n, what, keys));
  const char *type = "rigid";
  if ((x = get(c, n, "type"))) TRY(as_str(c, x, "body type", &type));
  // defaults: identity pose, at rest
  for (int i = 0; i < 9; i++) b->rotation[i] = (i % 4 == 0);
  if (!strcmp(type, "rigid")) {
    b->kind = FMBD_SCENE_RIGID;
    static const char *const flexkeys[] = {
        "file",       "modes",      "damping_ratio",    "make", "basis",
        "basis_body", "basis_kind", "inertia_coupling", NULL};
    for (int i = 0; flexkeys[i]; i++) {
      if ((x = get(c, n, flexkeys[i]))) {
        return fail_at(c, x, "key '%s' is for flexible bodies; %s is rigid (type: flexible?)",
                       flexkeys[i], what);
      }
    }
    yaml_node_t *g = get(c, n, "geometry"), *mn = get(c, n, "mass"), *in = get(c, n, "inertia"),
                *cn = get(c, n, "com");
    if (g) {
      if (mn || in || cn) {
        return fail_at(c,
                       mn   ? mn
                       : in ? in
                            : cn,
                       "%s: give geometry or mass/com/inertia, not both", what);
      }
      TRY(parse_geometry(c, g, b, "geometry"));
    } else {
      if (!mn) return fail_at(c, n, "%s: missing key 'mass' (or 'geometry')", what);
      if (!in) return fail_at(c, n, "%s: missing key 'inertia' (or 'geometry')", what);
      TRY(as_double(c, mn, "mass", &b->mass));
      if (!(b->mass > 0)) {
        return fail_at(c, mn,
                       "%s: mass must be positive (a massless body makes the mass matrix singular)",
                       what);
      }
      if (cn) TRY(as_vec3(c, cn, "com", b->com));
      TRY(parse_inertia(c, in, b->inertia));
    }
  } else if (!strcmp(type, "flexible")) {
    b->kind = FMBD_SCENE_FLEXIBLE;
    static const char *const rigkeys[] = {"mass", "com", "inertia", "geometry", NULL};
    for (int i = 0; rigkeys[i]; i++) {
      if ((x = get(c, n, rigkeys[i]))) {
        return fail_at(
            c, x, "key '%s' is for rigid bodies; a flexible body takes its inertia from its file",
            rigkeys[i]);
      }
    }
    if (!(x = get(c, n, "file")))
      return fail_at(c, n, "%s: missing key 'file' (a .rflex.h5 or .cb.h5)", what);
    b->file_loc = loc_of(x);
    const char *f;
    TRY(as_str(c, x, "file", &f));
    // resolve against the scene's folder
    const char *bdir = c->body_dir ? c->body_dir : c->s->dir;
    size_t len = strlen(bdir) + strlen(f) + 2;
    b->file = fmbd_malloc(len);
    if (!b->file) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    if (f[0] == '/' || !strcmp(bdir, ".")) {
      snprintf(b->file, len, "%s", f);
    } else {
      snprintf(b->file, len, "%s/%s", bdir, f);
    }
    if ((x = get(c, n, "basis"))) {  // a global-mode (GMc) basis from gmsolve
      b->basis_loc = loc_of(x);
      TRY(as_str(c, x, "basis", &f));
      len = strlen(bdir) + strlen(f) + 2;
      b->basis = fmbd_malloc(len);
      if (!b->basis) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
      if (f[0] == '/' || !strcmp(bdir, ".")) {
        snprintf(b->basis, len, "%s", f);
      } else {
        snprintf(b->basis, len, "%s/%s", bdir, f);
      }
    }
    if ((x = get(c, n, "basis_body"))) {
      if (!b->basis) return fail_at(c, x, "%s: 'basis_body' needs 'basis'", what);
      TRY(as_str(c, x, "basis_body", &f));
      b->basis_body = fmbd_strdup(f);
      if (!b->basis_body) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    if ((x = get(c, n, "basis_kind"))) {  // gmc (the body's own) or gms (shared coordinates)
      if (!b->basis) return fail_at(c, x, "%s: 'basis_kind' needs 'basis'", what);
      TRY(as_str(c, x, "basis_kind", &f));
      if (!strcmp(f, "gms"))
        b->basis_gms = true;
      else if (strcmp(f, "gmc"))
        return fail_at(c, x, "%s: basis_kind '%s': gmc or gms", what, f);
    }
    if ((x = get(c, n, "modes"))) TRY(as_int(c, x, "modes", 1, &b->modes));
    if ((x = get(c, n, "damping_ratio"))) {
      TRY(as_double(c, x, "damping_ratio", &b->damping_ratio));
      if (b->damping_ratio < 0) return fail_at(c, x, "damping_ratio must not be negative");
      b->damping_set = true;
    }
    if ((x = get(c, n, "inertia_coupling"))) {  // full (default) or partial (docs/SCENE.md)
      b->inertia_loc = loc_of(x);
      TRY(as_str(c, x, "inertia_coupling", &f));
      if (!strcmp(f, "partial"))
        b->inertia_partial = true;
      else if (strcmp(f, "full"))
        return fail_at(c, x, "%s: inertia_coupling '%s': full or partial", what, f);
    }
    if ((x = get(c, n, "make"))) {
      static const char *const mk[] = {"geometry", "mesh2fe", "fe",       "fe2cb",   "cb",
                                       "cbcheck",  "whole",   "gm_scene", "gmsolve", NULL};
      TRY(check_map(c, x, "make", mk));
      yaml_node_t *w = get(c, x, "whole");
      if (w) TRY(as_bool(c, w, "whole", &b->chain.whole));
      struct {
        const char *k;
        char **p;
        bool path;
      } fields[] = {{"geometry", &b->chain.geometry, true},
                    {"mesh2fe", &b->chain.mesh2fe_args, false},
                    {"fe", &b->chain.fe, true},
                    {"fe2cb", &b->chain.fe2cb_args, false},
                    {"cb", &b->chain.cb, true},
                    {"cbcheck", &b->chain.cbcheck_args, false},
                    {"gm_scene", &b->chain.gm_scene, true},
                    {"gmsolve", &b->chain.gmsolve_args, false}};
      for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++) {
        yaml_node_t *y = get(c, x, fields[i].k);
        if (!y) continue;
        const char *t;
        if (y->type == YAML_SCALAR_NODE && !scalar(y)[0] && !fields[i].path) {
          t = "";
        } else {
          TRY(as_str(c, y, fields[i].k, &t));
        }
        // the geometry and the gm scene are sources beside the scene; fe and cb files are made,
        // beside the body file
        bool src = i == 0 || fields[i].p == &b->chain.gm_scene;
        const char *fdir = src ? c->s->dir : c->body_dir ? c->body_dir : c->s->dir;
        size_t l2 = strlen(fdir) + strlen(t) + 2;
        *fields[i].p = fmbd_malloc(l2);
        if (!*fields[i].p) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
        if (!fields[i].path || t[0] == '/' || !strcmp(fdir, ".")) {
          snprintf(*fields[i].p, l2, "%s", t);
        } else {
          snprintf(*fields[i].p, l2, "%s/%s", fdir, t);
        }
      }
      if (b->chain.mesh2fe_args && !b->chain.geometry)
        return fail_at(c, x, "make: 'mesh2fe' options need 'geometry'");
      // a full-model body (.fe.h5) is the file mesh2fe makes
      size_t fl = strlen(b->file);
      bool full = fl >= 6 && !strcmp(b->file + fl - 6, ".fe.h5");
      if (b->chain.geometry && !b->chain.fe && !full)
        return fail_at(c, x, "make: 'geometry' needs 'fe' (the fe file it makes)");
      if (b->chain.fe2cb_args && !b->chain.fe)
        return fail_at(c, x, "make: 'fe2cb' options need 'fe'");
      if (b->chain.cbcheck_args && !b->chain.cb)
        return fail_at(c, x, "make: 'cbcheck' options need 'cb'");
      if (b->chain.gm_scene && !b->basis)
        return fail_at(c, x,
                       "make: 'gm_scene' (the scene gmsolve makes the basis from) needs 'basis'");
      if (b->chain.gmsolve_args && !b->chain.gm_scene)
        return fail_at(c, x, "make: 'gmsolve' options need 'gm_scene'");
    }
  } else {
    return fail_at(c, x, "unknown body type '%s' (rigid or flexible)", type);
  }
  if ((x = get(c, n, "position"))) TRY(as_vec3(c, x, "position", b->position));
  if ((x = get(c, n, "orientation"))) TRY(parse_orientation(c, x, "orientation", b->rotation));
  if ((x = get(c, n, "velocity"))) TRY(as_vec3(c, x, "velocity", b->velocity));
  if ((x = get(c, n, "angular_velocity")))
    TRY(as_vec3(c, x, "angular_velocity", b->angular_velocity));
  return 0;
}

static int parse_joint(ctx *c, yaml_node_t *n, int idx) {
  fmbd_scene_joint *j = &c->s->joints[idx];
  char what[160];
  snprintf(what, sizeof what, "joint %d", idx + 1);
  if (n->type != YAML_MAPPING_NODE)
    return fail_at(c, n, "%s must be a mapping, not %s", what, kind_name(n));
  j->loc = loc_of(n);
  yaml_node_t *x = get(c, n, "name");
  if (x) {
    TRY(check_name(c, x, "joint name", &j->name));
    for (int i = 0; i < idx; i++) {
      if (!strcmp(c->s->joints[i].name, j->name))
        return fail_at(c, x, "a second joint named '%s'", j->name);
    }
  } else {
    char nm[32];
    snprintf(nm, sizeof nm, "joint%d", idx + 1);
    j->name = fmbd_strdup(nm);
    if (!j->name) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  snprintf(what, sizeof what, "joint '%s'", j->name);
  static const char *const keys[] = {"name", "type", "body1", "body2", "point",
                                     "at1",  "at2",  "axis",  "axis2", NULL};
  TRY(check_map(c, n, what, keys));
  if (!(x = get(c, n, "type"))) {
    return fail_at(
        c, n,
        "%s: missing key 'type' (spherical, revolute, universal, prismatic, cylindrical or fixed)",
        what);
  }
  const char *t;
  TRY(as_str(c, x, "joint type", &t));
  j->kind = -1;
  for (int i = 0; joint_names[i]; i++) {
    if (!strcmp(joint_names[i], t)) j->kind = i;
  }
  if (j->kind < 0) {
    return fail_at(
        c, x,
        "unknown joint type '%s' (spherical, revolute, universal, prismatic, cylindrical or fixed)",
        t);
  }
  const char *bk[2] = {"body1", "body2"}, *ak[2] = {"at1", "at2"};
  for (int s = 0; s < 2; s++) {
    if (!(x = get(c, n, bk[s])))
      return fail_at(c, n, "%s: missing key '%s' (a body name or ground)", what, bk[s]);
    j->body_loc[s] = loc_of(x);
    TRY(body_ref(c, x, bk[s], &j->body[s]));
    if ((x = get(c, n, ak[s]))) {
      static const char *const atk[] = {"point", "interface", "node", "nearest", NULL};
      char w2[200];
      snprintf(w2, sizeof w2, "%s of %s", ak[s], what);
      TRY(check_map(c, x, w2, atk));
      TRY(parse_at_keys(c, x, w2, &j->at[s]));
      if (j->at[s].kind == FMBD_AT_DEFAULT)
        return fail_at(c, x, "%s: give point, interface, node or nearest", w2);
      if (j->body[s] < 0 && j->at[s].kind != FMBD_AT_POINT) {
        return fail_at(c, x, "%s: ground has only points (point: [x, y, z])", w2);
      }
      if (j->body[s] >= 0 && c->s->bodies[j->body[s]].kind == FMBD_SCENE_RIGID &&
          j->at[s].kind != FMBD_AT_POINT) {
        return fail_at(
            c, x,
            "%s: body '%s' is rigid: it has points (point: [x, y, z]), not nodes or interfaces", w2,
            c->s->bodies[j->body[s]].name);
      }
    }
  }
  if (j->body[0] == j->body[1]) {
    return fail_at(c, n, "%s joins %s to itself", what,
                   j->body[0] < 0 ? "ground" : c->s->bodies[j->body[0]].name);
  }
  if ((x = get(c, n, "point"))) {
    j->has_point = true;
    j->point_loc = loc_of(x);
    TRY(as_vec3(c, x, "point", j->point));
  } else {
    j->point_loc = j->loc;
    // the point must follow from an attachment on a flexible body
    bool from_at = false;
    for (int s = 0; s < 2; s++) from_at |= j->at[s].kind != FMBD_AT_DEFAULT;
    if (!from_at)
      return fail_at(c, n, "%s: missing key 'point' (the joint's world point at the start)", what);
  }
  bool wants_axis = j->kind == FMBD_MBS_REVOLUTE || j->kind == FMBD_MBS_PRISMATIC ||
                    j->kind == FMBD_MBS_CYLINDRICAL || j->kind == FMBD_MBS_UNIVERSAL;
  x = get(c, n, "axis");
  if (wants_axis && !x) return fail_at(c, n, "%s: a %s joint needs key 'axis'", what, t);
  if (!wants_axis && x) return fail_at(c, x, "key 'axis' does not apply to a %s joint", t);
  if (x) TRY(as_axis(c, x, "axis", j->axis));
  x = get(c, n, "axis2");
  if (j->kind == FMBD_MBS_UNIVERSAL) {
    if (!x)
      return fail_at(c, n, "%s: a universal joint needs key 'axis2' (the axis fixed in body2)",
                     what);
    TRY(as_axis(c, x, "axis2", j->axis2));
    double d = j->axis[0] * j->axis2[0] + j->axis[1] * j->axis2[1] + j->axis[2] * j->axis2[2];
    if (fabs(d) > 1e-9)
      return fail_at(c, x, "universal joint: axis2 must be orthogonal to axis (cos = %.3g)", d);
  } else if (x) {
    return fail_at(c, x, "key 'axis2' applies to universal joints only");
  }
  return 0;
}

static int find_joint(ctx *c, yaml_node_t *n, const char *what, int *idx) {
  const char *t;
  TRY(as_str(c, n, what, &t));
  for (int i = 0; i < c->s->njoints; i++) {
    if (!strcmp(c->s->joints[i].name, t)) {
      *idx = i;
      return 0;
    }
  }
  return fail_at(c, n, "%s: no joint named '%s'", what, t);
}

static int parse_driver(ctx *c, yaml_node_t *n, int idx) {
  fmbd_scene_driver *d = &c->s->drivers[idx];
  char what[160];
  snprintf(what, sizeof what, "driver %d", idx + 1);
  if (n->type != YAML_MAPPING_NODE)
    return fail_at(c, n, "%s must be a mapping, not %s", what, kind_name(n));
  d->loc = loc_of(n);
  yaml_node_t *x = get(c, n, "name");
  if (x) {
    TRY(check_name(c, x, "driver name", &d->name));
    snprintf(what, sizeof what, "driver '%s'", d->name);
  } else {
    d->name = fmbd_malloc(32);
    if (!d->name) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    snprintf(d->name, 32, "driver%d", idx + 1);
  }
  static const char *const keys[] = {"name", "joint", "body", "coordinate", "function", NULL};
  TRY(check_map(c, n, what, keys));
  d->joint = d->body = -1;
  yaml_node_t *jn = get(c, n, "joint"), *bn = get(c, n, "body"), *cn = get(c, n, "coordinate");
  if (jn && bn) return fail_at(c, bn, "%s: give joint or body, not both", what);
  if (jn) {
    if (cn)
      return fail_at(
          c, cn,
          "%s: 'coordinate' is for body drivers; a joint driver drives the joint's own coordinate",
          what);
    TRY(find_joint(c, jn, "joint", &d->joint));
    int k = c->s->joints[d->joint].kind;
    if (k != FMBD_MBS_REVOLUTE && k != FMBD_MBS_PRISMATIC && k != FMBD_MBS_CYLINDRICAL) {
      return fail_at(
          c, jn,
          "%s: a %s joint has no single coordinate to drive (revolute, prismatic or cylindrical)",
          what, joint_names[k]);
    }
  } else if (bn) {
    TRY(body_ref(c, bn, "body", &d->body));
    if (d->body < 0) return fail_at(c, bn, "%s: ground cannot be driven", what);
    if (!cn) return fail_at(c, n, "%s: missing key 'coordinate' (x, y or z)", what);
    const char *t;
    TRY(as_str(c, cn, "coordinate", &t));
    if (strlen(t) != 1 || t[0] < 'x' || t[0] > 'z')
      return fail_at(c, cn, "coordinate must be x, y or z, not '%s'", t);
    d->coordinate = t[0] - 'x';
  } else {
    return fail_at(c, n, "%s: missing key 'joint' (or 'body' and 'coordinate')", what);
  }
  if (!(x = get(c, n, "function"))) return fail_at(c, n, "%s: missing key 'function'", what);
  TRY(parse_fn(c, x, what, &d->fn));
  for (int i = 0; i < idx; i++) {
    fmbd_scene_driver *e = &c->s->drivers[i];
    if ((d->joint >= 0 && e->joint == d->joint) ||
        (d->body >= 0 && e->body == d->body && e->coordinate == d->coordinate)) {
      return fail_at(c, n, "%s drives the same coordinate as driver '%s' (line %d)", what, e->name,
                     e->loc.line);
    }
  }
  return 0;
}

static int parse_load(ctx *c, yaml_node_t *n, int idx) {
  fmbd_scene_load *l = &c->s->loads[idx];
  char what[160];
  snprintf(what, sizeof what, "load %d", idx + 1);
  if (n->type != YAML_MAPPING_NODE)
    return fail_at(c, n, "%s must be a mapping, not %s", what, kind_name(n));
  l->loc = loc_of(n);
  yaml_node_t *x = get(c, n, "name");
  if (x) {
    TRY(check_name(c, x, "load name", &l->name));
    snprintf(what, sizeof what, "load '%s'", l->name);
  } else {
    l->name = fmbd_malloc(32);
    if (!l->name) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    snprintf(l->name, 32, "load%d", idx + 1);
  }
  static const char *const keys[] = {"name",      "type",     "body",    "point",
                                     "interface", "node",     "nearest", "direction",
                                     "frame",     "function", NULL};
  TRY(check_map(c, n, what, keys));
  if (!(x = get(c, n, "type")))
    return fail_at(c, n, "%s: missing key 'type' (force or torque)", what);
  const char *t;
  TRY(as_str(c, x, "load type", &t));
  if (!strcmp(t, "force")) {
    l->kind = FMBD_LOAD_FORCE;
  } else if (!strcmp(t, "torque")) {
    l->kind = FMBD_LOAD_TORQUE;
  } else {
    return fail_at(c, x, "unknown load type '%s' (force or torque)", t);
  }
  if (!(x = get(c, n, "body"))) return fail_at(c, n, "%s: missing key 'body'", what);
  TRY(body_ref(c, x, "body", &l->body));
  if (l->body < 0) return fail_at(c, x, "%s: a load on ground does nothing", what);
  TRY(parse_at_keys(c, n, what, &l->at));
  if (l->kind == FMBD_LOAD_TORQUE && l->at.kind == FMBD_AT_POINT) {
    return fail_at(c, get(c, n, "point"), "%s: a torque has no point of application", what);
  }
  if (c->s->bodies[l->body].kind == FMBD_SCENE_RIGID && l->at.kind != FMBD_AT_POINT &&
      l->at.kind != FMBD_AT_DEFAULT) {
    return fail_at(c, n, "%s: body '%s' is rigid: give 'point' (body frame)", what,
                   c->s->bodies[l->body].name);
  }
  if (!(x = get(c, n, "direction")))
    return fail_at(c, n, "%s: missing key 'direction' (a vector, scaled by function)", what);
  TRY(as_vec3(c, x, "direction", l->direction));
  if ((x = get(c, n, "frame"))) {
    TRY(as_str(c, x, "frame", &t));
    if (!strcmp(t, "body")) {
      l->body_frame = true;
    } else if (strcmp(t, "world")) {
      return fail_at(c, x, "frame must be world or body, not '%s'", t);
    }
  }
  if ((x = get(c, n, "function"))) {
    TRY(parse_fn(c, x, what, &l->fn));
  } else {
    l->fn.kind = FMBD_MBS_FN_CONSTANT;
    l->fn.value = 1;
  }
  return 0;
}

static int parse_outputs(ctx *c, yaml_node_t *n) {
  static const char *const keys[] = {"every", "energy", "momentum", "points", "reactions", NULL};
  TRY(check_map(c, n, "outputs", keys));
  fmbd_scene *s = c->s;
  yaml_node_t *x;
  if ((x = get(c, n, "every"))) {
    TRY(as_double(c, x, "every", &s->solver.output_every));
    if (s->solver.output_every < 0) return fail_at(c, x, "every must not be negative");
  }
  if ((x = get(c, n, "energy"))) TRY(as_bool(c, x, "energy", &s->energy));
  if ((x = get(c, n, "momentum"))) TRY(as_bool(c, x, "momentum", &s->momentum));
  if ((x = get(c, n, "points"))) {
    if (x->type != YAML_SEQUENCE_NODE) return fail_at(c, x, "points must be a list");
    for (yaml_node_item_t *it = x->data.sequence.items.start; it < x->data.sequence.items.top;
         it++) {
      yaml_node_t *p = node(c, *it);
      TRY(grow((void **)&s->outputs, s->noutputs, sizeof *s->outputs));
      fmbd_scene_output *o = &s->outputs[s->noutputs++];
      char what[160];
      snprintf(what, sizeof what, "output point %d", s->noutputs);
      if (p->type != YAML_MAPPING_NODE)
        return fail_at(c, p, "%s must be a mapping, not %s", what, kind_name(p));
      o->loc = loc_of(p);
      yaml_node_t *y = get(c, p, "name");
      if (!y) return fail_at(c, p, "%s: missing key 'name' (the group /outputs/NAME)", what);
      TRY(check_name(c, y, "output name", &o->name));
      for (int i = 0; i + 1 < s->noutputs; i++) {
        if (!strcmp(s->outputs[i].name, o->name))
          return fail_at(c, y, "a second output named '%s'", o->name);
      }
      snprintf(what, sizeof what, "output '%s'", o->name);
      static const char *const pk[] = {"name", "body",    "point",      "interface",
                                       "node", "nearest", "quantities", NULL};
      TRY(check_map(c, p, what, pk));
      if (!(y = get(c, p, "body"))) return fail_at(c, p, "%s: missing key 'body'", what);
      TRY(body_ref(c, y, "body", &o->body));
      if (o->body < 0) return fail_at(c, y, "%s: ground does not move", what);
      TRY(parse_at_keys(c, p, what, &o->at));
      bool flex = s->bodies[o->body].kind == FMBD_SCENE_FLEXIBLE;
      if (!flex && o->at.kind != FMBD_AT_POINT && o->at.kind != FMBD_AT_DEFAULT) {
        return fail_at(c, p, "%s: body '%s' is rigid: give 'point' (body frame)", what,
                       s->bodies[o->body].name);
      }
      o->quantities = FMBD_OUT_POSITION;
      if ((y = get(c, p, "quantities"))) {
        if (y->type != YAML_SEQUENCE_NODE)
          return fail_at(c, y, "quantities must be a list, e.g. [position, velocity]");
        o->quantities = 0;
        static const char *const qn[] = {
            "position", "velocity", "acceleration", "von_mises", "stress", "strain", NULL};
        for (yaml_node_item_t *qt = y->data.sequence.items.start; qt < y->data.sequence.items.top;
             qt++) {
          yaml_node_t *q = node(c, *qt);
          const char *t;
          TRY(as_str(c, q, "quantity", &t));
          int k = -1;
          for (int i = 0; qn[i]; i++) {
            if (!strcmp(qn[i], t)) k = i;
          }
          if (k < 0) {
            return fail_at(c, q,
                           "unknown quantity '%s' (position, velocity, acceleration, von_mises, "
                           "stress, strain)",
                           t);
          }
          if (k >= 3 && !flex)
            return fail_at(c, q, "%s: '%s' needs a flexible body; '%s' is rigid", what, t,
                           s->bodies[o->body].name);
          if (k >= 3 && (o->at.kind == FMBD_AT_POINT || o->at.kind == FMBD_AT_DEFAULT)) {
            return fail_at(c, q, "%s: '%s' is known at nodes: give node, interface or nearest",
                           what, t);
          }
          o->quantities |= 1u << k;
        }
        if (!o->quantities) return fail_at(c, y, "%s: quantities is empty", what);
      }
    }
  }
  if ((x = get(c, n, "reactions"))) {
    if (x->type != YAML_SEQUENCE_NODE)
      return fail_at(c, x, "reactions must be a list of joint names");
    for (yaml_node_item_t *it = x->data.sequence.items.start; it < x->data.sequence.items.top;
         it++) {
      TRY(grow((void **)&s->reactions, s->nreactions, sizeof *s->reactions));
      TRY(grow((void **)&s->reaction_locs, s->nreactions, sizeof *s->reaction_locs));
      yaml_node_t *r = node(c, *it);
      s->reaction_locs[s->nreactions] = loc_of(r);
      TRY(find_joint(c, r, "reaction", &s->reactions[s->nreactions]));
      for (int i = 0; i < s->nreactions; i++) {
        if (s->reactions[i] == s->reactions[s->nreactions])
          return fail_at(c, r, "joint '%s' listed twice", scalar(r));
      }
      s->nreactions++;
    }
  }
  return 0;
}

typedef int (*item_fn)(ctx *, yaml_node_t *, int);
static int parse_list(ctx *c, yaml_node_t *n, const char *what, void **arr, int *count, size_t size,
                      item_fn f) {
  if (n->type != YAML_SEQUENCE_NODE) {
    return fail_at(c, n, "%s must be a list (lines starting with '- '), not %s", what,
                   kind_name(n));
  }
  for (yaml_node_item_t *it = n->data.sequence.items.start; it < n->data.sequence.items.top; it++) {
    TRY(grow(arr, *count, size));
    (*count)++;
    TRY(f(c, node(c, *it), *count - 1));
  }
  return 0;
}

static int parse_root(ctx *c, yaml_node_t *root) {
  static const char *const keys[] = {"title",   "gravity", "solver",  "bodies", "joints",
                                     "drivers", "loads",   "outputs", NULL};
  TRY(check_map(c, root, "the scene", keys));
  fmbd_scene *s = c->s;
  yaml_node_t *x;
  if ((x = get(c, root, "title"))) TRY(dup_str(c, x, "title", &s->title));
  if ((x = get(c, root, "gravity"))) TRY(as_vec3(c, x, "gravity", s->gravity));
  if (!(x = get(c, root, "solver")))
    return fail_at(c, root, "the scene has no 'solver' section (t_end at least)");
  TRY(parse_solver(c, x));
  if (!(x = get(c, root, "bodies"))) return fail_at(c, root, "the scene has no 'bodies' section");
  TRY(parse_list(c, x, "bodies", (void **)&s->bodies, &s->nbodies, sizeof *s->bodies, parse_body));
  if (s->nbodies == 0) return fail_at(c, x, "bodies is empty");
  if ((x = get(c, root, "joints"))) {
    TRY(parse_list(c, x, "joints", (void **)&s->joints, &s->njoints, sizeof *s->joints,
                   parse_joint));
  }
  if ((x = get(c, root, "drivers"))) {
    TRY(parse_list(c, x, "drivers", (void **)&s->drivers, &s->ndrivers, sizeof *s->drivers,
                   parse_driver));
  }
  if ((x = get(c, root, "loads"))) {
    TRY(parse_list(c, x, "loads", (void **)&s->loads, &s->nloads, sizeof *s->loads, parse_load));
  }
  if ((x = get(c, root, "outputs"))) TRY(parse_outputs(c, x));
  s->solver.reactions = s->nreactions > 0;
  return 0;
}

int fmbd_scene_parse(const char *file, const char *text, int64_t len, fmbd_scene **out) {
  return fmbd_scene_parse_dir(file, NULL, text, len, out);
}

int fmbd_scene_parse_dir(const char *file, const char *body_dir, const char *text, int64_t len,
                         fmbd_scene **out) {
  int rc = 0;
  *out = NULL;
  yaml_parser_t parser;
  bool parser_ok = false, doc_ok = false;
  ctx c = {.file = file, .body_dir = body_dir};
  fmbd_scene *s = fmbd_calloc(1, sizeof *s);
  FMBD_GALLOC(s);
  c.s = s;
  if (body_dir) FMBD_GALLOC(s->body_dir = fmbd_strdup(body_dir));
  FMBD_GALLOC(s->file = fmbd_strdup(file));
  FMBD_GALLOC(s->text = fmbd_malloc((size_t)len + 1));
  memcpy(s->text, text, (size_t)len);
  s->text[len] = 0;
  {
    const char *slash = strrchr(file, '/');
    if (slash) {
      size_t n = (size_t)(slash - file);
      FMBD_GALLOC(s->dir = fmbd_malloc(n + 2));
      memcpy(s->dir, file, n ? n : 1);
      s->dir[n ? n : 1] = 0;
    } else {
      FMBD_GALLOC(s->dir = fmbd_strdup("."));
    }
  }
  // defaults (docs/SCENE.md): the multibody library's own
  fmbd_mbs_settings_defaults(&s->solver);
  if (!yaml_parser_initialize(&parser)) FMBD_GFAIL(FMBD_ERR_NOMEM, "cannot start the YAML parser");
  parser_ok = true;
  yaml_parser_set_input_string(&parser, (const unsigned char *)text, (size_t)len);
  if (!yaml_parser_load(&parser, &c.doc)) {
    fmbd_err_contextf(file, "%d:%d", (int)parser.problem_mark.line + 1,
                      (int)parser.problem_mark.column + 1);
    FMBD_GFAIL(FMBD_ERR_SCENE, "not valid YAML: %s%s%s",
               parser.problem ? parser.problem : "syntax error", parser.context ? " " : "",
               parser.context ? parser.context : "");
  }
  doc_ok = true;
  yaml_node_t *root = yaml_document_get_root_node(&c.doc);
  if (!root) {
    fmbd_err_contextf(file, "1:1");
    FMBD_GFAIL(FMBD_ERR_SCENE, "the scene is empty");
  }
  FMBD_GCALL(parse_root(&c, root));
  // a second document is a mistake (a stray '---')
  {
    yaml_document_t extra;
    if (yaml_parser_load(&parser, &extra)) {
      yaml_node_t *r2 = yaml_document_get_root_node(&extra);
      if (r2) {
        fmbd_err_contextf(file, "%d:%d", (int)r2->start_mark.line + 1,
                          (int)r2->start_mark.column + 1);
        yaml_document_delete(&extra);
        FMBD_GFAIL(FMBD_ERR_SCENE, "a second YAML document: a scene is one document");
      }
      yaml_document_delete(&extra);
    }
  }
  *out = s;
  s = NULL;
done:
  if (doc_ok) yaml_document_delete(&c.doc);
  if (parser_ok) yaml_parser_delete(&parser);
  fmbd_scene_destroy(&s);
  return rc;
}

int fmbd_scene_read(const char *file, fmbd_scene **out) {
  return fmbd_scene_read_dir(file, NULL, out);
}

int fmbd_scene_read_dir(const char *file, const char *body_dir, fmbd_scene **out) {
  int rc = 0;
  char *buf = NULL;
  size_t n = 0, cap = 0;
  FILE *fp = strcmp(file, "-") ? fopen(file, "rb") : stdin;
  *out = NULL;
  if (!fp) {
    fmbd_err_context(file, "");
    FMBD_FAIL(FMBD_ERR_IO, "cannot open the scene: %s", strerror(errno));
  }
  for (;;) {
    if (n + 4096 > cap) {
      cap = cap ? 2 * cap : 65536;
      char *nb = fmbd_realloc(buf, cap);
      FMBD_GALLOC(nb);
      buf = nb;
    }
    size_t k = fread(buf + n, 1, cap - n, fp);
    n += k;
    if (k == 0) break;
  }
  if (ferror(fp)) {
    fmbd_err_context(file, "");
    FMBD_GFAIL(FMBD_ERR_IO, "cannot read the scene");
  }
  rc = fmbd_scene_parse_dir(file, body_dir, buf, (int64_t)n, out);
done:
  if (fp && fp != stdin) fclose(fp);
  fmbd_free(buf);
  return rc;
}

static void fn_free(fmbd_mbs_fn *f) {  // the table points the scene allocated (parse_fn)
  fmbd_free((void *)f->t);
  fmbd_free((void *)f->v);
}

void fmbd_scene_destroy(fmbd_scene **sp) {
  if (!sp || !*sp) return;
  fmbd_scene *s = *sp;
  for (int i = 0; i < s->nbodies; i++) {
    fmbd_scene_body *b = &s->bodies[i];
    fmbd_free(b->name);
    fmbd_free(b->file);
    fmbd_free(b->basis);
    fmbd_free(b->basis_body);
    fmbd_free(b->chain.geometry);
    fmbd_free(b->chain.mesh2fe_args);
    fmbd_free(b->chain.fe);
    fmbd_free(b->chain.fe2cb_args);
    fmbd_free(b->chain.cb);
    fmbd_free(b->chain.cbcheck_args);
    fmbd_free(b->chain.gm_scene);
    fmbd_free(b->chain.gmsolve_args);
  }
  for (int i = 0; i < s->njoints; i++) {
    fmbd_free(s->joints[i].name);
    fmbd_free(s->joints[i].at[0].interface);
    fmbd_free(s->joints[i].at[1].interface);
  }
  for (int i = 0; i < s->ndrivers; i++) {
    fmbd_free(s->drivers[i].name);
    fn_free(&s->drivers[i].fn);
  }
  for (int i = 0; i < s->nloads; i++) {
    fmbd_free(s->loads[i].name);
    fmbd_free(s->loads[i].at.interface);
    fn_free(&s->loads[i].fn);
  }
  for (int i = 0; i < s->noutputs; i++) {
    fmbd_free(s->outputs[i].name);
    fmbd_free(s->outputs[i].at.interface);
  }
  fmbd_free(s->bodies);
  fmbd_free(s->joints);
  fmbd_free(s->drivers);
  fmbd_free(s->loads);
  fmbd_free(s->outputs);
  fmbd_free(s->reactions);
  fmbd_free(s->reaction_locs);
  fmbd_free(s->title);
  fmbd_free(s->text);
  fmbd_free(s->file);
  fmbd_free(s->dir);
  fmbd_free(s->body_dir);
  fmbd_free(s);
  *sp = NULL;
}

// --- make rules ----------------------------------------------------------------------------
typedef struct sbuf {
  char *p;
  size_t n, cap;
  int bad;
} sbuf;

static void sb_add(sbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_add(sbuf *b, const char *fmt, ...) {
  if (b->bad) return;
  va_list ap;
  va_start(ap, fmt);
  int k = vsnprintf(NULL, 0, fmt, ap);
  va_end(ap);
  if (b->n + (size_t)k + 1 > b->cap) {
    size_t cap = (b->cap + (size_t)k + 1) * 2;
    char *q = fmbd_realloc(b->p, cap);
    if (!q) {
      b->bad = 1;
      return;
    }
    b->p = q;
    b->cap = cap;
  }
  va_start(ap, fmt);
  vsnprintf(b->p + b->n, b->cap - b->n, fmt, ap);
  va_end(ap);
  b->n += (size_t)k;
}

void fmbd_scene_held_interfaces(const fmbd_scene *s, const char *file, int body, char *buf,
                                size_t n) {
  if (n) buf[0] = '\0';
  for (int j = 0; j < s->njoints; j++) {
    const fmbd_scene_joint *jt = &s->joints[j];
    if (jt->kind == FMBD_MBS_SPHERICAL) continue;  // holds translations only
    for (int k = 0; k < 2; k++) {
      int bi = jt->body[k];
      if (bi < 0 || jt->at[k].kind != FMBD_AT_INTERFACE || !jt->at[k].interface) continue;
      const fmbd_scene_body *bd = &s->bodies[bi];
      bool match = body >= 0 ? bi == body : (file && bd->file && !strcmp(bd->file, file));
      if (!match) continue;
      if (fmbd_scene_list_has(buf, jt->at[k].interface)) continue;
      size_t l = strlen(buf);
      snprintf(buf + l, n > l ? n - l : 0, "%s%s", l ? "," : "", jt->at[k].interface);
    }
  }
}

bool fmbd_scene_list_has(const char *list, const char *name) {
  size_t m = strlen(name);
  for (const char *p = list; p && *p;) {
    const char *e = strchr(p, ',');
    size_t l = e ? (size_t)(e - p) : strlen(p);
    if (l == m && !strncmp(p, name, m)) return true;
    p = e ? e + 1 : p + l;
  }
  return false;
}

static bool ends_with(const char *s, const char *suf) {
  size_t a = strlen(s), b = strlen(suf);
  return a >= b && !strcmp(s + a - b, suf);
}

// whether the rules text has a rule for target (a line starting "target:")
static bool has_rule(const char *text, const char *target) {
  size_t l = strlen(target);
  for (const char *p = text; p && *p; p = strchr(p, '\n'), p = p ? p + 1 : NULL) {
    if (!strncmp(p, target, l) && p[l] == ':') return true;
  }
  return false;
}

static int make_rules(const fmbd_scene *s, const char *target, int depth, char **text);

// Without make: gm_scene, an existing basis file says how it was made: the scene gmsolve read
// (the first of its root `inputs`, a path as gmsolve was given it) and the options that fix
// its content (--modes K, --at T, --keep-drivers, --rank-tol E). *scene NULL: not known (the
// file is missing or was not made from a scene file).
static void recorded_basis(const char *file, char **scene, char *opts, size_t len) {
  fmbd_h5 *f = NULL;
  int n = 0;
  char **names = NULL, **sha = NULL;
  *scene = NULL;
  opts[0] = '\0';
  FILE *t = fopen(file, "rb");
  if (!t) return;
  fclose(t);
  if (fmbd_h5_open(file, &f) || fmbd_h5_read_inputs(f, &n, &names, &sha)) {
    fmbd_err_clear();
    fmbd_h5_close(&f);
    return;
  }
  int64_t k = 0, kd = 0;
  double at = 0, tol = 0;
  if (n > 0 && (strstr(names[0], ".yaml") || strstr(names[0], ".yml")) &&
      !fmbd_h5_read_attr_i64(f, "/gms", "modes", 1, &k) &&
      !fmbd_h5_read_attr_f64(f, "/global", "time", 1, &at) &&
      !fmbd_h5_read_attr_i64(f, "/global", "keep_drivers", 1, &kd) &&
      !fmbd_h5_read_attr_f64(f, "/gmc", "rank_tolerance", 1, &tol)) {
    *scene = fmbd_strdup(names[0]);
    char atx[64] = "";
    if (at != 0) snprintf(atx, sizeof atx, " --at %.17g", at);
    snprintf(opts, len, "--modes %lld%s%s --rank-tol %.17g", (long long)k, atx,
             kd ? " --keep-drivers" : "", tol);
  }
  fmbd_err_clear();
  for (int i = 0; i < n; i++) fmbd_free(names[i]), fmbd_free(sha[i]);
  fmbd_free(names);
  fmbd_free(sha);
  fmbd_h5_close(&f);
}

// The rules of a global-mode basis: gmsolve makes it from the scene gm (make: gm_scene, or the
// one the existing file records) with options opts; that scene's own rules (the chains of its
// full .fe.h5 bodies) follow, appended to b where b has no rule for the same file yet.
static int basis_rules(const fmbd_scene *s, const fmbd_scene_body *bd, const char *gm,
                       const char *opts, int depth, sbuf *b) {
  int rc = 0;
  fmbd_scene *ref = NULL;
  char *rt = NULL;
  FMBD_CHECK(depth < 4, FMBD_ERR_SCENE,
             "%s: body '%s': gm_scene %s: bases made from scenes that use bases, more than 4 "
             "deep (a loop?)",
             s->file, bd->name, gm);
  rc = fmbd_scene_read_dir(gm, s->body_dir, &ref);
  if (rc) {
    char msg[1100];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    FMBD_GFAIL(rc, "%s:%d: body '%s': the scene %s is made from: %s", s->file, bd->loc.line,
               bd->name, bd->basis, msg);
  }
  FMBD_GCALL(make_rules(ref, bd->basis, depth + 1, &rt));
  // first block: "basis: gm_scene files...\n"; then "\nTARGET: ...\n\trecipe\n" blocks
  char *cut = strstr(rt, "\n\n");
  size_t head = cut ? (size_t)(cut - rt) + 1 : strlen(rt);
  sb_add(b, "\n%.*s\tgmsolve %s%s%s%s%s -o $@\n", (int)head, rt, gm,
         s->body_dir ? " --body-dir " : "", s->body_dir ? s->body_dir : "",
         opts && opts[0] ? " " : "", opts ? opts : "");
  for (char *p = cut ? cut + 1 : NULL; p && *p;) {  // p at "\nTARGET: ..."
    char *e = strstr(p + 1, "\n\n");
    size_t l = e ? (size_t)(e - p) + 1 : strlen(p);
    const char *t = p + 1, *colon = strchr(t, ':');
    char tg[1024];
    snprintf(tg, sizeof tg, "%.*s", colon ? (int)(colon - t) : 0, t);
    if (!b->p || !has_rule(b->p, tg)) sb_add(b, "%.*s", (int)l, p);
    p = e ? e + 1 : NULL;
  }
done:
  fmbd_free(rt);
  fmbd_scene_destroy(&ref);
  return rc;
}

int fmbd_scene_make_rules(const fmbd_scene *s, const char *target, char **text) {
  return make_rules(s, target, 0, text);
}

static int make_rules(const fmbd_scene *s, const char *target, int depth, char **text) {
  sbuf b = {0};
  *text = NULL;
  sb_add(&b, "%s: %s", target, s->file);
  for (int i = 0; i < s->nbodies; i++) {
    const fmbd_scene_body *bd = &s->bodies[i];
    if (bd->kind != FMBD_SCENE_FLEXIBLE) continue;
    bool seen = false;  // the same file for two bodies: list once
    for (int k = 0; k < i; k++) seen |= s->bodies[k].file && !strcmp(s->bodies[k].file, bd->file);
    if (!seen) sb_add(&b, " \\\n  %s", bd->file);
  }
  for (int i = 0; i < s->nbodies; i++) {  // global-mode bases (rules below with make: gm_scene)
    const fmbd_scene_body *bd = &s->bodies[i];
    if (bd->kind != FMBD_SCENE_FLEXIBLE || !bd->basis) continue;
    bool seen = false;
    for (int k = 0; k < i; k++)
      seen |= s->bodies[k].basis && !strcmp(s->bodies[k].basis, bd->basis);
    if (!seen) sb_add(&b, " \\\n  %s", bd->basis);
  }
  sb_add(&b, "\n");
  // the chain of each distinct body file, upstream first is not needed by make: one rule each
  for (int i = 0; i < s->nbodies; i++) {
    const fmbd_scene_body *bd = &s->bodies[i];
    if (bd->kind != FMBD_SCENE_FLEXIBLE) continue;
    bool seen = false;
    for (int k = 0; k < i; k++) seen |= s->bodies[k].file && !strcmp(s->bodies[k].file, bd->file);
    if (seen) continue;
    const fmbd_scene_chain *ch = &bd->chain;
    bool is_cb = ends_with(bd->file, ".cb.h5");
    if (ends_with(bd->file, ".fe.h5")) {  // a full-model body: mesh2fe only
      if (ch->geometry) {
        sb_add(&b, "\n%s: %s\n\tmesh2fe %s%s%s -o $@\n", bd->file, ch->geometry, ch->geometry,
               ch->mesh2fe_args && ch->mesh2fe_args[0] ? " " : "",
               ch->mesh2fe_args ? ch->mesh2fe_args : "");
      }
      continue;
    }
    if (!is_cb && ch->cb) {
      // the interfaces the scene's joints hold: the body is reduced for them (cbcheck --hold),
      // unless the scene's own cbcheck options say how
      char held[1024], holds[1400] = "";
      fmbd_scene_held_interfaces(s, bd->file, -1, held, sizeof held);
      if (!(ch->cbcheck_args && strstr(ch->cbcheck_args, "--hold"))) {
        for (const char *p = held; *p;) {
          const char *e = strchr(p, ',');
          size_t l = e ? (size_t)(e - p) : strlen(p), o = strlen(holds);
          snprintf(holds + o, sizeof holds - o, " --hold %.*s", (int)l, p);
          p = e ? e + 1 : p + l;
        }
      }
      // a body file of one body holds only what this scene reads of it (cbcheck --for-scene,
      // docs/FORMAT.md /subset), so it depends on the scene too; a file two bodies share, a
      // chain with `whole: true` or whose options say --for-scene already, is left as it is
      bool shared = false;
      for (int k = 0; k < s->nbodies; k++)
        shared |= k != i && s->bodies[k].file && !strcmp(s->bodies[k].file, bd->file);
      bool subset =
          !shared && !ch->whole && !(ch->cbcheck_args && strstr(ch->cbcheck_args, "--for-scene"));
      sb_add(&b, "\n%s: %s%s%s%s%s\n\tcbcheck %s%s%s%s%s%s", bd->file, ch->cb, ch->fe ? " " : "",
             ch->fe ? ch->fe : "", subset ? " " : "", subset ? s->file : "", ch->cb,
             ch->fe ? " --fe " : "", ch->fe ? ch->fe : "",
             ch->cbcheck_args && ch->cbcheck_args[0] ? " " : "",
             ch->cbcheck_args ? ch->cbcheck_args : "", holds);
      if (subset) sb_add(&b, " --for-scene %s:%s", s->file, bd->name);
      sb_add(&b, " -o $@\n");
    }
    const char *cb = is_cb ? bd->file : ch->cb;
    if (cb && ch->fe) {
      sb_add(&b, "\n%s: %s\n\tfe2cb %s%s%s -o $@\n", cb, ch->fe, ch->fe,
             ch->fe2cb_args && ch->fe2cb_args[0] ? " " : "", ch->fe2cb_args ? ch->fe2cb_args : "");
    }
    if (ch->fe && ch->geometry) {
      sb_add(&b, "\n%s: %s\n\tmesh2fe %s%s%s -o $@\n", ch->fe, ch->geometry, ch->geometry,
             ch->mesh2fe_args && ch->mesh2fe_args[0] ? " " : "",
             ch->mesh2fe_args ? ch->mesh2fe_args : "");
    }
  }
  for (int i = 0; i < s->nbodies; i++) {  // a basis: gmsolve's rule, when its scene is known
    const fmbd_scene_body *bd = &s->bodies[i];
    if (bd->kind != FMBD_SCENE_FLEXIBLE || !bd->basis) continue;
    if (b.p && has_rule(b.p, bd->basis)) continue;  // the same basis named by another body
    bool named = false;  // another body of the same basis names its gm_scene
    for (int k = 0; k < s->nbodies && !named; k++) {
      const fmbd_scene_body *o = &s->bodies[k];
      named = k != i && o->basis && o->chain.gm_scene && !strcmp(o->basis, bd->basis);
    }
    if (named && !bd->chain.gm_scene) continue;
    char *gm = NULL, opts[256];
    if (!bd->chain.gm_scene) recorded_basis(bd->basis, &gm, opts, sizeof opts);
    if (!bd->chain.gm_scene && !gm) continue;  // not known: a dependency only
    int rc = bd->chain.gm_scene
                 ? basis_rules(s, bd, bd->chain.gm_scene, bd->chain.gmsolve_args, depth, &b)
                 : basis_rules(s, bd, gm, opts, depth, &b);
    fmbd_free(gm);
    if (rc) {
      fmbd_free(b.p);
      return rc;
    }
  }
  if (b.bad) {
    fmbd_free(b.p);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  *text = b.p;
  return 0;
}
