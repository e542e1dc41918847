// common/fmbd.h: umbrella header of libfmbd, the shared library of the toolchain
// SPDX-License-Identifier: MIT
//
// Conventions for the whole API (see each module's header for details):
// - fallible functions return int: 0 = FMBD_OK, negative = an FMBD_ERR_* code (fmbd_err.h);
//   results come through out-parameters; the library never writes to stdout or exits;
// - ownership: an out-parameter documented "caller frees" is released with fmbd_free, an
//   object with its fmbd_<type>_destroy(&p), which accepts NULL and sets p = NULL;
// - all memory through fmbd_malloc & co (fmbd_alloc.h), so tests can fail the Nth call.
#ifndef FMBD_H
#define FMBD_H

// infrastructure
#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_sha256.h"
#include "fmbd_svg.h"
// linear algebra
#include "fmbd_chol.h"
#include "fmbd_csr.h"
#include "fmbd_dense.h"
#include "fmbd_eig.h"
// finite elements and reduction (mesh2fe, fe2cb, cbcheck)
#include "fmbd_cb.h"
#include "fmbd_est.h"
#include "fmbd_fe.h"
#include "fmbd_mesh.h"
#include "fmbd_rflex.h"
// multibody simulation (fmbd-run)
#include "fmbd_mbs.h"
#include "fmbd_scene.h"

#endif
