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
  // format into a copy first: the arguments may point into the record itself (a caller
  // wrapping the previous message), and vsnprintf onto its own source is undefined
  char msg[sizeof g_err.msg];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  memcpy(g_err.msg, msg, sizeof msg);
  return code;
}

void fmbd_err_context(const char *file, const char *where) {
  char buf[sizeof g_err.file];  // same size as where; the source may be the record itself
  if (file) {
    snprintf(buf, sizeof buf, "%s", file);
    memcpy(g_err.file, buf, sizeof buf);
  }
  if (where) {
    snprintf(buf, sizeof buf, "%s", where);
    memcpy(g_err.where, buf, sizeof buf);
  }
}

void fmbd_err_contextf(const char *file, const char *fmt, ...) {
  char buf[sizeof g_err.where];
  if (file) {
    snprintf(buf, sizeof buf, "%s", file);
    memcpy(g_err.file, buf, sizeof buf);
  }
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  memcpy(g_err.where, buf, sizeof buf);
}

void fmbd_err_clear(void) {
  memset(&g_err, 0, sizeof g_err);
}

const fmbd_err *fmbd_err_get(void) {
  return &g_err;
}

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
