// common/fmbd_err.h: error codes, the error record, and the propagation macros
// SPDX-License-Identifier: MIT
//
// Every fallible fmbd_* function returns int: 0 (FMBD_OK) or a negative code from
// FMBD_ERROR_LIST. The code's details (message, source location, and the context the
// caller set: file name and HDF5 path or scene line) are kept in one error record that
// only main() reads, through fmbd_err_get() / fmbd_cli_finish().
#ifndef FMBD_ERR_H
#define FMBD_ERR_H

#include <stdarg.h>

// X(name, value, message, exit_status)  exit_status: 1 = data, 2 = usage
#define FMBD_ERROR_LIST(X)                                      \
  X(FMBD_OK, 0, "success", 0)                                   \
  X(FMBD_ERR_NOMEM, -1, "out of memory", 1)                     \
  X(FMBD_ERR_IO, -2, "input/output error", 1)                   \
  X(FMBD_ERR_FORMAT, -3, "bad or foreign file", 1)              \
  X(FMBD_ERR_VERSION, -4, "unsupported format version", 1)      \
  X(FMBD_ERR_VALUE, -5, "invalid value", 1)                     \
  X(FMBD_ERR_USAGE, -6, "usage error", 2)                       \
  X(FMBD_ERR_SINGULAR, -7, "singular matrix", 1)                \
  X(FMBD_ERR_CONVERGE, -8, "no convergence", 1)                 \
  X(FMBD_ERR_EXTERNAL, -9, "failure in an external library", 1) \
  X(FMBD_ERR_INTERNAL, -10, "internal error", 1)                \
  X(FMBD_ERR_SCENE, -11, "bad scene", 1)

enum fmbd_error_code {
#define FMBD_ERR_ENUM_(name, value, msg, ex) name = value,
  FMBD_ERROR_LIST(FMBD_ERR_ENUM_)
#undef FMBD_ERR_ENUM_
};

/// The error record. Filled by fmbd_err_set (through FMBD_FAIL and friends).
typedef struct fmbd_err {
  int code;          ///< one of FMBD_ERROR_LIST
  char msg[1024];    ///< the detail message
  char file[512];    ///< data file at fault ("" if none)
  char where[512];   ///< HDF5 path, dataset, or "line L, column C" of a scene ("" if none)
  const char *src;   ///< __FILE__ of the failure
  int line;          ///< __LINE__ of the failure
  const char *func;  ///< __func__ of the failure
} fmbd_err;

/// @brief The message of an error code (never NULL).
const char *fmbd_err_string(int code);
/// @brief Exit status for an error code: 0 for FMBD_OK, 2 for usage errors, else 1.
int fmbd_err_exit_status(int code);

/// @brief Record an error. Keeps the file/where context set before (fmbd_err_context).
/// @return code, so that `return fmbd_err_set(...)` works.
int fmbd_err_set(int code, const char *src, int line, const char *func, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));

/// @brief Set the data context of the next errors: file name and location (HDF5 path, scene
/// line). Either may be NULL to leave it unchanged; "" clears it. Setting context does not
/// raise an error. A failing function may also set it just before FMBD_FAIL.
void fmbd_err_context(const char *file, const char *where);
/// @brief Same as fmbd_err_context with a printf-formatted `where`.
void fmbd_err_contextf(const char *file, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
/// @brief Forget the last error and its context.
void fmbd_err_clear(void);
/// @brief The current error record (borrowed; valid until the next fmbd_err_* call).
const fmbd_err *fmbd_err_get(void);
/// @brief Format the record as "FILE:WHERE: message" into buf (no program name).
void fmbd_err_format(char *buf, int size);

// --- propagation macros -----------------------------------------------------------------
// Direct-return family, for functions that hold no resources.
#define FMBD_FAIL(code, ...) return fmbd_err_set((code), __FILE__, __LINE__, __func__, __VA_ARGS__)
#define FMBD_CHECK(cond, code, ...)            \
  do {                                         \
    if (!(cond)) FMBD_FAIL(code, __VA_ARGS__); \
  } while (0)
#define FMBD_CALL(expr)                 \
  do {                                  \
    int fmbd_rc_ = (expr);              \
    if (fmbd_rc_ != 0) return fmbd_rc_; \
  } while (0)

// goto-done family, for functions with one `done:` cleanup label and an `int rc` variable.
#define FMBD_GFAIL(code, ...)                                             \
  do {                                                                    \
    rc = fmbd_err_set((code), __FILE__, __LINE__, __func__, __VA_ARGS__); \
    goto done;                                                            \
  } while (0)
#define FMBD_GCHECK(cond, code, ...)            \
  do {                                          \
    if (!(cond)) FMBD_GFAIL(code, __VA_ARGS__); \
  } while (0)
#define FMBD_GCALL(expr)    \
  do {                      \
    rc = (expr);            \
    if (rc != 0) goto done; \
  } while (0)
/// Allocation check in the goto-done family: `FMBD_GALLOC(p = fmbd_malloc(n));`
#define FMBD_GALLOC(assign)                                     \
  do {                                                          \
    if (!(assign)) FMBD_GFAIL(FMBD_ERR_NOMEM, "out of memory"); \
  } while (0)

// Internal invariants: gone under NDEBUG (PetscAssert). Input checks use FMBD_CHECK.
#ifdef NDEBUG
#define FMBD_ASSERT(cond) ((void)0)
#else
#define FMBD_ASSERT(cond)                                                     \
  do {                                                                        \
    if (!(cond)) FMBD_FAIL(FMBD_ERR_INTERNAL, "assertion failed: %s", #cond); \
  } while (0)
#endif

#endif
