// common/fmbd_check.h: checking a Craig-Bampton body a posteriori: the cb file, the fe file it
// was reduced from, the estimators built from both, more fixed-interface modes on demand, exact
// eigenvalues, and the reduced flexible body written with its selection record (cbcheck's engine)
// SPDX-License-Identifier: MIT
//
// A `fmbd_check` is one cb file opened for estimation (docs/THEORY.md sections 2 and 3):
//
//   fmbd_check_open        reads /cb, /reduced and the body description, builds the estimator
//                          of the body as reduced (every boundary dof free) and, with holds,
//                          the estimator of the held problem (docs/THEORY.md section 12)
//   fmbd_check_estimator   the problem that is estimated and selected (held if any, else free)
//   fmbd_check_extend      a fmbd_est_extend_fn: more fixed-interface modes through fe2cb's
//                          library (fmbd_cb_extend), from the fe file
//   fmbd_check_exact       the full body's eigenvalues (--exact)
//   fmbd_check_rflex       the kept modes as a fmbd_rflex (through fmbd_rflex_build)
//   fmbd_check_subset_for_scene  a body that holds only what one scene reads (/subset)
//   fmbd_check_write_rflex the rflex file: inputs, body description, modes, /modes record
//
// THE FE FILE. The residual blocks are exact (projected, fmbd_est_base_projected) when the fe
// file is at hand, else from the cb file alone (fmbd_est_base_plain). It is found as
// fmbd_cb_source_fe says: --fe, else the cb file's fe_file attribute as given or beside the cb
// file; its SHA-256 must equal the cb file's fe_sha256. A file the user named must be usable
// (an error otherwise); a recorded one that is missing or changed is a warning, and the
// estimates come from the cb file alone, until something needs it (more modes, --exact): then
// its absence is an error that says why it was needed.
//
// ERRORS: FMBD_OK or an fmbd_err code with the message and the file/dataset context set.
#ifndef FMBD_CHECK_H
#define FMBD_CHECK_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_cb.h"
#include "fmbd_est.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_rflex.h"

/// What the user chose (fmbd_check_opts_defaults: none of it).
typedef struct fmbd_check_opts {
  const char *fe;           ///< the fe file to use (NULL: the cb file's fe_file attribute)
  bool plain;               ///< never read the fe file for the estimates (cb file alone)
  int nhold;                ///< interfaces held by the scene (docs/THEORY.md section 12)
  const char *const *hold;  ///< their names (nhold)
  int64_t max_modes;        ///< most fixed-interface modes (<= 0: the interior dofs - 1)
} fmbd_check_opts;

void fmbd_check_opts_defaults(fmbd_check_opts *o);

/// The open check. Fields are read-only for callers; all owned, released by fmbd_check_close.
typedef struct fmbd_check {
  fmbd_check_opts opts;
  fmbd_h5 *cbf;          ///< the cb file
  fmbd_cb *cb;           ///< its /cb, /reduced (nd grows with fmbd_check_extend)
  fmbd_fe_body *desc;    ///< its body description (no K, M)
  fmbd_fe_body *fe;      ///< the fe body with K, M (NULL until loaded, or unavailable)
  char *fe_name;         ///< the fe file read (NULL: none)
  char fe_sha[65];       ///< its SHA-256
  bool fe_tried;         ///< a lookup was made
  fmbd_est *est;         ///< the body as reduced (every boundary dof free)
  fmbd_est *est_held;    ///< with holds: the held problem (boundary = the free dofs), else NULL
  int64_t nheld, nfree;  ///< boundary dofs held / free
  int64_t *held_idx, *free_idx;  ///< their positions in /cb/boundary_dofs
  int64_t nd_max;                ///< most fixed-interface modes (interior dofs - 1, max_modes)
  int64_t nd_file;               ///< fixed-interface modes in the cb file
  int64_t nextend;               ///< fmbd_check_extend calls that added modes
  double t_extend_s, t_exact_s, t_load_s;  ///< wall time: extensions, exact, fe file
  double c_exact_s, c_load_s;              ///< cpu time: exact, fe file
  char *subset_scene, *subset_body;        ///< fmbd_check_subset_for_scene: made for them
  char subset_sha[65];                     ///< the scene file's SHA-256
} fmbd_check;

