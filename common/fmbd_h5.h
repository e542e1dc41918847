// common/fmbd_h5.h: HDF5 files of the toolchain: reading, atomic writing, stdin/stdout images
// SPDX-License-Identifier: MIT
//
// Conventions (docs/DESIGN.md, docs/FORMAT.md):
// - root attributes format, format_version ("MAJOR.MINOR"), creator, command_line, inputs
//   ((n, 2) strings: name, SHA-256 hex), wall_time_s, cpu_time_s;
// - dense arrays row-major with the shape h5py shows; those of 8192 values or more chunked
//   (about 1 MiB a chunk) + shuffle + deflate: integers level 4, floats level 1 up to 4 M
//   values and uncompressed beyond (compressing doubles costs ~0.2 us each and saves little;
//   FMBD_H5_DEFLATE=0..9 in the environment forces one level for all); smaller ones contiguous;
// - sparse matrices as CSR groups (data, indices, indptr int64; attrs encoding-type =
//   "csr_matrix", shape (2,) int64), full symmetric storage.
// A file name "-" reads the whole file from standard input (an HDF5 file image) or writes it
// to standard output when committed. Writing goes to "<target>.part", renamed to the target
// by fmbd_h5_commit only when complete.
// Every failure names the file and the HDF5 path in the error record (fmbd_err_context);
// standard input / output are named "<stdin>" / "<stdout>" there.
// HDF5's own error printing is off unless fmbd_h5_debug(true).
#ifndef FMBD_H5_H
#define FMBD_H5_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"

/// The file kinds (root attribute `format`), the `format_version` written, and the major
/// version readers accept (docs/FORMAT.md): one place for every program and module.
#define FMBD_FE_FORMAT "fmbd-fe"
#define FMBD_FE_FORMAT_VERSION "1.0"
#define FMBD_FE_FORMAT_MAJOR 1
#define FMBD_CB_FORMAT "fmbd-cb"
#define FMBD_CB_FORMAT_VERSION "1.0"
#define FMBD_CB_FORMAT_MAJOR 1
#define FMBD_RFLEX_FORMAT "fmbd-rflex"
#define FMBD_RFLEX_VERSION "1.0"
#define FMBD_RFLEX_MAJOR 1
#define FMBD_RUN_FORMAT "fmbd-run"
#define FMBD_RUN_FORMAT_VERSION "1.0"
#define FMBD_RUN_FORMAT_MAJOR 1

typedef struct fmbd_h5 fmbd_h5;

/// @brief Turn HDF5's automatic error stack printing on (--debug) or off (default).
void fmbd_h5_debug(bool on);

// --- opening for reading -----------------------------------------------------------------
/// @brief Open an existing file read-only ("-" = standard input). Computes the SHA-256 of
/// the bytes read, for provenance. Fails with FMBD_ERR_IO (missing, unreadable) or
/// FMBD_ERR_FORMAT (not HDF5, truncated).
/// @param[out] out caller closes with fmbd_h5_close
int fmbd_h5_open(const char *name, fmbd_h5 **out);
/// @brief Check the root attributes: `format` equals `format` (else FMBD_ERR_FORMAT: "is a
/// fmbd-cb file, expected fmbd-fe" or "not a toolchain file"), and `format_version` major
/// <= `major` (else FMBD_ERR_VERSION). A newer minor is accepted.
int fmbd_h5_check_format(fmbd_h5 *f, const char *format, int major);
/// @brief Close (read or write handle; an uncommitted write handle is discarded). NULL ok.
void fmbd_h5_close(fmbd_h5 **f);
/// @brief The name given at open/create (borrowed).
const char *fmbd_h5_name(const fmbd_h5 *f);
/// @brief SHA-256 hex (64 chars + NUL) of the file's bytes as read (read handles only; "" for
/// a handle of fmbd_h5_open_unhashed until fmbd_h5_sha256_now).
const char *fmbd_h5_sha256(const fmbd_h5 *f);
/// @brief fmbd_h5_open without the SHA-256 of a regular file (standard input, a FIFO or a
/// device are hashed as by fmbd_h5_open): for a reader that records the file only in some runs
/// (cbcheck's cb file, an input of the rflex file it may write).
int fmbd_h5_open_unhashed(const char *name, fmbd_h5 **out);
/// @brief The SHA-256 of a read handle's file (as fmbd_h5_sha256), computed now for a handle of
/// fmbd_h5_open_unhashed (once; an input hashed before in the process is not hashed again).
/// FMBD_ERR_IO when the file changed (device, inode, size, modification or change time) since
/// it was opened: the bytes read are then not the ones that would be hashed.
int fmbd_h5_sha256_now(fmbd_h5 *f, const char **sha);

