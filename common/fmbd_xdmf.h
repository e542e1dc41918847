// common/fmbd_xdmf.h: the deformed flexible bodies of a run as fields for ParaView: per output
// frame the nodes' world positions, elastic displacements and von Mises stress in the run file
// (/fields), and RUN.xdmf, an XDMF 3 temporal collection that points into it
// SPDX-License-Identifier: MIT
//
// For a modal body with pose (R, A) and modal coordinates q at a frame, node p's
//   elastic displacement (body frame)  u_p = T_p q,   T_p = rows 6p..6p+2 of /expand * shapes
//   world position                     r_p = R + A (x0_p + u_p)
//   stress (body frame)                sigma_p = S_p q,  S_p = /modes/stress[p] (6 x nm)
// and von Mises of sigma_p (docs/THEORY.md section 9: the modal stresses, recovered at the
// frames written only). The run file gets, beside the series of fmbd_runfile:
//   /fields/nodes (N, 3), /fields/cells (C, k): the bodies' meshes concatenated (reference
//   coordinates, body frames; cells in XDMF node order, indices into the N nodes);
//   /fields/body/NAME: attributes file, first_node, nodes, first_cell, cells; series pose
//   (frames, 12: R then A row-major) and q (frames, nm), one row per run-file row;
//   /fields/frames/K/{position (N, 3), displacement (N, 3), von_mises (N,)}, K = 0, 1, ...
// RUN.xdmf refers to RUN.h5 by its base name: keep the two side by side.
//
//   fmbd_xdmf *x;
//   FMBD_CALL(fmbd_xdmf_create(rf, "pend.xdmf", &x));
//   FMBD_CALL(fmbd_xdmf_add_body(x, "rod", "rod.rflex.h5", rflex, body_file, nm));  // each body
//   ... at every run-file row, after fmbd_runfile_row:
//   FMBD_CALL(fmbd_xdmf_frame(x, t, R, A, q));   // R[b], A[b], q[b] per body, in order added
//   ... after fmbd_runfile_commit:
//   FMBD_CALL(fmbd_xdmf_commit(&x));             // RUN.xdmf.part -> RUN.xdmf
#ifndef FMBD_XDMF_H
#define FMBD_XDMF_H

#include <stdint.h>

#include "fmbd_h5.h"
#include "fmbd_rflex.h"
#include "fmbd_runfile.h"

typedef struct fmbd_xdmf fmbd_xdmf;

/// @brief Start the fields of the run file rf (a named file, not standard output) and the
/// XDMF file `xdmf_name` (written at fmbd_xdmf_commit).
int fmbd_xdmf_create(fmbd_runfile *rf, const char *xdmf_name, fmbd_xdmf **out);
/// @brief The same fields in any open HDF5 file h written under the name h5_name (its base name
/// is what the XDMF file refers to): /fields/nodes, /fields/cells, /fields/body/NAME (without the
/// pose and q series of a run file) and /fields/frames/K (gmsolve --xdmf: one frame per global
/// mode). h must stay open until the last frame.
int fmbd_xdmf_create_h5(fmbd_h5 *h, const char *h5_name, const char *xdmf_name, fmbd_xdmf **out);
/// @brief Add a flexible body before the first frame: its name, the body file's name (for the
/// file attribute), the reduced body r (the first nm of its modes are used: the body's modal
/// coordinates; r->stress is needed) and the open body file (its /mesh/elements: tet4 or tet10;
/// every body of one run must have the same kind). The data are copied: r and f may be released
/// afterwards. FMBD_ERR_VALUE naming the body for a body without stress or without solid
/// elements.
int fmbd_xdmf_add_body(fmbd_xdmf *x, const char *name, const char *file, const fmbd_rflex *r,
                       fmbd_h5 *f, int64_t nm);
/// The fields of a body that is not modal (a full FE body): from its coordinates q, the
/// elastic translations u[a + 3p] and stresses sigma[i + 6p] (xx yy zz xy yz zx) of its nodes.
typedef int (*fmbd_xdmf_field_fn)(void *user, const double *q, double *u, double *sigma);
/// @brief Add a body whose fields fn computes (nnodes nodes at x0[a + 3p], body frame; nq
/// coordinates, written as its q series): the same as fmbd_xdmf_add_body otherwise. fn and user
/// must live until the last frame.
int fmbd_xdmf_add_body_fn(fmbd_xdmf *x, const char *name, const char *file, int64_t nnodes,
                          const double *x0, fmbd_h5 *f, int64_t nq, fmbd_xdmf_field_fn fn,
                          void *user);
/// @brief One frame at time t (call after fmbd_runfile_row, once per row): per body b in the
/// order added, its origin R[b] (3), rotation A[b] (9, body -> world, row-major) and modal
/// coordinates q[b] (nm).
int fmbd_xdmf_frame(fmbd_xdmf *x, double t, const double *const *R, const double *const *A,
                    const double *const *q);
/// @brief Write the XDMF file (every frame) under NAME.part and rename it; *x is NULL after.
int fmbd_xdmf_commit(fmbd_xdmf **x);
/// @brief Release without writing the XDMF file. NULL fine.
void fmbd_xdmf_close(fmbd_xdmf **x);

#endif
