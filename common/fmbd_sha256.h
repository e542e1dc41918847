// common/fmbd_sha256.h: SHA-256 (FIPS 180-4) of buffers and files, for the inputs attribute
// SPDX-License-Identifier: MIT
#ifndef FMBD_SHA256_H
#define FMBD_SHA256_H

#include <stdint.h>

/// Streaming SHA-256 state: init, update any number of times, final.
typedef struct fmbd_sha256 {
  uint32_t h[8];
  uint64_t nbytes;
  unsigned nbuf;
  unsigned char buf[64];
} fmbd_sha256;
void fmbd_sha256_init(fmbd_sha256 *s);
void fmbd_sha256_update(fmbd_sha256 *s, const void *data, uint64_t n);
/// @brief Finish: 64 lowercase hex chars + NUL. The state must be re-initialised to be reused.
void fmbd_sha256_final(fmbd_sha256 *s, char hex[65]);
/// @brief SHA-256 of a byte buffer as 64 lowercase hex chars + NUL.
void fmbd_sha256_hex(const void *data, uint64_t n, char hex[65]);
/// @brief SHA-256 of a file's contents. FMBD_ERR_IO if it cannot be read.
int fmbd_sha256_file(const char *path, char hex[65]);
/// @brief Whether the x86 SHA extensions are used: enable 0 forces the portable code, 1 uses
/// them when the processor has them, -1 only asks. Returns 1 when they are used.
int fmbd_sha256_hw(int enable);

#endif
