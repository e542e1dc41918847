// tests/unit/t505-mbs-errors.c: error paths of the multibody core: Newton failure at the
// smallest step names the time and the constraint; inconsistent initial positions that
// cannot be projected name the joint; bad bodies, joints, drivers and settings are refused
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

static const double COM[3] = {0.25, 0, 0}, INERTIA[9] = {1e-4, 0, 0, 0, 0.02, 0, 0, 0, 0.02};

// a rod on a ball joint at its body point (0.5, 0, 0), its origin pushed along x by a driver
// beyond reach: the push R_x(t) = R_x(0) + 0.5 t needs |R| <= 0.5, impossible after t ~ 1.9 s
static void newton_failure(void) {
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double z[3] = {0, 0, 1}, u[3] = {0.5, 0, 0}, o[3] = {0, 0, 0};
  fmbd_mbs_rotation_axis_angle(z, M_PI / 6, s0.rotation);
  s0.position[0] = -0.5 * cos(M_PI / 6), s0.position[1] = -0.5 * sin(M_PI / 6);
  int b, pb, pg, j;
  rc = rc ? rc : fmbd_mbs_add_rigid(m, "rod", 1.0, COM, INERTIA, &s0, &b);
  rc = rc ? rc : fmbd_mbs_add_point(m, b, u, NULL, NULL, &pb);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg);
  fmbd_mbs_joint_desc jd = {.name = "ball", .kind = FMBD_MBS_SPHERICAL, .point = {pg, pb}};
  rc = rc ? rc : fmbd_mbs_add_joint(m, &jd, &j);
  fmbd_mbs_fn f = fmbd_mbs_fn_linear(0, s0.position[0], 0.5);
  rc = rc ? rc : fmbd_mbs_add_driver_body(m, "push", b, 0, &f, NULL);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 3, s.min_step = 1e-9;
  rc = rc ? rc : fmbd_mbs_init(m, &s);
  EXPECT(rc == 0, "init: %s", fmbd_err_get()->msg);
  if (!rc) rc = fmbd_mbs_run(m, NULL, NULL);
  const char *msg = fmbd_err_get()->msg;
  EXPECT(rc == FMBD_ERR_CONVERGE, "expected FMBD_ERR_CONVERGE, got %d (%s)", rc, msg);
  double t = -1;
  const char *pt = strstr(msg, "t = ");
  if (pt) t = atof(pt + 4);
  // reach ends at R_x = 0.5: t = (0.5 + 0.433) / 0.5 = 1.87 s; the failure comes before it
  // (the rod approaches the singular straight configuration) and after 1.5 s
  EXPECT(t > 1.5 && t < 1.87, "failure time %g not in the message or wrong: %s", t, msg);
  EXPECT(strstr(msg, "Newton did not converge"), "message: %s", msg);
  if (getenv("FMBD_TEST_VERBOSE")) fprintf(stderr, "t505: %s\n", msg);
  // the rod straight at the end of its reach: the ball joint's rows and the push's depend
  EXPECT(strstr(msg, "constraints are singular") && strstr(msg, "joint 'ball'") &&
             strstr(msg, "driver 'push'"),
         "message does not name the singular position, the joint and the driver: %s", msg);
  fmbd_mbs_destroy(&m);
}

// the same rod far from its reach (t_end 0.5 s), but one Newton iteration allowed: every
// step fails at a regular position, reported by its residual and not as a singular one
static void newton_failure_regular(void) {
  fmbd_err_clear();
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double z[3] = {0, 0, 1}, u[3] = {0.5, 0, 0}, o[3] = {0, 0, 0};
  fmbd_mbs_rotation_axis_angle(z, M_PI / 6, s0.rotation);
  s0.position[0] = -0.5 * cos(M_PI / 6), s0.position[1] = -0.5 * sin(M_PI / 6);
  int b, pb, pg, j;
  rc = rc ? rc : fmbd_mbs_add_rigid(m, "rod", 1.0, COM, INERTIA, &s0, &b);
  rc = rc ? rc : fmbd_mbs_add_point(m, b, u, NULL, NULL, &pb);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg);
  fmbd_mbs_joint_desc jd = {.name = "ball", .kind = FMBD_MBS_SPHERICAL, .point = {pg, pb}};
  rc = rc ? rc : fmbd_mbs_add_joint(m, &jd, &j);
  fmbd_mbs_fn f = fmbd_mbs_fn_linear(0, s0.position[0], 0.5);
  rc = rc ? rc : fmbd_mbs_add_driver_body(m, "push", b, 0, &f, NULL);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 0.5, s.min_step = 1e-6, s.newton_max = 1;
  rc = rc ? rc : fmbd_mbs_init(m, &s);
  EXPECT(rc == 0, "init: %s", fmbd_err_get()->msg);
  if (!rc) rc = fmbd_mbs_run(m, NULL, NULL);
  const char *msg = fmbd_err_get()->msg;
  if (getenv("FMBD_TEST_VERBOSE")) fprintf(stderr, "t505: %s\n", msg);
  EXPECT(rc == FMBD_ERR_CONVERGE && strstr(msg, "Newton did not converge; largest residual") &&
             !strstr(msg, "singular"),
         "a failure at a regular position: %s", msg);
  fmbd_mbs_destroy(&m);
}

