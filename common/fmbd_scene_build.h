// common/fmbd_scene_build.h: a scene (fmbd_scene.h) turned into a multibody system (fmbd_mbs.h):
// the body files opened, points placed, joints, drivers, loads and outputs added
// SPDX-License-Identifier: MIT
//
// The solver settings need no translation: the scene's `solver` is the fmbd_mbs_settings that
// fmbd_mbs_init takes.
#ifndef FMBD_SCENE_BUILD_H
#define FMBD_SCENE_BUILD_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_mbs.h"
#include "fmbd_rflex.h"
#include "fmbd_scene.h"

/// A scene turned into an fmbd_mbs system, with what the outputs need to be evaluated.
typedef struct fmbd_scene_model {
  fmbd_mbs *mbs;      ///< owned; fmbd_mbs_init not yet called
  int nbodies;        ///< = scene nbodies
  int *body_id;       ///< scene body -> mbs body id
  fmbd_rflex **flex;  ///< per body: the modal body (NULL for rigid), owned
  double *E, *nu;     ///< per body: material of a flexible body (strain outputs)
  char **file_kind;   ///< per body: "fmbd-rflex" / "fmbd-cb" / "fmbd-fe" / NULL (rigid)
  fmbd_fe_body **fe;  ///< per body: a full FE body (fmbd-fe file; flex[i] then holds only its
                      ///< nodes and interfaces, nm = 0), else NULL; owned
  int64_t **fe_col;   ///< per FE body: active dof -> coordinate (-1: fixed by the frame)
  int *joint_id;      ///< scene joint -> mbs joint id
  int noutputs;
  int *out_point;         ///< per output: mbs point id
  int *out_body;          ///< per output: scene body index
  int64_t *out_node;      ///< per output: node of a flexible body, or -1
  double **out_sigma;     ///< per output: 6 x nm modal stress (stress/strain asked), or NULL
  int ninputs;            ///< body files read (provenance)
  char **input_name;      ///< owned names
  char (*input_sha)[65];  ///< their SHA-256
} fmbd_scene_model;

/// @brief Build the multibody system of a scene: open every body file (.rflex.h5, .cb.h5, or
/// .fe.h5 for a full FE body, docs/THEORY.md section 4b; another kind is an error naming the
/// scene line of `file`), keep the first N modes if
/// asked, place points of joints, loads and outputs (a joint point that is not on its
/// flexible body is an error naming the joint's line and the nearest node), add joints,
/// drivers, loads and gravity. Modal stress is kept only for outputs asking for it.
/// @param[out] out caller destroys with fmbd_scene_model_destroy
int fmbd_scene_build(const fmbd_scene *s, fmbd_scene_model **out);
/// @brief Stress (xx yy zz xy yz zx, Pa) at output `o` now (out_sigma times the body's
/// modal coordinates; for a full FE body the nodal average of the element stresses of the
/// current nodal displacements, fmbd_fe_nodal_stress). FMBD_ERR_VALUE if that output has no
/// stress.
int fmbd_scene_output_stress(const fmbd_scene_model *m, int o, double sigma[6]);
/// @brief Linear elastic strain (tensor components xx yy zz xy yz zx) of a stress, and its
/// von Mises equivalent 2 (1 + nu) sigma_vm / (3 E) (returned).
double fmbd_scene_strain(double E, double nu, const double sigma[6], double eps[6]);
/// @brief Release the model; NULL fine.
void fmbd_scene_model_destroy(fmbd_scene_model **m);
/// @brief A flexible body from a .cb.h5 (format fmbd-cb): the flexible eigenvectors of the
/// reduced problem (/reduced/eigenvectors without /reduced/rigid), expanded to the FE dofs
/// (qF = [Phi Psi; 0 I] Xi, mass-normalised), built by fmbd_rflex_build (the one producer of
/// reduced bodies, as cbcheck's), its inertia invariants with the mass the modes come from
/// (docs/THEORY.md section 9); with stress, the modal stresses of its modes (the fe
/// description in the cb file carries the elements and the material).
/// @param[out] out caller destroys with fmbd_rflex_destroy
int fmbd_scene_rflex_from_cb(fmbd_h5 *f, bool stress, fmbd_rflex **out);
/// @brief The nodes of flexible body bi that scene s reads, resolved on r as fmbd_scene_build
/// resolves them: the joints', loads' and point outputs' nodes (motion), and the nodes of
/// outputs that ask for stress or strain (stress; they need motion too). For a body that holds
/// only what the scene reads (fmbd_rflex_subset; cbcheck --for-scene). Errors name the scene
/// line, as fmbd_scene_build's; a joint whose point comes from another flexible body's file
/// (no `point`, the place named only on that body) cannot be resolved here and is an error.
/// @param[out] motion, stress  caller frees (fmbd_free); may repeat a node
int fmbd_scene_body_nodes(const fmbd_scene *s, int bi, const fmbd_rflex *r, int64_t **motion,
                          int64_t *nmotion, int64_t **stress, int64_t *nstress);

#endif
