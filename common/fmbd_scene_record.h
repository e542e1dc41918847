// common/fmbd_scene_record.h: the outputs of a scene model recorded in a run file: the series
// the scene asks for (point outputs, energies, momenta, reactions), the integrator's counters
// in /stats, and with XDMF the fields of its flexible bodies
// SPDX-License-Identifier: MIT
//
// Between the multibody model of a scene (fmbd_scene_build.h) and the run file (fmbd_runfile.h):
//
//   fmbd_scene_recorder *rec;
//   FMBD_CALL(fmbd_runfile_create(name, keep, &rf));
//   FMBD_CALL(fmbd_scene_recorder_create(s, m, rf, xdmf_name_or_NULL, &rec));  // the series
//   FMBD_CALL(fmbd_scene_record(rec));   // the initial state, then at every output instant
//   ... fmbd_runfile_finish / _compare / _commit, then
//   FMBD_CALL(fmbd_scene_recorder_commit(rec));   // RUN.xdmf (if asked)
//   fmbd_scene_recorder_destroy(&rec);
#ifndef FMBD_SCENE_RECORD_H
#define FMBD_SCENE_RECORD_H

#include "fmbd_runfile.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"

typedef struct fmbd_scene_recorder fmbd_scene_recorder;

/// @brief Declare in rf the series of the scene's outputs (docs/FORMAT.md: /outputs/NAME/*,
/// compared with a reference, with the attributes body and node; /energy/*, /momentum/*,
/// /reactions/JOINT/*), make rf's /stats come from m's integrator, and with xdmf_name (not NULL)
/// the fields of every flexible body with solid elements (fmbd_xdmf.h; modal bodies' files are
/// read again for their modal stresses, full FE bodies give their nodal displacements and the
/// element stresses averaged at the nodes; bodies without solid elements are left out with a
/// warning, none at all is an error naming the scene). s, m and rf must outlive the recorder.
int fmbd_scene_recorder_create(const fmbd_scene *s, fmbd_scene_model *m, fmbd_runfile *rf,
                               const char *xdmf_name, fmbd_scene_recorder **out);
/// @brief One run-file row of the model's state now.
int fmbd_scene_record(fmbd_scene_recorder *r);
/// @brief The series id of output o's position, or -1 (for fmbd_runfile_plot_position).
int fmbd_scene_recorder_position(const fmbd_scene_recorder *r, int o);
/// @brief After fmbd_runfile_commit: write the XDMF file, if asked.
int fmbd_scene_recorder_commit(fmbd_scene_recorder *r);
/// @brief Release (the XDMF file is not written unless committed); NULL fine. The run file
/// calls the recorder for its /stats until it is committed, abandoned or closed: release the
/// recorder after that.
void fmbd_scene_recorder_destroy(fmbd_scene_recorder **r);

#endif