// --- creating ---------------------------------------------------------------------------
/// @brief Create a file to be written: "<name>.part" (or an in-memory image for "-"),
/// with the root attributes format, format_version, creator ("prog VERSION" from
/// fmbd_log_prog and fmbd_version) and command_line (fmbd_cli_command_line).
/// @param[out] out caller ends with fmbd_h5_commit or fmbd_h5_close
int fmbd_h5_create(const char *name, const char *format, const char *format_version, fmbd_h5 **out);
/// @brief Record one input file in the `inputs` root attribute (written at commit).
/// sha256 may be NULL: then the file is read and hashed here ("-" not allowed then).
int fmbd_h5_add_input(fmbd_h5 *f, const char *name, const char *sha256);
/// @brief Flush to disk (for time series written as a run goes).
int fmbd_h5_flush(fmbd_h5 *f);
/// @brief Write wall_time_s / cpu_time_s, close, and rename "<name>.part" to name (or write
/// the image to standard output). *f is NULL afterwards, also on failure (then no target).
int fmbd_h5_commit(fmbd_h5 **f, double wall_s, double cpu_s);
/// @brief Close a write handle but keep "<name>.part" (an interrupted run's valid prefix; what
/// was flushed is readable). For "-" nothing is written to standard output.
void fmbd_h5_abandon(fmbd_h5 **f);

// --- datasets ---------------------------------------------------------------------------
/// @brief Whether an object (group or dataset) exists at path.
bool fmbd_h5_exists(fmbd_h5 *f, const char *path);
/// @brief Write a dense array; intermediate groups are created. dims[rank], rank 0..4.
int fmbd_h5_write_f64(fmbd_h5 *f, const char *path, int rank, const int64_t *dims,
                      const double *data);
int fmbd_h5_write_i64(fmbd_h5 *f, const char *path, int rank, const int64_t *dims,
                      const int64_t *data);
/// @brief Read a dense array of any numeric type converted to double / int64. `rank` is the
/// expected rank; dims[k] >= 0 on entry requires that extent (FMBD_ERR_FORMAT otherwise),
/// -1 accepts any; on return dims holds the extents. Missing dataset: FMBD_ERR_FORMAT
/// "missing dataset". Non-finite values: FMBD_ERR_VALUE.
/// @param[out] data caller frees with fmbd_free
int fmbd_h5_read_f64(fmbd_h5 *f, const char *path, int rank, int64_t *dims, double **data);
int fmbd_h5_read_i64(fmbd_h5 *f, const char *path, int rank, int64_t *dims, int64_t **data);
/// @brief Write a COLUMN-major rows x cols matrix A (A[i + j*rows]) as a dataset of shape
/// (rows, cols), transposing a block of rows at a time (no full copy). See fmbd_dense.h.
int fmbd_h5_write_f64_cm(fmbd_h5 *f, const char *path, int64_t rows, int64_t cols, const double *A);
/// @brief Read a 2-D dataset of shape (rows, cols) into a COLUMN-major matrix. *rows, *cols
/// >= 0 on entry require that extent (FMBD_ERR_FORMAT otherwise), -1 accepts any; on return
/// they hold the shape. Non-finite values: FMBD_ERR_VALUE naming row and column.
/// @param[out] A caller frees with fmbd_free
int fmbd_h5_read_f64_cm(fmbd_h5 *f, const char *path, int64_t *rows, int64_t *cols, double **A);
/// @brief Copy the group or dataset at `path` of src (any handle) to the same path in dst (a
/// write handle), with everything below it (H5Ocopy); an existing object there is replaced,
/// missing parent groups are created. Missing in src: FMBD_ERR_FORMAT "missing object".
/// path must not be "/" (copy the root's members one by one, e.g. via fmbd_h5_list).
int fmbd_h5_copy(fmbd_h5 *src, const char *path, fmbd_h5 *dst);
/// @brief Remove the object at path (write handles); a missing path is fine.
int fmbd_h5_delete(fmbd_h5 *f, const char *path);
/// @brief Write a CSR group at path (replacing an existing one).
int fmbd_h5_write_csr(fmbd_h5 *f, const char *path, const fmbd_csr *A);
/// @brief The same, A having the pattern of the CSR group already written at `like` (checked:
/// equal shape, indptr and indices, else FMBD_ERR_INTERNAL): only `data` is written, and
/// `indices` and `indptr` are hard links to like's datasets (one object in the file; readers
/// that know nothing of it see ordinary datasets; docs/FORMAT.md).
int fmbd_h5_write_csr_like(fmbd_h5 *f, const char *path, const fmbd_csr *A, const char *like);
/// @brief Read and validate (fmbd_csr_check) a CSR group. @param[out] out caller destroys
int fmbd_h5_read_csr(fmbd_h5 *f, const char *path, fmbd_csr **out);
/// @brief The same, with B the CSR group already read from `like` (may be NULL): where path's
/// `indices` and `indptr` are the very datasets of like's (hard links, fmbd_h5_write_csr_like)
/// they are not read again but copied from B, or with `share` are B's arrays themselves (the
/// same pointers, as fmbd_fe_assemble's M shares K's: free them once, as fmbd_fe_body_destroy
/// does). Otherwise as fmbd_h5_read_csr.
int fmbd_h5_read_csr_like(fmbd_h5 *f, const char *path, const fmbd_csr *B, const char *like,
                          bool share, fmbd_csr **out);
