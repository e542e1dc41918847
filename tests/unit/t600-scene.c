// tests/unit/t600-scene.c: the scene reader: values, defaults, and the line:column of errors
// SPDX-License-Identifier: MIT
#include <math.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_scene.h"

static fmbd_scene *parse(const char *text) {
  fmbd_scene *s = NULL;
  fmbd_err_clear();
  int rc = fmbd_scene_parse("dir/t.yaml", text, (int64_t)strlen(text), &s);
  EXPECT(rc == 0, "parse failed: %s:%s: %s", fmbd_err_get()->file, fmbd_err_get()->where,
         fmbd_err_get()->msg);
  return s;
}

// The scene must fail at line:column with a message containing `needle`.
static void bad(const char *text, const char *where, const char *needle) {
  fmbd_scene *s = NULL;
  fmbd_err_clear();
  int rc = fmbd_scene_parse("t.yaml", text, (int64_t)strlen(text), &s);
  const fmbd_err *e = fmbd_err_get();
  EXPECT(rc == FMBD_ERR_SCENE, "expected a scene error (%s) at %s, got rc %d", needle, where, rc);
  EXPECT(s == NULL, "no scene on failure");
  EXPECT(!strcmp(e->file, "t.yaml"), "file '%s'", e->file);
  EXPECT(!strcmp(e->where, where), "'%s': where '%s', expected '%s' (%s)", needle, e->where, where,
         e->msg);
  EXPECT(strstr(e->msg, needle) != NULL, "message '%s' lacks '%s'", e->msg, needle);
  fmbd_scene_destroy(&s);
}

static const char *good =
    "title: two links\n"
    "gravity: [0, -9.81, 0]\n"
    "solver: {t_end: 2, first_step: 1e-5, max_step: 1e-3}\n"
    "bodies:\n"
    "  - name: a\n"
    "    geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}\n"
    "    position: [0.2, 0, 0]\n"
    "  - name: b\n"
    "    mass: 2\n"
    "    inertia: [1, 2, 2.5]\n"
    "    orientation: {axis: z, angle_deg: 90}\n"
    "    angular_velocity: [0, 0, 1]\n"
    "  - name: rod\n"
    "    type: flexible\n"
    "    file: rod.rflex.h5\n"
    "    modes: 6\n"
    "    make: {cb: rod.cb.h5, cbcheck: --tol 1e-3, fe: rod.fe.h5, fe2cb: --modes 20, geometry: "
    "rod.geo}\n"
    "joints:\n"
    "  - {name: j0, type: spherical, body1: ground, body2: a, point: [0, 0, 0]}\n"
    "  - {name: j1, type: revolute, body1: a, body2: b, point: [0.4, 0, 0], axis: [0, 0, 2]}\n"
    "  - {name: j2, type: spherical, body1: b, body2: rod, at2: {interface: left}}\n"
    "drivers:\n"
    "  - {name: d, joint: j1, function: {type: table, points: [[0, 0], [1, 2], [2, 2]]}}\n"
    "loads:\n"
    "  - {type: torque, body: b, direction: [0, 0, 1], function: {type: ramp, t1: 0.1, v1: 3}}\n"
    "outputs:\n"
    "  every: 0.01\n"
    "  energy: true\n"
    "  points:\n"
    "    - {name: A, body: rod, nearest: [0.3, 0, 0], quantities: [position, von_mises]}\n"
    "  reactions: [j0]\n";

// the scene's functions are the multibody core's (fmbd_mbs_fn), evaluated by its one
// implementation
static double fn_eval(const fmbd_mbs_fn *f, double t, double *d1, double *d2) {
  return fmbd_mbs_fn_eval(f, t, d1, d2);
}

