// common/fmbd_scene_record.c: the outputs of a scene model recorded in a run file
// SPDX-License-Identifier: MIT
#include "fmbd_scene_record.h"

#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_xdmf.h"

// The series of each point output, by quantity (FMBD_OUT_* bit order), and their units.
enum { Q_POS, Q_VEL, Q_ACC, Q_VM, Q_STRESS, Q_STRAIN, Q_VMSTRAIN, NQ };
static const char *const q_name[NQ] = {"position", "velocity", "acceleration",    "von_mises",
                                       "stress",   "strain",   "von_mises_strain"};
static const int q_cols[NQ] = {3, 3, 3, 0, 6, 6, 0};
static const char *const q_unit[NQ] = {"m", "m/s", "m/s^2", "Pa", "Pa", "1", "1"};

struct fmbd_scene_recorder {
  const fmbd_scene *s;
  fmbd_scene_model *m;
  fmbd_runfile *rf;
  int (*out)[NQ];  // per output: series id, -1 when not asked
  int energy[3], momentum[2];
  int (*react)[2];      // per reaction: force, torque
  fmbd_xdmf *xdmf;      // the fields of the flexible bodies (xdmf_name given)
  int nx, *xbody;       // their mbs body ids
  struct fe_field *fe;  // per field body: what a full FE body's fields need (fe NULL: modal)
};
typedef fmbd_scene_recorder run;

static void get_stats(void *user, fmbd_runfile_stats *st) {
  const run *r = user;
  fmbd_mbs_stats ms;
  fmbd_mbs_get_stats(r->m->mbs, &ms);
  *st = (fmbd_runfile_stats){.steps = ms.steps,
                             .rejected_steps = ms.rejected,
                             .newton_iterations = ms.newton_iterations,
                             .factorizations = ms.factorizations,
                             .coordinates = ms.coordinates,
                             .equations = ms.equations,
                             .redundant_equations = ms.redundant,
                             .t_reached = fmbd_mbs_time(r->m->mbs),
                             .last_step_s = ms.h_last,
                             .factor_cpu_s = ms.factor_cpu_s,
                             .solve_cpu_s = ms.solve_cpu_s,
                             .eval_cpu_s = ms.eval_cpu_s};
}

// The run file's series, in the order of docs/FORMAT.md.
static int declare(run *r) {
  const fmbd_scene *s = r->s;
  fmbd_h5 *f = fmbd_runfile_h5(r->rf);
  char path[600];
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    snprintf(path, sizeof path, "/outputs/%s", op->name);
    FMBD_CALL(fmbd_h5_make_group(f, path));
    FMBD_CALL(fmbd_h5_write_attr_str(f, path, "body", s->bodies[op->body].name));
    FMBD_CALL(fmbd_h5_write_attr_i64(f, path, "node", 1, &r->m->out_node[o]));
    for (int q = 0; q < NQ; q++) {
      unsigned bit = q == Q_VMSTRAIN ? FMBD_OUT_STRAIN : 1u << q;
      r->out[o][q] = -1;
      if (!(op->quantities & bit)) continue;
      snprintf(path, sizeof path, "/outputs/%s/%s", op->name, q_name[q]);
      FMBD_CALL(fmbd_runfile_series(r->rf, path, q_cols[q], q_unit[q], FMBD_RUNFILE_COMPARED,
                                    &r->out[o][q]));
    }
  }
  if (s->energy) {
    static const char *const en[3] = {"/energy/kinetic", "/energy/potential", "/energy/strain"};
    for (int k = 0; k < 3; k++)
      FMBD_CALL(fmbd_runfile_series(r->rf, en[k], 0, "J", 0, &r->energy[k]));
  }
  if (s->momentum) {
    FMBD_CALL(fmbd_runfile_series(r->rf, "/momentum/linear", 3, "N s", 0, &r->momentum[0]));
    FMBD_CALL(fmbd_runfile_series(r->rf, "/momentum/angular", 3, "N m s", 0, &r->momentum[1]));
  }
  for (int k = 0; k < s->nreactions; k++) {
    const char *jn = s->joints[s->reactions[k]].name;
    snprintf(path, sizeof path, "/reactions/%s/force", jn);
    FMBD_CALL(fmbd_runfile_series(r->rf, path, 3, "N", 0, &r->react[k][0]));
    snprintf(path, sizeof path, "/reactions/%s/torque", jn);
    FMBD_CALL(fmbd_runfile_series(r->rf, path, 3, "N m", 0, &r->react[k][1]));
  }
  return FMBD_OK;
}

