// common/fmbd_fe_impl.h: internals shared by fmbd_fe.c, fmbd_fe_tie.c and fmbd_fe_io.c
// SPDX-License-Identifier: MIT
#ifndef FMBD_FE_IMPL_H
#define FMBD_FE_IMPL_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"
#include "fmbd_fe.h"

/// Build the map from the full dofs (fdof[p] .. fdof[p+1]-1 of node p, 3 or 6 of them) to the
/// active dofs, from the body's interfaces and clamps: fills b->ndof, b->dofs, b->node_dof and
/// b->expand, and returns T (nfull x ndof) with u_full = T q. node_tied[p] (caller allocates
/// nnodes) is set to 1 for nodes with a tied (RBE2 slave or RBE3 dependent) dof, else 0; the
/// dofs of an untied node are either all active (identity rows) or all clamped (empty rows).
/// @param[out] T caller destroys
int fmbd_fe_tie_build(fmbd_fe_body *b, const int64_t *fdof, fmbd_csr **T, int8_t *node_tied);

/// Derive b->node_dof from b->dofs (checks that /dofs is node-major and in range).
int fmbd_fe_index_dofs(fmbd_fe_body *b);

/// The assembly's element loop visits the nodes set by set (fmbd_fe.c, "the order of the element
/// loop"). For tests only: set_nodes > 0 fixes the nodes per set (0: from the cache size), and
/// the assembly records the number of sets it used in sets_used.
typedef struct fmbd_fe_asm_hook {
  int64_t set_nodes;
  int32_t sets_used;
} fmbd_fe_asm_hook;
extern fmbd_fe_asm_hook fmbd_fe_asm_test;

#endif