/// @brief Read rows r0 .. r1-1 of a CSR group (HDF5 hyperslabs: the indptr slice, then the
/// indices and data slices it points to), so a process of a distributed program holds only its
/// row block (docs/SCALE.md). *out is (r1 - r0) x ncols with indptr from 0 and the column
/// indices of the whole matrix; validated as fmbd_h5_read_csr validates (fmbd_csr_check).
/// *nrows_all gets the whole matrix's rows (may be NULL). 0 <= r0 <= r1 <= rows, else
/// FMBD_ERR_VALUE. @param[out] out caller destroys
int fmbd_h5_read_csr_rows(fmbd_h5 *f, const char *path, int64_t r0, int64_t r1, int64_t *nrows_all,
                          fmbd_csr **out);
/// @brief Names of the members of a group, sorted. @param[out] names caller frees each and
/// the array with fmbd_free. A missing group gives n = 0 and FMBD_OK.
int fmbd_h5_list(fmbd_h5 *f, const char *group, int *n, char ***names);
/// @brief Create the group (and parents) if missing.
int fmbd_h5_make_group(fmbd_h5 *f, const char *path);

// --- attributes (obj is a path; "/" for the root) -----------------------------------------
// Writers create obj as a group when it does not exist, and replace an existing attribute.
// Strings are variable-length UTF-8 (h5py: str). One number (n == 1) is a scalar attribute
// (h5py: a number), n > 1 a 1-D array. Attributes live in the object header: keep them small
// (under 64 KiB; arrays belong in datasets).
int fmbd_h5_write_attr_str(fmbd_h5 *f, const char *obj, const char *name, const char *value);
int fmbd_h5_write_attr_f64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                           const double *values);
int fmbd_h5_write_attr_i64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                           const int64_t *values);
/// @brief Read a string attribute (fixed or variable length). @param[out] value caller frees
int fmbd_h5_read_attr_str(fmbd_h5 *f, const char *obj, const char *name, char **value);
/// @brief Read exactly n numbers (FMBD_ERR_FORMAT if the attribute has another size).
int fmbd_h5_read_attr_f64(fmbd_h5 *f, const char *obj, const char *name, int64_t n, double *values);
int fmbd_h5_read_attr_i64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                          int64_t *values);
/// @brief A 1-D attribute of n variable-length UTF-8 strings (h5py: an array of str).
int fmbd_h5_write_attr_strv(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                            const char *const *values);
/// @brief Read a string attribute of any shape (fixed or variable length) as a flat list.
/// @param[out] values caller frees each and the array with fmbd_free
int fmbd_h5_read_attr_strv(fmbd_h5 *f, const char *obj, const char *name, int64_t *n,
                           char ***values);
/// @brief The root attribute `inputs` of a file: n (name, SHA-256 hex) pairs.
/// FMBD_ERR_FORMAT if missing. @param[out] names, sha256 caller frees each and the arrays
int fmbd_h5_read_inputs(fmbd_h5 *f, int *n, char ***names, char ***sha256);
/// @brief Whether attribute `name` exists on obj.
bool fmbd_h5_has_attr(fmbd_h5 *f, const char *obj, const char *name);

// --- time series: extendible along the first dimension, flushed as they grow ---------------
typedef struct fmbd_h5_series fmbd_h5_series;
/// @brief Create an extendible f64 dataset of rows of `ncols` values (ncols == 0: a 1-D
/// series of scalars). @param[out] out caller closes with fmbd_h5_series_close
int fmbd_h5_series_create(fmbd_h5 *f, const char *path, int64_t ncols, fmbd_h5_series **out);
/// @brief Append nrows rows (row-major). Nothing reaches the disk's metadata before the next
/// fmbd_h5_flush (a file with series holds its metadata in memory between flushes), so a file
/// killed at any moment shows its series as of the last flush: flush after appending to every
/// series of a row block, not between them.
int fmbd_h5_series_append(fmbd_h5_series *s, int64_t nrows, const double *rows);
/// @brief Whether a growing file is due for a flush (0.5 s of wall time since the last one).
bool fmbd_h5_flush_due(const fmbd_h5 *f);
/// @brief Rows written so far.
int64_t fmbd_h5_series_rows(const fmbd_h5_series *s);
void fmbd_h5_series_close(fmbd_h5_series **s);

/// @brief The toolchain version and the command line that fmbd_h5_create writes into the root
/// attributes `creator` (with the program name of fmbd_log_init) and `command_line` (both
/// borrowed: they must outlive the files; until set, the compiled-in version and ""). The
/// command-line layer (fmbd_cli_init) calls it, so that this layer does not depend on that one.
void fmbd_h5_set_provenance(const char *version, const char *command_line);

/// @brief For a signal handler (async-signal-safe): remove the ".part" of the output being
/// written, if any (created by fmbd_h5_create and neither committed, closed nor abandoned), so
/// that an interrupted program leaves nothing half-written. fmbd_cli_init installs the handler.
void fmbd_h5_signal_cleanup(void);

#endif
