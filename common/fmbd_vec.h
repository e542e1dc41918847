/// @file fmbd_vec.h
/// @brief The library's one 4-wide double vector type (GCC/clang vector extension) for the
/// kernels chosen when called by processor (fmbd_csr.c's sparse products, fmbd_chol.c's own
/// supernodal solves, fmbd_mbs_body.c's dense product). Internal to common/. Each user sets its
/// own floating-point contraction rule (bitwise kernels: none; the solves: explicit FMA) and its
/// own target attributes; this header only gives the type, unaligned loads and stores.
#ifndef FMBD_VEC_H
#define FMBD_VEC_H

#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__) && !defined(FMBD_NO_VECTOR)
/// defined where the vector kernels are compiled (x86-64, GCC or clang, not FMBD_NO_VECTOR)
#define FMBD_HAVE_V4D 1
/// four doubles, loaded and stored at any double's alignment, aliasing plain doubles
typedef double v4d
    __attribute__((vector_size(4 * sizeof(double)), aligned(sizeof(double)), may_alias));
#define LD4(p) (*(const v4d *)(p))
#define ST4(p, v) (*(v4d *)(p) = (v))
#endif

#endif