int main(void) {
  fmbd_scene *s = parse(good);
  if (s) {
    EXPECT(s->nbodies == 3 && s->njoints == 3 && s->ndrivers == 1 && s->nloads == 1, "counts");
    EXPECT(!strcmp(s->dir, "dir"), "dir '%s'", s->dir);
    fmbd_scene_body *a = &s->bodies[0];
    // m = rho pi r^2 L; transverse I = m (3 r^2 + L^2) / 12 (solid cylinder), to round-off
    double m = 7850 * M_PI * 0.015 * 0.015 * 0.3;
    EXPECT(fabs(a->mass - m) < 1e-12 * m, "cylinder mass %g vs %g", a->mass, m);
    EXPECT(fabs(a->inertia[0] - m * 0.015 * 0.015 / 2) < 1e-15, "axial inertia %g", a->inertia[0]);
    EXPECT(fabs(a->inertia[4] - m * (3 * 0.015 * 0.015 + 0.09) / 12) < 1e-15, "transverse inertia");
    fmbd_scene_body *b = &s->bodies[1];
    // rotation by 90 deg about z maps x to y: R[1][0] = 1 (row-major), to round-off
    EXPECT(fabs(b->rotation[3] - 1) < 1e-15 && fabs(b->rotation[0]) < 1e-15, "orientation");
    EXPECT(s->bodies[2].kind == FMBD_SCENE_FLEXIBLE && s->bodies[2].modes == 6, "flexible");
    EXPECT(!strcmp(s->bodies[2].file, "dir/rod.rflex.h5"), "file resolved: %s", s->bodies[2].file);
    EXPECT(fabs(s->joints[1].axis[2] - 1) < 1e-15, "axis normalised");
    EXPECT(s->joints[2].at[1].kind == FMBD_AT_INTERFACE && !s->joints[2].has_point,
           "interface attach");
    EXPECT(s->solver.rho_inf == 0.9 && !s->solver.fixed && s->solver.max_step == 1e-3, "solver");
    // table: linear between points, constant outside; ramp: linear to 3 at 0.1
    double d1;
    EXPECT(fabs(fn_eval(&s->drivers[0].fn, 0.5, &d1, NULL) - 1) < 1e-15 && fabs(d1 - 2) < 1e-15,
           "table");
    EXPECT(fn_eval(&s->drivers[0].fn, 5, NULL, NULL) == 2, "table after");
    EXPECT(fabs(fn_eval(&s->loads[0].fn, 0.05, NULL, NULL) - 1.5) < 1e-15, "ramp");
    EXPECT(s->noutputs == 1 && s->outputs[0].quantities == (FMBD_OUT_POSITION | FMBD_OUT_VON_MISES),
           "quantities");
    EXPECT(s->energy && s->nreactions == 1 && s->solver.output_every == 0.01, "outputs");
    char *rules = NULL;
    EXPECT(fmbd_scene_make_rules(s, "t.run.h5", &rules) == 0, "rules");
    if (rules) {
      EXPECT(strstr(rules, "t.run.h5: dir/t.yaml \\\n  dir/rod.rflex.h5\n"), "run rule: %s", rules);
      EXPECT(strstr(rules,
                    "dir/rod.rflex.h5: dir/rod.cb.h5 dir/rod.fe.h5 dir/t.yaml\n\tcbcheck "
                    "dir/rod.cb.h5 --fe dir/rod.fe.h5 --tol 1e-3 --for-scene dir/t.yaml:rod -o $@"),
             "cbcheck rule: %s", rules);
      EXPECT(strstr(rules, "dir/rod.fe.h5: dir/rod.geo\n\tmesh2fe dir/rod.geo -o $@"),
             "mesh2fe rule: %s", rules);
    }
    fmbd_free(rules);
    fmbd_scene_destroy(&s);
    EXPECT(s == NULL, "destroy sets NULL");
  }
  // sine function and its derivatives at t = 0: offset, A w, 0
  s = parse(
      "solver: {t_end: 1, step: 1e-3}\nbodies: [{name: p, mass: 1, inertia: [1,1,1]}]\n"
      "drivers: [{body: p, coordinate: y, function: {type: sine, amplitude: 2, frequency_hz: 0.5, "
      "offset: 1}}]\n");
  if (s) {
    double d1, d2;
    double v = fn_eval(&s->drivers[0].fn, 0, &d1, &d2);
    EXPECT(v == 1 && fabs(d1 - 2 * M_PI) < 1e-14 && fabs(d2) < 1e-14, "sine %g %g %g", v, d1, d2);
    EXPECT(s->solver.fixed && s->solver.step == 1e-3, "fixed step");
    fmbd_scene_destroy(&s);
  }
  // spinup: the keys land where fmbd_mbs_fn_eval reads them: at t0 + (t1 - t0) the angle is
  // v0 + speed (t1 - t0) / 2 and the speed is speed (to round-off)
  s = parse(
      "solver: {t_end: 1}\nbodies: [{name: p, mass: 1, inertia: [1,1,1]}]\n"
      "drivers: [{body: p, coordinate: y, function: {type: spinup, speed: 4, t0: 1, t1: 16, "
      "v0: 0.5}}]\n");
  if (s) {
    double d1, d2;
    double v = fn_eval(&s->drivers[0].fn, 16, &d1, &d2);
    EXPECT(s->drivers[0].fn.kind == FMBD_MBS_FN_SPINUP && fabs(v - 30.5) < 1e-13 &&
               fabs(d1 - 4) < 1e-15 && d2 == 0,
           "spinup %g %g %g", v, d1, d2);
    EXPECT(fn_eval(&s->drivers[0].fn, 0.5, &d1, &d2) == 0.5 && d1 == 0 && d2 == 0,
           "spinup before t0");
    fmbd_scene_destroy(&s);
  }
  // a rigid-only scene depends on its file alone
  s = parse("solver: {t_end: 1}\nbodies: [{name: p, mass: 1, inertia: [1,1,1]}]\n");
  if (s) {
    char *rules = NULL;
    EXPECT(fmbd_scene_make_rules(s, "x.run.h5", &rules) == 0 && rules &&
               !strcmp(rules, "x.run.h5: dir/t.yaml\n"),
           "rigid-only rules '%s'", rules ? rules : "");
    fmbd_free(rules);
    fmbd_scene_destroy(&s);
  }

  // --- errors: line:column and message ---
  const char *head = "solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 1, inertia: [1, 1, 1]}\n";
  char buf[1024];
  bad("solver: {t_end: 1}\nbodies: []\nfoo: 1\n", "3:1", "unknown key 'foo' in the scene");
  snprintf(buf, sizeof buf,
           "%sjoints:\n  - name: j1\n    type: spherical\n    body1: ground\n    body2: p\n    "
           "point: [0,0,0]\n    foo: 3\n",
           head);
  bad(buf, "10:5", "unknown key 'foo' in joint 'j1'");
  snprintf(buf, sizeof buf,
           "%sjoints:\n  - {name: j1, type: spherical, body1: ground, body2: q, point: [0,0,0]}\n",
           head);
  bad(buf, "5:55", "no body named 'q'");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 0, inertia: [1, 1, 1]}\n", "3:21",
      "mass matrix singular");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 1, inertia: [1, 1, 3]}\n", "3:33",
      "triangle inequality");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 1, inertia: [1, 1, 1]}\n  - {name: p, "
      "mass: 1, inertia: [1, 1, 1]}\n",
      "4:12", "a second body named 'p'");
  bad("solver: {t_end: one}\nbodies: []\n", "1:17", "'one' is not a finite number");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, type: flexible}\n", "3:5", "missing key 'file'");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, type: flexible, file: a.rflex.h5, mass: 2}\n",
      "3:55", "for rigid bodies");
  snprintf(buf, sizeof buf,
           "%sjoints:\n  - {name: j, type: revolute, body1: ground, body2: p, point: [0,0,0]}\n",
           head);
  bad(buf, "5:5", "needs key 'axis'");
  snprintf(
      buf, sizeof buf,
      "%sjoints:\n  - {name: j, type: spherical, body1: ground, body2: p, at2: {interface: a}}\n",
      head);
  bad(buf, "5:62", "body 'p' is rigid");
  snprintf(buf, sizeof buf,
           "%sdrivers:\n  - {body: p, coordinate: x, function: {type: ramp, t0: 1, t1: 1}}\n",
           head);
  bad(buf, "5:64", "t1 must be later than t0");
  // spinup: the same rule, named at the spinup's t1; a non-finite speed; speed required
  snprintf(buf, sizeof buf,
           "%sdrivers:\n  - {body: p, coordinate: x, function: {type: spinup, speed: 4, t1: 0}}\n",
           head);
  bad(buf, "5:69", "spinup function: t1 must be later than t0");
  snprintf(buf, sizeof buf,
           "%sdrivers:\n  - {body: p, coordinate: x, function: {type: spinup, speed: .nan, t1: "
           "1}}\n",
           head);
  bad(buf, "5:62", "speed: '.nan' is not a finite number");
  snprintf(buf, sizeof buf,
           "%sdrivers:\n  - {body: p, coordinate: x, function: {type: spinup, t1: 1}}\n", head);
  bad(buf, "5:40", "spinup function: missing key 'speed'");
  snprintf(buf, sizeof buf,
           "%sdrivers:\n  - {body: p, coordinate: x, function: {type: spinup, t1: 1, speed: 1, "
           "v1: 2}}\n",
           head);
  bad(buf, "5:72", "unknown key 'v1' in a spinup function");
  bad("solver: {t_end: 1}\nbodies: [\n", "3:1", "not valid YAML");
  bad("solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 1, inertia: [1, 1, 1], orientation: "
      "{matrix: [1,0,0, 0,1,0, 0,0,2]}}\n",
      "3:66", "not a rotation");
  snprintf(
      buf, sizeof buf,
      "%soutputs:\n  points:\n    - {name: A, body: p, point: [0,0,0], quantities: [von_mises]}\n",
      head);
  bad(buf, "6:55", "needs a flexible body");

  // allocation failures: every one is reported, nothing leaks (checked under SANITIZE=1)
  for (int64_t k = 0; k < 400; k++) {
    fmbd_alloc_fail_after(k);
    fmbd_scene *t = NULL;
    int rc = fmbd_scene_parse("dir/t.yaml", good, (int64_t)strlen(good), &t);
    fmbd_alloc_fail_after(-1);
    EXPECT(rc == 0 || rc == FMBD_ERR_NOMEM, "countdown %lld: rc %d", (long long)k, rc);
    EXPECT((rc == 0) == (t != NULL), "countdown %lld: scene iff success", (long long)k);
    fmbd_scene_destroy(&t);
    if (rc == 0) break;
  }
  TEST_EXIT();
}