// One output row: time, the asked quantities, energies, momenta, reactions.
int fmbd_scene_record(fmbd_scene_recorder *r) {
  const fmbd_scene *s = r->s;
  fmbd_mbs *mb = r->m->mbs;
  FMBD_CALL(fmbd_runfile_row(r->rf, fmbd_mbs_time(mb)));
  for (int o = 0; o < s->noutputs; o++) {
    const int *id = r->out[o];
    int pid = r->m->out_point[o];
    double v[6], ep[6], vm, ev;
    if (id[Q_POS] >= 0) {
      fmbd_mbs_point_position(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_POS], v));
    }
    if (id[Q_VEL] >= 0) {
      fmbd_mbs_point_velocity(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VEL], v));
    }
    if (id[Q_ACC] >= 0) {
      fmbd_mbs_point_acceleration(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_ACC], v));
    }
    if (id[Q_VM] < 0 && id[Q_STRESS] < 0 && id[Q_STRAIN] < 0) continue;
    FMBD_CALL(fmbd_scene_output_stress(r->m, o, v));
    if (id[Q_VM] >= 0) {
      vm = fmbd_von_mises(v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VM], &vm));
    }
    if (id[Q_STRESS] >= 0) FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_STRESS], v));
    if (id[Q_STRAIN] >= 0) {
      int b = r->m->out_body[o];
      ev = fmbd_scene_strain(r->m->E[b], r->m->nu[b], v, ep);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_STRAIN], ep));
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VMSTRAIN], &ev));
    }
  }
  if (s->energy) {
    double e[3];
    fmbd_mbs_energy(mb, &e[0], &e[1], &e[2]);
    for (int k = 0; k < 3; k++) FMBD_CALL(fmbd_runfile_put(r->rf, r->energy[k], &e[k]));
  }
  if (s->momentum) {
    double L[3], H[3];
    fmbd_mbs_momentum(mb, L, H);
    FMBD_CALL(fmbd_runfile_put(r->rf, r->momentum[0], L));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->momentum[1], H));
  }
  for (int k = 0; k < s->nreactions; k++) {
    double F[3], T[3];
    FMBD_CALL(fmbd_mbs_joint_reaction(mb, r->m->joint_id[s->reactions[k]], F, T));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->react[k][0], F));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->react[k][1], T));
  }
  if (r->xdmf) {
    double R[64][3], A[64][9];
    const double *Rp[64], *Ap[64], *qp[64];
    for (int i = 0; i < r->nx; i++) {
      fmbd_mbs_body_pose(mb, r->xbody[i], R[i], A[i]);
      fmbd_mbs_modal(mb, r->xbody[i], &qp[i], NULL, NULL);
      Rp[i] = R[i];
      Ap[i] = A[i];
    }
    FMBD_CALL(fmbd_xdmf_frame(r->xdmf, fmbd_mbs_time(mb), Rp, Ap, qp));
  }
  return FMBD_OK;
}

// A full FE body's fields: its active dofs from the coordinates (0 where the frame fixes them),
// the nodal translations through /expand, the element stresses averaged at the nodes.
struct fe_field {
  const fmbd_fe_body *fe;
  const int64_t *col;  // active dof -> coordinate, -1: fixed by the frame
  double *ua, *uall;   // ndof, 6 nnodes
};

static int fe_fields(void *user, const double *q, double *u, double *sigma) {
  struct fe_field *d = user;
  const fmbd_fe_body *fe = d->fe;
  for (int64_t i = 0; i < fe->ndof; i++) d->ua[i] = d->col[i] >= 0 ? q[d->col[i]] : 0.0;
  fmbd_csr_matvec(fe->expand, d->ua, d->uall);
  for (int64_t p = 0; p < fe->nnodes; p++) {
    for (int a = 0; a < 3; a++) u[a + 3 * p] = d->uall[6 * p + a];
  }
  return fmbd_fe_nodal_stress(fe, 1, d->ua, sigma);
}

