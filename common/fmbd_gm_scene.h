// common/fmbd_gm_scene.h: the global modes of a scene's mechanism (gmsolve's library side):
// the rigid-reference configuration, the mechanism's equations named as the scene names them,
// and each flexible body's GMs and GMc bases in the fmbd-gm file
// SPDX-License-Identifier: MIT
//
// USE (gmsolve/main.c): fmbd_scene_read -> fmbd_scene_build -> fmbd_mbs_init ->
//   fmbd_gm_rigid_reference (x) -> fmbd_mbs_linearise at x -> fmbd_gm_solve (common/fmbd_gm.h)
//   -> fmbd_gm_write_body for every flexible body. docs/THEORY.md section 6 states the method.
#ifndef FMBD_GM_SCENE_H
#define FMBD_GM_SCENE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fmbd_h5.h"
#include "fmbd_mbs.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"

/// @brief The name of equation e of the mechanism (fmbd_mbs numbering: the joints' equations in
/// scene order, then the drivers', then one Euler-parameter normalisation per body) as the scene
/// names it: "FILE:LINE: joint 'J' (kind) equation k", "FILE:LINE: driver 'D'", "FILE:LINE: the
/// Euler-parameter normalisation of body 'B'".
/// @brief The number of equations fmbd_scene_build gives the scene's mechanism (joints,
/// drivers, normalisations, redundant ones included): a check of the numbering below.
int64_t fmbd_gm_equation_count(const fmbd_scene *s);
/// @brief True when equation e (same numbering) is a driver's (a prescribed motion).
bool fmbd_gm_equation_is_driver(const fmbd_scene *s, int64_t e);
void fmbd_gm_equation_name(const fmbd_scene *s, const fmbd_scene_model *md, int64_t e, char *buf,
                           size_t len);

/// @brief The rigid-reference configuration at time T: the elastic coordinates zero and the frame
/// coordinates (rigid[i] true) moved, least change, onto Phi(x, T) = 0 by Gauss-Newton steps
/// dx_r = -Cr' (Cr Cr')^+ phi (Cr: the constraint Jacobian's frame columns; the pseudo-inverse
/// allows rows dependent on the frames alone), to 1e-12 of the mechanism's size.
/// @param[in]  rigid (n) true for the frame coordinates (R, p) of every body
/// @param[out] x     (n) the configuration; starts from the model's current state
/// @return FMBD_OK; FMBD_ERR_CONVERGE naming the worst equation (fmbd_gm_equation_name) when the
///         constraints cannot be satisfied; errors of fmbd_mbs_linearise
int fmbd_gm_rigid_reference(fmbd_mbs *mbs, const fmbd_scene *s, const fmbd_scene_model *md,
                            const bool *rigid, double T, double *x);

/// @brief Write flexible scene body bi's GMs and GMc bases (docs/FORMAT.md, fmbd-gm) from the
/// nk global modes Xf (n x nk, column-major, mechanism coordinates). The body's elastic
/// coordinates start at off + 7: nq modal coordinates of a modal body (shapes on the FE dofs
/// through the body file's modes) or the FE dofs of a full FE body other than its frame node's.
/// GMc keeps the columns independent to rank_tol (Gram-Schmidt in the body's mass, in mode
/// order), stored mass-orthonormal. sha: the body file's SHA-256 (recorded; may be NULL).
/// @param[out] ncols the GMc columns kept
int fmbd_gm_write_body(fmbd_h5 *f, const fmbd_scene *s, const fmbd_scene_model *md, int bi,
                       int64_t off, int64_t nq, int64_t n, const double *Xf, int64_t nk,
                       double rank_tol, const char *sha, int64_t *ncols);

#endif