// a rod held at both ends by ball joints to ground points farther apart than its length
static void bad_assembly(void) {
  fmbd_err_clear();
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double a[3] = {0, 0, 0}, bpt[3] = {0.5, 0, 0}, g1[3] = {0, 0, 0}, g2[3] = {0.8, 0, 0};
  int b, p1, p2, q1, q2;
  rc = rc ? rc : fmbd_mbs_add_rigid(m, "rod", 1.0, COM, INERTIA, &s0, &b);
  rc = rc ? rc : fmbd_mbs_add_point(m, b, a, NULL, NULL, &p1);
  rc = rc ? rc : fmbd_mbs_add_point(m, b, bpt, NULL, NULL, &p2);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, g1, NULL, NULL, &q1);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, g2, NULL, NULL, &q2);
  fmbd_mbs_joint_desc j1 = {.name = "left", .kind = FMBD_MBS_SPHERICAL, .point = {q1, p1}};
  fmbd_mbs_joint_desc j2 = {.name = "right", .kind = FMBD_MBS_SPHERICAL, .point = {q2, p2}};
  rc = rc ? rc : fmbd_mbs_add_joint(m, &j1, NULL);
  rc = rc ? rc : fmbd_mbs_add_joint(m, &j2, NULL);
  EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  rc = fmbd_mbs_init(m, &s);
  const char *msg = fmbd_err_get()->msg;
  EXPECT(rc == FMBD_ERR_CONVERGE, "expected FMBD_ERR_CONVERGE, got %d (%s)", rc, msg);
  if (getenv("FMBD_TEST_VERBOSE")) fprintf(stderr, "t505: %s\n", msg);
  EXPECT(strstr(msg, "initial positions") &&
             (strstr(msg, "joint 'left'") || strstr(msg, "joint 'right'")),
         "message: %s", msg);
  fmbd_mbs_destroy(&m);
}

