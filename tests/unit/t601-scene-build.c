// tests/unit/t601-scene-build.c: a scene turned into an mbs system: bodies, points, joints,
// drivers; scene time functions equal to the mbs ones; Hooke's strain of a stress
// SPDX-License-Identifier: MIT
#include <math.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_scene_build.h"

static const char *scene_text =
    "gravity: [0, -9.81, 0]\n"
    "solver: {t_end: 0.1, step: 1e-3}\n"
    "bodies:\n"
    "  - {name: bob, mass: 2, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}\n"
    "  - {name: slider, geometry: {shape: box, size: [0.1, 0.1, 0.1], mass: 1}, position: [0, -2, "
    "0]}\n"
    "joints:\n"
    "  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}\n"
    "  - {name: rail, type: prismatic, body1: ground, body2: slider, point: [0, -2, 0], axis: x}\n"
    "drivers:\n"
    "  - {name: push, joint: rail, function: {type: sine, amplitude: 0.1, frequency_hz: 2}}\n"
    "outputs:\n"
    "  points:\n"
    "    - {name: tip, body: bob, point: [0.5, 0, 0], quantities: [position, velocity]}\n"
    "    - {name: s, body: slider}\n"
    "  reactions: [pivot]\n";

int main(void) {
  fmbd_scene *s = NULL;
  fmbd_scene_model *m = NULL;
  int rc = fmbd_scene_parse("t.yaml", scene_text, (int64_t)strlen(scene_text), &s);
  EXPECT(rc == 0, "parse: %s", fmbd_err_get()->msg);
  if (s) {
    rc = fmbd_scene_build(s, &m);
    EXPECT(rc == 0, "build: %s:%s: %s", fmbd_err_get()->file, fmbd_err_get()->where,
           fmbd_err_get()->msg);
  }
  if (m) {
    EXPECT(fmbd_mbs_nbodies(m->mbs) == 2 && m->body_id[0] == 0 && m->body_id[1] == 1, "bodies");
    EXPECT(m->out_node[0] == -1 && m->out_sigma[0] == NULL, "rigid output has no node, no stress");
    fmbd_mbs_settings set = s->solver;  // the scene's solver section is the mbs settings
    EXPECT(set.fixed && set.step == 1e-3 && set.t_end == 0.1 && set.reactions, "settings");
    rc = fmbd_mbs_init(m->mbs, &set);
    EXPECT(rc == 0, "init: %s", fmbd_err_get()->msg);
    double x[3];
    fmbd_mbs_point_position(m->mbs, m->out_point[0], x);
    // the output point is 0.5 m beyond the bob's centre on the body x axis: (1.5, 0, 0)
    EXPECT(fabs(x[0] - 1.5) < 1e-12 && fabs(x[1]) < 1e-12, "tip at (%g, %g, %g)", x[0], x[1], x[2]);
    rc = fmbd_mbs_run(m->mbs, NULL, NULL);
    EXPECT(rc == 0, "run: %s", fmbd_err_get()->msg);
    // the slider follows its driver: slide = 0.1 sin(2 pi 2 t) at t = 0.1 (Newton tolerance)
    fmbd_mbs_point_position(m->mbs, m->out_point[1], x);
    double want = 0.1 * sin(2 * M_PI * 2 * 0.1);
    EXPECT(fabs(x[0] - want) < 1e-7 && fabs(x[1] + 2) < 1e-9, "slider at %.9f, want %.9f", x[0],
           want);
    // the bob fell: its tip moved down
    fmbd_mbs_point_position(m->mbs, m->out_point[0], x);
    EXPECT(x[1] < -1e-3 && fabs(hypot(x[0], x[1]) - 1.5) < 1e-7, "tip after the fall (%g, %g)",
           x[0], x[1]);
  }
  // the scene's functions reach the mbs as written: their values and derivatives against the
  // closed forms (ramp with C1 cubic blend, sine with the phase in degrees, piecewise linear
  // table); 1e-12 absolute is a few ulps of the values (order 1) and of the derivatives (<= 200)
  const char *fns =
      "solver: {t_end: 1}\nbodies: [{name: p, mass: 1, inertia: [1, 1, 1]}]\n"
      "drivers:\n"
      "  - {body: p, coordinate: x, function: {type: ramp, t0: 0.1, t1: 0.5, v0: 1, v1: 3, smooth: "
      "true}}\n"
      "  - {body: p, coordinate: y, function: {type: sine, amplitude: 2, frequency_hz: 3, "
      "phase_deg: 30, offset: 1}}\n"
      "  - {body: p, coordinate: z, function: {type: table, t: [0, 0.2, 0.7], v: [0, 1, -1]}}\n";
  fmbd_scene *f = NULL;
  rc = fmbd_scene_parse("f.yaml", fns, (int64_t)strlen(fns), &f);
  EXPECT(rc == 0, "parse functions: %s", fmbd_err_get()->msg);
  if (f) {
    fmbd_scene_model *fm = NULL;
    EXPECT(fmbd_scene_build(f, &fm) == 0, "build functions");
    for (double t = -0.1; t < 1; t += 0.0371) {
      double ex[3][3];  // [driver][value, first, second derivative]
      double s = (t - 0.1) / 0.4;
      if (t < 0.1) {
        ex[0][0] = 1, ex[0][1] = 0, ex[0][2] = 0;
      } else if (t >= 0.5) {
        ex[0][0] = 3, ex[0][1] = 0, ex[0][2] = 0;
      } else {
        ex[0][0] = 1 + 2 * s * s * (3 - 2 * s), ex[0][1] = 2 * 6 * s * (1 - s) / 0.4,
        ex[0][2] = 2 * (6 - 12 * s) / 0.16;
      }
      double w = 2 * M_PI * 3, ph = w * t + M_PI / 6;
      ex[1][0] = 1 + 2 * sin(ph), ex[1][1] = 2 * w * cos(ph), ex[1][2] = -2 * w * w * sin(ph);
      if (t < 0) {
        ex[2][0] = 0, ex[2][1] = 0;
      } else if (t < 0.2) {
        ex[2][0] = 5 * t, ex[2][1] = 5;
      } else if (t < 0.7) {
        ex[2][0] = 1 - 4 * (t - 0.2), ex[2][1] = -4;
      } else {
        ex[2][0] = -1, ex[2][1] = 0;
      }
      ex[2][2] = 0;
      for (int d = 0; d < 3; d++) {
        double d1, d2, v = fmbd_mbs_fn_eval(&f->drivers[d].fn, t, &d1, &d2);
        EXPECT(fabs(v - ex[d][0]) < 1e-12 && fabs(d1 - ex[d][1]) < 1e-12 &&
                   fabs(d2 - ex[d][2]) < 1e-12,
               "driver %d at t = %g: %g %g %g vs %g %g %g", d, t, v, d1, d2, ex[d][0], ex[d][1],
               ex[d][2]);
      }
    }
    fmbd_scene_model_destroy(&fm);
    fmbd_scene_destroy(&f);
  }
  // Hooke: uniaxial stress s: eps_xx = s/E, eps_yy = eps_zz = -nu s/E, equivalent 2(1+nu)s/(3E)
  double sg[6] = {2e8, 0, 0, 0, 0, 0}, ep[6], E = 2e11, nu = 0.3;
  double ev = fmbd_scene_strain(E, nu, sg, ep);
  EXPECT(fabs(ep[0] - 1e-3) < 1e-15 && fabs(ep[1] + 3e-4) < 1e-15 && fabs(ep[2] + 3e-4) < 1e-15,
         "uniaxial strain");
  EXPECT(fabs(ev - 2 * 1.3 * 2e8 / (3 * E)) < 1e-15, "equivalent strain %g", ev);
  // pure shear tau: eps_xy = (1+nu) tau / E (tensor), equivalent 2 (1+nu) sqrt(3) tau / (3E)
  double sh[6] = {0, 0, 0, 1e8, 0, 0};
  ev = fmbd_scene_strain(E, nu, sh, ep);
  EXPECT(fabs(ep[3] - 1.3e8 / E) < 1e-15 && fabs(ev - 2 * 1.3 * sqrt(3) * 1e8 / (3 * E)) < 1e-15,
         "shear strain");
  fmbd_scene_model_destroy(&m);
  fmbd_scene_destroy(&s);
  TEST_EXIT();
}