/// Open `cb_path` (format fmbd-cb) and build the estimators at the file's Nd (reads the fe file
/// when it is usable, see above). *out on success; nothing allocated on failure.
int fmbd_check_open(const char *cb_path, const fmbd_check_opts *o, fmbd_check **out);
void fmbd_check_close(fmbd_check **c);

/// The problem estimated and selected: the held one with holds, else the free one.
fmbd_est *fmbd_check_estimator(fmbd_check *c);

/// Load the fe file if not yet done. required: failure is an error naming `why`; else a
/// warning and c->fe stays NULL. A file given in the options is always required.
int fmbd_check_load_fe(fmbd_check *c, bool required, const char *why);

/// fmbd_est_extend_fn (ctx = the fmbd_check): at least nd_wanted fixed-interface modes (grows
/// by half the pool, at least 10, at most nd_max), the estimators' pools reset to them.
int fmbd_check_extend(void *ctx, fmbd_est *e, int64_t nd_wanted);

/// Eigenvalues of the first nflex FLEXIBLE modes of the full body into *chi (nflex, caller
/// frees with fmbd_free), its n_rigid rigid-body modes skipped. Method "nm": the reduced modes
/// are exact eigenpairs, so chi = their eigenvalues (m, no eigensolution).
int fmbd_check_exact(fmbd_check *c, const fmbd_est_modes *m, int64_t nflex, double **chi);

/// An engine for fmbd_check_exact's eigensolution in place of fmbd_eig_solve (cbcheck-mpi:
/// SLEPc on MPI processes, docs/SCALE.md): the lowest nev eigenvalues of K x = lambda M x of
/// the fe file fe_path (c->fe's K and M, read from it), ascending, into lambda (nev), with
/// fmbd_eig_solve's guarantee that none was skipped; free_body as fmbd_eig_opts.
typedef int (*fmbd_check_exact_engine)(void *ctx, const char *fe_path, const fmbd_csr *K,
                                       const fmbd_csr *M, int64_t nev, bool free_body,
                                       double *lambda);
/// @brief Set (fn NULL: reset to fmbd_eig_solve) the engine of every later fmbd_check_exact.
void fmbd_check_set_exact_engine(fmbd_check_exact_engine fn, void *ctx);

/// The reduced flexible body of the first nm flexible modes of m (Xi: the reduced eigenvectors
/// of fmbd_est_run, nr x m->nmodes). With holds, the held problem's modes are completed by the
/// held dofs' constraint modes (fmbd_est_held_modes): *nkept >= nm modes.
int fmbd_check_rflex(fmbd_check *c, const fmbd_est_modes *m, const double *Xi, int64_t nm,
                     bool stress, fmbd_rflex **rf, int64_t *nkept);

/// The selection a reduced body records in /modes (docs/FORMAT.md).
typedef struct fmbd_check_record {
  int64_t nd;           ///< fixed-interface modes (n_fixed_interface_modes)
  double max_estimate;  ///< the largest estimate of the kept modes (max_estimate)
  double tolerance;     ///< the tolerance met (<= 0: none given; attribute absent)
} fmbd_check_record;

/// Make rf a body that holds only what one scene reads (--for-scene SCENE:BODY; docs/FORMAT.md
/// /subset): the nodes of BODY's joints, loads and point outputs in SCENE, resolved as fmbd-run
/// resolves them (fmbd_scene_body_nodes), stress only where an output asks for it
/// (fmbd_rflex_subset). Errors name the scene line; a BODY that is not a flexible body of the
/// scene is an error.
int fmbd_check_subset_for_scene(fmbd_check *c, fmbd_rflex *rf, const char *spec);

/// Write the rflex file `path` atomically: inputs (the cb file, the fe file if read), the body
/// description, the modes (fmbd_rflex_write) and the /modes record, held_interfaces included;
/// wall_s, cpu_s: the times recorded in the provenance (the program's, fmbd_h5_commit).
int fmbd_check_write_rflex(fmbd_check *c, const char *path, const fmbd_rflex *rf,
                           const fmbd_check_record *rec, double wall_s, double cpu_s);

#endif