static void bad_inputs(void) {
  fmbd_mbs *m = NULL;
  fmbd_mbs_create(&m);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  int b, p1, p2, pg;
  double o[3] = {0, 0, 0}, I2[9] = {1, 0, 0, 0, -1, 0, 0, 0, 1};
  EXPECT(fmbd_mbs_add_rigid(m, "neg", -1, COM, INERTIA, &s0, NULL) == FMBD_ERR_VALUE,
         "negative mass accepted");
  EXPECT(fmbd_mbs_add_rigid(m, "badI", 1, COM, I2, &s0, NULL) == FMBD_ERR_VALUE,
         "indefinite inertia accepted");
  fmbd_mbs_state0 sb = s0;
  sb.rotation[0] = 2;
  EXPECT(fmbd_mbs_add_rigid(m, "badR", 1, COM, INERTIA, &sb, NULL) == FMBD_ERR_VALUE,
         "non-orthonormal rotation accepted");
  EXPECT(fmbd_mbs_add_rigid(m, "rod", 1, COM, INERTIA, &s0, &b) == 0, "good body refused");
  EXPECT(fmbd_mbs_add_rigid(m, "rod", 1, COM, INERTIA, &s0, NULL) == FMBD_ERR_VALUE,
         "duplicate name accepted");
  fmbd_mbs_add_point(m, b, o, NULL, NULL, &p1);
  fmbd_mbs_add_point(m, b, COM, NULL, NULL, &p2);
  fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg);
  EXPECT(fmbd_mbs_add_point(m, 7, o, NULL, NULL, NULL) == FMBD_ERR_VALUE,
         "point on unknown body accepted");
  fmbd_mbs_joint_desc same = {.name = "same", .kind = FMBD_MBS_SPHERICAL, .point = {p1, p2}};
  EXPECT(fmbd_mbs_add_joint(m, &same, NULL) == FMBD_ERR_VALUE, "joint within one body accepted");
  fmbd_mbs_joint_desc noaxis = {.name = "noaxis", .kind = FMBD_MBS_REVOLUTE, .point = {pg, p1}};
  EXPECT(fmbd_mbs_add_joint(m, &noaxis, NULL) == FMBD_ERR_VALUE, "revolute without axis accepted");
  fmbd_mbs_joint_desc uni = {.name = "uni",
                             .kind = FMBD_MBS_UNIVERSAL,
                             .point = {pg, p1},
                             .axis = {0, 0, 1},
                             .axis2 = {0, 1, 1}};
  EXPECT(fmbd_mbs_add_joint(m, &uni, NULL) == FMBD_ERR_VALUE, "non-orthogonal universal accepted");
  fmbd_mbs_joint_desc sph = {.name = "sph", .kind = FMBD_MBS_SPHERICAL, .point = {pg, p1}};
  int js;
  EXPECT(fmbd_mbs_add_joint(m, &sph, &js) == 0, "good joint refused: %s", fmbd_err_get()->msg);
  fmbd_mbs_fn f = fmbd_mbs_fn_constant(0);
  EXPECT(fmbd_mbs_add_driver_joint(m, "drv", js, &f, NULL) == FMBD_ERR_VALUE,
         "driver on a spherical joint accepted");
  EXPECT(fmbd_mbs_add_driver_body(m, "drv", b, 5, &f, NULL) == FMBD_ERR_VALUE,
         "modal driver on a rigid body accepted");
  double t[2] = {1, 0.5}, v[2] = {0, 1};
  fmbd_mbs_fn tab = fmbd_mbs_fn_table(2, t, v);
  double dir[3] = {1, 0, 0};
  EXPECT(fmbd_mbs_add_load(m, "ld", FMBD_MBS_FORCE, p1, false, dir, &tab, NULL) == FMBD_ERR_VALUE,
         "decreasing table accepted");
  EXPECT(fmbd_mbs_add_load(m, "ld", FMBD_MBS_FORCE, pg, false, dir, &f, NULL) == FMBD_ERR_VALUE,
         "load on ground accepted");
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.rho_inf = 1.5;
  EXPECT(fmbd_mbs_init(m, &s) == FMBD_ERR_VALUE, "rho_inf 1.5 accepted");
  fmbd_mbs_destroy(&m);
  // a flexible body whose modal mass matrix is not positive definite
  fmbd_mbs_create(&m);
  double S1[3] = {0}, XS[9] = {0}, SS[9] = {0}, Mff[1] = {-1}, Kff[1] = {1};
  fmbd_mbs_flex_data d = {.nm = 1,
                          .mass = 1,
                          .second_moment = {1, 0, 0, 0, 1, 0, 0, 0, 1},
                          .S1 = S1,
                          .XS = XS,
                          .SS = SS,
                          .Mff = Mff,
                          .Kff = Kff};
  EXPECT(fmbd_mbs_add_flex(m, "flex", &d, &s0, NULL) == FMBD_ERR_SINGULAR,
         "indefinite Mff accepted");
  fmbd_mbs_destroy(&m);
  // all mass on the x axis and no joint: no inertia about x, singular iteration matrix; the
  // message names the body
  fmbd_mbs_create(&m);
  Mff[0] = 1;
  fmbd_mbs_flex_data dl = d;
  double J[9] = {0.5, 0, 0, 0, 0, 0, 0, 0, 0};
  memcpy(dl.second_moment, J, sizeof J);
  int rc = fmbd_mbs_add_flex(m, "line", &dl, &s0, NULL);
  EXPECT(rc == 0, "add_flex: %s", fmbd_err_get()->msg);
  fmbd_mbs_settings s2;
  fmbd_mbs_settings_defaults(&s2);
  if (!rc) rc = fmbd_mbs_init(m, &s2);
  EXPECT(rc == FMBD_ERR_SINGULAR && strstr(fmbd_err_get()->msg, "body 'line'"),
         "mass on a line: %d %s", rc, fmbd_err_get()->msg);
  if (getenv("FMBD_TEST_VERBOSE")) fprintf(stderr, "t505: %s\n", fmbd_err_get()->msg);
  fmbd_mbs_destroy(&m);
}

