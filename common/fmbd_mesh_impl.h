// common/fmbd_mesh_impl.h: helpers of fmbd_mesh.c that the readers in fmbd_mesh_read.c share
// (internal to the library; not part of fmbd.h)
// SPDX-License-Identifier: MIT
#ifndef FMBD_MESH_IMPL_H
#define FMBD_MESH_IMPL_H

#include <stddef.h>
#include <stdint.h>

#include "fmbd_mesh.h"

int fmbd_mesh_ends_with(const char *name, const char *ext);
// add a node group (sorted, unique) named name
int fmbd_mesh_add_group_(fmbd_mesh *m, const char *name, int64_t n, const int64_t *nodes);
double fmbd_mesh_bbox_diagonal(int64_t n, const double *xyz);
// fmbd_mesh_check naming elements by their gmsh tags (NULL: by index)
int fmbd_mesh_check_tagged(const fmbd_mesh *m, const size_t *tet_tag, const size_t *beam_tag);
// drop the nodes with keep[i] == 0 (renumbering elements and groups)
int fmbd_mesh_compact_nodes(fmbd_mesh *m, const unsigned char *keep);
int fmbd_mesh_reduce_to_tet4(fmbd_mesh *m);
double fmbd_mesh_tet_detj(const double *xyz, int nn, const int64_t *nodes, const double p[3]);

#endif