// XDMF: every flexible body with solid elements, its modal stresses read again (the model
// keeps them only where an output asks).
static int add_fields(run *r, const char *xdmf_name) {
  const fmbd_scene *s = r->s;
  const fmbd_scene_model *m = r->m;
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  fmbd_rflex *rf = NULL;
  FMBD_CALL(fmbd_xdmf_create(r->rf, xdmf_name, &r->xdmf));
  FMBD_GALLOC(r->xbody = fmbd_calloc((size_t)s->nbodies + 1, sizeof(int)));
  FMBD_GALLOC(r->fe = fmbd_calloc((size_t)s->nbodies + 1, sizeof *r->fe));
  for (int b = 0; b < s->nbodies; b++) {
    if (!m->file_kind || !m->file_kind[b]) continue;  // rigid
    const char *file = s->bodies[b].file, *kind = m->file_kind[b];
    bool full = m->fe && m->fe[b] && !strcmp(kind, FMBD_FE_FORMAT);
    if (!full &&
        (!m->flex[b] || (strcmp(kind, FMBD_RFLEX_FORMAT) && strcmp(kind, FMBD_CB_FORMAT)))) {
      fmbd_log(FMBD_LOG_WARN,
               "XDMF fields: body '%s' (%s, %s) is neither a modal nor a full FE body: not in the "
               "fields",
               s->bodies[b].name, file, kind);
      continue;
    }
    FMBD_GCALL(fmbd_h5_open(file, &f));
    fmbd_err_context(file, "");
    if (fmbd_h5_exists(f, "/subset")) {  // made for its scene: no elements, a few nodes' motion
      fmbd_log(FMBD_LOG_WARN,
               "XDMF fields: body '%s' (%s) holds only what its scene reads (cbcheck "
               "--for-scene): not in the fields; make it whole (`whole: true` in its make "
               "mapping, or cbcheck without --for-scene)",
               s->bodies[b].name, file);
    } else if (!fmbd_h5_exists(f, "/mesh/elements/tet4") &&
               !fmbd_h5_exists(f, "/mesh/elements/tet10")) {
      fmbd_log(FMBD_LOG_WARN,
               "XDMF fields: body '%s' (%s) has no solid elements: not in the fields",
               s->bodies[b].name, file);
    } else {
      FMBD_GCHECK(r->nx < 64, FMBD_ERR_VALUE, "XDMF fields: more than 64 flexible bodies");
      int id = m->body_id[b];
      if (full) {  // the full model: every node's displacement and averaged element stress
        const fmbd_fe_body *fe = m->fe[b];
        struct fe_field *d = &r->fe[r->nx];
        d->fe = fe;
        d->col = m->fe_col[b];
        FMBD_GALLOC(d->ua = fmbd_calloc((size_t)fe->ndof + 1, sizeof(double)));
        FMBD_GALLOC(d->uall = fmbd_calloc((size_t)(6 * fe->nnodes) + 1, sizeof(double)));
        FMBD_GCALL(fmbd_xdmf_add_body_fn(r->xdmf, s->bodies[b].name, file, fe->nnodes, fe->xyz, f,
                                         fmbd_mbs_body_nm(m->mbs, id), fe_fields, d));
      } else {
        if (!strcmp(kind, FMBD_RFLEX_FORMAT)) {
          FMBD_GCALL(fmbd_rflex_read(f, &rf));
        } else {
          FMBD_GCALL(fmbd_scene_rflex_from_cb(f, true, &rf));
        }
        FMBD_GCALL(fmbd_xdmf_add_body(r->xdmf, s->bodies[b].name, file, rf, f,
                                      fmbd_mbs_body_nm(m->mbs, id)));
        fmbd_rflex_destroy(&rf);
      }
      r->xbody[r->nx++] = id;
    }
    fmbd_h5_close(&f);
  }
  fmbd_err_context(s->file, "");
  FMBD_GCHECK(r->nx > 0, FMBD_ERR_VALUE,
              "XDMF fields: the scene has no flexible body with solid elements");
done:
  fmbd_rflex_destroy(&rf);
  fmbd_h5_close(&f);
  return rc;
}

int fmbd_scene_recorder_create(const fmbd_scene *s, fmbd_scene_model *m, fmbd_runfile *rf,
                               const char *xdmf_name, fmbd_scene_recorder **out) {
  int rc = FMBD_OK;
  *out = NULL;
  run *r = fmbd_calloc(1, sizeof *r);
  FMBD_CHECK(r, FMBD_ERR_NOMEM, "out of memory");
  r->s = s;
  r->m = m;
  r->rf = rf;
  fmbd_runfile_set_stats(rf, get_stats, r);
  FMBD_GALLOC(r->out = fmbd_calloc((size_t)s->noutputs + 1, sizeof *r->out));
  FMBD_GALLOC(r->react = fmbd_calloc((size_t)s->nreactions + 1, sizeof *r->react));
  FMBD_GCALL(declare(r));
  if (xdmf_name) FMBD_GCALL(add_fields(r, xdmf_name));
  *out = r;
  return FMBD_OK;
done:
  fmbd_scene_recorder_destroy(&r);
  return rc;
}

int fmbd_scene_recorder_position(const fmbd_scene_recorder *r, int o) {
  return o >= 0 && o < r->s->noutputs ? r->out[o][Q_POS] : -1;
}

int fmbd_scene_recorder_commit(fmbd_scene_recorder *r) {
  return r->xdmf ? fmbd_xdmf_commit(&r->xdmf) : FMBD_OK;
}

void fmbd_scene_recorder_destroy(fmbd_scene_recorder **rp) {
  run *r = *rp;
  if (!r) return;
  fmbd_xdmf_close(&r->xdmf);
  for (int i = 0; r->fe && i < r->s->nbodies; i++) {
    fmbd_free(r->fe[i].ua);
    fmbd_free(r->fe[i].uall);
  }
  fmbd_free(r->fe);
  fmbd_free(r->xbody);
  fmbd_free(r->out);
  fmbd_free(r->react);
  fmbd_free(r);
  *rp = NULL;
}