// function evaluation against closed forms
static void functions(void) {
  fmbd_mbs_fn r = fmbd_mbs_fn_ramp(1, 2, 3, 6, true);
  double d1, d2;
  double v = fmbd_mbs_fn_eval(&r, 2, &d1, &d2);
  EXPECT(fabs(v - 4) < 1e-15 && fabs(d1 - 3) < 1e-15 && fabs(d2) < 1e-15,
         "smooth ramp mid: %g %g %g", v, d1, d2);
  v = fmbd_mbs_fn_eval(&r, 0, &d1, &d2);
  EXPECT(v == 2 && d1 == 0, "ramp before: %g %g", v, d1);
  fmbd_mbs_fn sn = fmbd_mbs_fn_sine(1, 2, 0.5, 0);
  v = fmbd_mbs_fn_eval(&sn, 0.5, &d1, &d2);  // sin(pi/2) = 1
  EXPECT(fabs(v - 3) < 1e-14 && fabs(d1) < 1e-14 && fabs(d2 + 2 * M_PI * M_PI) < 1e-12,
         "sine: %g %g %g", v, d1, d2);
  double t[3] = {0, 1, 3}, vv[3] = {0, 2, 0};
  fmbd_mbs_fn tb = fmbd_mbs_fn_table(3, t, vv);
  v = fmbd_mbs_fn_eval(&tb, 2, &d1, NULL);
  EXPECT(fabs(v - 1) < 1e-15 && fabs(d1 + 1) < 1e-15, "table: %g %g", v, d1);
  v = fmbd_mbs_fn_eval(&tb, 5, &d1, NULL);
  EXPECT(v == 0 && d1 == 0, "table after: %g %g", v, d1);
}

// allocation failures: make the n-th allocation fail while building and initialising a small
// closed-loop flexible-free system; every attempt either succeeds or reports
// FMBD_ERR_NOMEM, and nothing leaks (checked by ASan under SANITIZE=1)
static int build_small(void) {
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  if (rc) return rc;
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double o[3] = {0, 0, 0}, tt[2] = {0, 1}, vv[2] = {0, 0.1};
  int b, p1, pg;
  fmbd_mbs_joint_desc jd = {.name = "hinge", .kind = FMBD_MBS_REVOLUTE, .axis = {0, 0, 1}};
  fmbd_mbs_fn f = fmbd_mbs_fn_table(2, tt, vv);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 0.01;
  if (!(rc = fmbd_mbs_add_rigid(m, "rod", 1.0, COM, INERTIA, &s0, &b)) &&
      !(rc = fmbd_mbs_add_point(m, b, o, NULL, NULL, &p1)) &&
      !(rc = fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg))) {
    jd.point[0] = pg, jd.point[1] = p1;
    int j;
    if (!(rc = fmbd_mbs_add_joint(m, &jd, &j)) &&
        !(rc = fmbd_mbs_add_driver_joint(m, "drive", j, &f, NULL)) && !(rc = fmbd_mbs_init(m, &s)))
      rc = fmbd_mbs_run(m, NULL, NULL);
  }
  fmbd_mbs_destroy(&m);
  return rc;
}
static void alloc_failures(void) {
  int64_t n0 = fmbd_alloc_count();
  int rc = build_small();
  int64_t total = fmbd_alloc_count() - n0;
  EXPECT(rc == 0, "small system: %s", fmbd_err_get()->msg);
  for (int64_t k = 0; k < total; k++) {
    fmbd_alloc_fail_after(k);
    rc = build_small();
    fmbd_alloc_fail_after(-1);
    EXPECT(rc == 0 || rc == FMBD_ERR_NOMEM, "allocation %lld failing gave %d (%s)", (long long)k,
           rc, fmbd_err_get()->msg);
  }
}

int main(void) {
  fmbd_log_init("t505", FMBD_LOG_ERROR);
  alloc_failures();
  newton_failure();
  newton_failure_regular();
  bad_assembly();
  bad_inputs();
  functions();
  TEST_EXIT();
}
