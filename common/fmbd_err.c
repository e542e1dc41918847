// common/fmbd_err.c: the error record
// SPDX-License-Identifier: MIT
#include "fmbd_err.h"

#include <stdio.h>
#include <string.h>

static fmbd_err g_err;

const char *fmbd_err_string(int code) {
  switch (code) {
#define FMBD_ERR_STR_(name, value, msg, ex) \
  case value:                               \
    return msg;
    FMBD_ERROR_LIST(FMBD_ERR_STR_)
#undef FMBD_ERR_STR_
  }
  return "unknown error";
}

int fmbd_err_exit_status(int code) {
  switch (code) {
#define FMBD_ERR_EX_(name, value, msg, ex) \
  case value:                              \
    return ex;
    FMBD_ERROR_LIST(FMBD_ERR_EX_)
#undef FMBD_ERR_EX_
  }
  return 1;
}

int fmbd_err_set(int code, const char *src, int line, const char *func, const char *fmt, ...) {
  g_err.code = code;
  g_err.src = src;
  g_err.line = line;
  g_err.func = func;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(g_err.msg, sizeof g_err.msg, fmt, ap);
  va_end(ap);
  return code;
}

void fmbd_err_context(const char *file, const char *where) {
  if (file) snprintf(g_err.file, sizeof g_err.file, "%s", file);
  if (where) snprintf(g_err.where, sizeof g_err.where, "%s", where);
}

void fmbd_err_contextf(const char *file, const char *fmt, ...) {
  if (file) snprintf(g_err.file, sizeof g_err.file, "%s", file);
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(g_err.where, sizeof g_err.where, fmt, ap);
  va_end(ap);
}

void fmbd_err_clear(void) { memset(&g_err, 0, sizeof g_err); }

const fmbd_err *fmbd_err_get(void) { return &g_err; }

void fmbd_err_format(char *buf, int size) {
  const char *msg = g_err.msg[0] ? g_err.msg : fmbd_err_string(g_err.code);
  if (g_err.file[0] && g_err.where[0]) {
    snprintf(buf, (size_t)size, "%s:%s: %s", g_err.file, g_err.where, msg);
  } else if (g_err.file[0]) {
    snprintf(buf, (size_t)size, "%s: %s", g_err.file, msg);
  } else if (g_err.where[0]) {
    snprintf(buf, (size_t)size, "%s: %s", g_err.where, msg);
  } else {
    snprintf(buf, (size_t)size, "%s", msg);
  }
}
