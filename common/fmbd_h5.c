// common/fmbd_h5.c: HDF5 files of the toolchain: reading, atomic writing, stdin/stdout images
// SPDX-License-Identifier: MIT
//
// Reading: a named file is hashed (SHA-256, streamed) and opened with the default (sec2)
// driver; "-" reads standard input into memory and opens it with the core driver from a file
// image (H5Pset_file_image). Writing: "<name>.part" created with the sec2 driver, renamed at
// commit; "-" is built in memory (core driver, no backing store) and its image
// (H5Fget_file_image) written to standard output at commit. Files use HDF5's default
// (earliest) object formats: with H5F_LIBVER_V18 the version-2 superblock of an image from
// H5Fget_file_image has a wrong checksum in HDF5 1.10.8 (found by tests/cli/h5pipe.sh).
#include "fmbd_h5.h"

#include <errno.h>
#include <hdf5.h>
#include <libdeflate.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_sha256.h"

// which array of a CSR group is being written (its own filters: create_dataset)
typedef enum csr_array { CSR_NONE, CSR_INDEX, CSR_VALUES } csr_array;

struct fmbd_h5 {
  hid_t fid;
  char *name;        ///< as given ("-" for stdin/stdout)
  char *part;        ///< "<name>.part" while writing to a named file; NULL otherwise
  bool writing;      ///< created by fmbd_h5_create
  bool to_stdout;    ///< writing an in-memory image for standard output, or (to_device) for
                     ///< a named output that is not a regular file
  bool to_device;    ///< the image goes to `name` (/dev/null, a FIFO): opened, written, no rename
  char sha[65];      ///< SHA-256 of the bytes read (read handles), "" otherwise
  bool unhashed;     ///< fmbd_h5_open_unhashed: sha computed by fmbd_h5_sha256_now
  struct stat st;    ///< the file as opened (unhashed handles)
  int ninputs, cap;  ///< the `inputs` attribute, written at commit
  char **input_name, **input_sha;
  double last_flush_s;  ///< wall clock of the last flush (fmbd_h5_flush_due)
  bool metadata_held;   ///< metadata evictions off: the disk changes only at flushes (series)
  bool inputs_checked;  ///< the recorded inputs were compared with the files at hand
  csr_array csr;        ///< set by the CSR writers around each array's write
};

struct fmbd_h5_series {
  fmbd_h5 *f;
  hid_t dset;
  char *path;
  int64_t ncols, nrows;
};

// --- HDF5 error capture ---------------------------------------------------------------------
static int g_debug = -1;  // -1: not set yet (first use turns printing off)

void fmbd_h5_debug(bool on) {
  g_debug = on;
  if (on) {
    H5Eset_auto2(H5E_DEFAULT, (H5E_auto2_t)H5Eprint2, stderr);
  } else {
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
  }
}

static void lazy_init(void) {
  if (g_debug < 0) fmbd_h5_debug(false);
}

static herr_t walk_cb(unsigned n, const H5E_error2_t *e, void *data) {
  (void)n;
  char *buf = data;
  if (e->desc && *e->desc) snprintf(buf, 256, "%s", e->desc);  // keep the deepest
  return 0;
}

// Record an error whose message ends with the deepest description on HDF5's error stack.
static int h5_fail(int code, const char *src, int line, const char *func, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
static int h5_fail(int code, const char *src, int line, const char *func, const char *fmt, ...) {
  char msg[700], detail[256] = "";
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk_cb, detail);
  if (detail[0]) return fmbd_err_set(code, src, line, func, "%s (HDF5: %s)", msg, detail);
  return fmbd_err_set(code, src, line, func, "%s", msg);
}

// goto-done wrapper of an HDF5 call: a negative hid_t/herr_t/htri_t is a failure
#define FMBD_H5(expr, code, ...)                                       \
  do {                                                                 \
    if ((expr) < 0) {                                                  \
      rc = h5_fail((code), __FILE__, __LINE__, __func__, __VA_ARGS__); \
      goto done;                                                       \
    }                                                                  \
  } while (0)

// The name used in error messages: "<stdin>" / "<stdout>" for "-".
static const char *disp(const fmbd_h5 *f) {
  if (!f) return "";
  if (!strcmp(f->name, "-")) return f->writing ? "<stdout>" : "<stdin>";
  return f->name;
}

// Set the error context (file, path) of a failure; called at `done:` when rc != 0.
static void ctx(const fmbd_h5 *f, const char *path) {
  fmbd_err_context(disp(f), path ? path : "");
}

static void close_id(hid_t *id, herr_t (*fn)(hid_t)) {
  if (*id >= 0) fn(*id);
  *id = -1;
}

// --- paths --------------------------------------------------------------------------------
bool fmbd_h5_exists(fmbd_h5 *f, const char *path) {
  if (!f || !path) return false;
  size_t n = strlen(path);
  while (n > 1 && path[n - 1] == '/') n--;  // "/mesh/" is "/mesh"
  if (n == 0) return false;
  char buf[1024];
  if (n >= sizeof buf) return false;
  memcpy(buf, path, n);
  buf[n] = '\0';
  // check each prefix: H5Lexists fails when an intermediate link is missing
  for (size_t i = 1; i <= n; i++) {
    if (buf[i] != '/' && buf[i] != '\0') continue;
    if (i == 1 && buf[0] == '/') {
      if (n == 1) return true;  // the root
      continue;
    }
    char c = buf[i];
    buf[i] = '\0';
    htri_t e = H5Lexists(f->fid, buf, H5P_DEFAULT);
    buf[i] = c;
    if (e <= 0) return false;
  }
  return H5Oexists_by_name(f->fid, buf, H5P_DEFAULT) > 0;
}

static bool is_group(fmbd_h5 *f, const char *path) {
  H5O_info_t info;
  if (H5Oget_info_by_name(f->fid, path, &info, H5P_DEFAULT) < 0) return false;
  return info.type == H5O_TYPE_GROUP;
}

static hid_t lcpl_intermediate(void) {
  hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  if (lcpl >= 0) {
    H5Pset_create_intermediate_group(lcpl, 1);
    H5Pset_char_encoding(lcpl, H5T_CSET_UTF8);
  }
  return lcpl;
}

int fmbd_h5_make_group(fmbd_h5 *f, const char *path) {
  int rc = FMBD_OK;
  hid_t lcpl = -1, g = -1;
  if (!strcmp(path, "/") || !*path) return FMBD_OK;
  if (fmbd_h5_exists(f, path)) {
    if (!is_group(f, path)) FMBD_GFAIL(FMBD_ERR_FORMAT, "exists and is not a group");
    goto done;
  }
  FMBD_H5(lcpl = lcpl_intermediate(), FMBD_ERR_EXTERNAL, "cannot make a link property list");
  FMBD_H5(g = H5Gcreate2(f->fid, path, lcpl, H5P_DEFAULT, H5P_DEFAULT), FMBD_ERR_IO,
          "cannot create group");
done:
  close_id(&g, H5Gclose);
  close_id(&lcpl, H5Pclose);
  if (rc) ctx(f, path);
  return rc;
}

// Remove an existing link at path (to overwrite a dataset).
static int unlink_existing(fmbd_h5 *f, const char *path) {
  int rc = FMBD_OK;
  if (fmbd_h5_exists(f, path)) {
    FMBD_H5(H5Ldelete(f->fid, path, H5P_DEFAULT), FMBD_ERR_IO,
            "cannot replace the existing object");
  }
done:
  return rc;
}

// --- opening for reading --------------------------------------------------------------------
// Read all of standard input into memory (out: caller frees with fmbd_free).
static int slurp_stdin(unsigned char **out, size_t *size) {
  int rc = FMBD_OK;
  size_t cap = 1 << 20, n = 0;
  unsigned char *buf = fmbd_malloc(cap);
  FMBD_GALLOC(buf);
  for (;;) {
    if (n == cap) {
      unsigned char *nb = fmbd_realloc(buf, cap * 2);
      FMBD_GALLOC(nb);
      buf = nb;
      cap *= 2;
    }
    size_t got = fread(buf + n, 1, cap - n, stdin);
    n += got;
    if (got == 0) {
      if (ferror(stdin)) FMBD_GFAIL(FMBD_ERR_IO, "read error: %s", strerror(errno));
      break;
    }
  }
  *out = buf;
  *size = n;
  buf = NULL;
done:
  fmbd_free(buf);
  return rc;
}

static int h5_alloc(const char *name, bool writing, fmbd_h5 **out) {
  fmbd_h5 *f = fmbd_calloc(1, sizeof *f);
  if (!f) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  f->fid = -1;
  f->writing = writing;
  f->name = fmbd_strdup(name);
  if (!f->name) {
    fmbd_free(f);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  *out = f;
  return FMBD_OK;
}

static void h5_free(fmbd_h5 *f) {
  if (!f) return;
  for (int i = 0; i < f->ninputs; i++) {
    fmbd_free(f->input_name[i]);
    fmbd_free(f->input_sha[i]);
  }
  fmbd_free(f->input_name);
  fmbd_free(f->input_sha);
  fmbd_free(f->part);
  fmbd_free(f->name);
  fmbd_free(f);
}

// SHA-256 of an input file, remembered for the process: a file is hashed once however often it
// is opened or named as an input (cbcheck hashed the fe file twice: when opened, and as the
// cb file's recorded input; fe2cb when it records the fe file it read). Keyed by device, inode,
// size, modification and change times, looked at before and after the hash: a file written
// meanwhile is hashed again. Only inputs (read, never written by this process) go through here.
// A file rewritten by another process during this one's run in place, with the same size, within
// one tick of the file system's clock, would keep its first hash: the check never covered that
// case anyway (the hash and the read of a file are not one atomic step).
typedef struct sha_memo {
  dev_t dev;
  ino_t ino;
  off_t size;
  struct timespec mt, ct;
  char hex[65];
} sha_memo;
static sha_memo g_memo[8];
static int g_nmemo;
static bool memo_same(const sha_memo *a, const struct stat *st) {
  return a->dev == st->st_dev && a->ino == st->st_ino && a->size == st->st_size &&
         a->mt.tv_sec == st->st_mtim.tv_sec && a->mt.tv_nsec == st->st_mtim.tv_nsec &&
         a->ct.tv_sec == st->st_ctim.tv_sec && a->ct.tv_nsec == st->st_ctim.tv_nsec;
}
static int input_sha256(const char *path, char hex[65]) {
  struct stat st0, st1;
  bool have = stat(path, &st0) == 0 && S_ISREG(st0.st_mode);
  for (int i = 0; have && i < g_nmemo; i++) {
    if (memo_same(&g_memo[i], &st0)) {
      memcpy(hex, g_memo[i].hex, 65);
      return FMBD_OK;
    }
  }
  FMBD_CALL(fmbd_sha256_file(path, hex));
  if (!have) return FMBD_OK;
  sha_memo e = {.dev = st0.st_dev,
                .ino = st0.st_ino,
                .size = st0.st_size,
                .mt = st0.st_mtim,
                .ct = st0.st_ctim};
  if (stat(path, &st1) == 0 && memo_same(&e, &st1)) {  // not written while it was hashed
    memcpy(e.hex, hex, 65);
    g_memo[g_nmemo < 8 ? g_nmemo++ : (int)(st0.st_ino % 8)] = e;
  }
  return FMBD_OK;
}

static int open_read(const char *name, bool hash, fmbd_h5 **out) {
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  hid_t fapl = -1;
  unsigned char *image = NULL;
  size_t size = 0;
  *out = NULL;
  lazy_init();
  FMBD_GCALL(h5_alloc(name, false, &f));
  if (!strcmp(name, "-")) {
    FMBD_GCHECK(!isatty(STDIN_FILENO), FMBD_ERR_IO,
                "standard input is a terminal; pipe an HDF5 file into it or name the file");
    FMBD_GCALL(slurp_stdin(&image, &size));
    FMBD_GCHECK(size > 0, FMBD_ERR_FORMAT, "empty input, not an HDF5 file");
    fmbd_sha256_hex(image, size, f->sha);
    FMBD_H5(fapl = H5Pcreate(H5P_FILE_ACCESS), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
    FMBD_H5(H5Pset_fapl_core(fapl, 1 << 20, 0), FMBD_ERR_EXTERNAL, "H5Pset_fapl_core failed");
    FMBD_H5(H5Pset_file_image(fapl, image, size), FMBD_ERR_NOMEM, "cannot hand the image to HDF5");
    fmbd_free(image);  // HDF5 keeps its own copy
    image = NULL;
    FMBD_H5(f->fid = H5Fopen("fmbd-stdin-image", H5F_ACC_RDONLY, fapl), FMBD_ERR_FORMAT,
            "not an HDF5 file, or truncated");
  } else {
    struct stat st;
    if (stat(name, &st) != 0) FMBD_GFAIL(FMBD_ERR_IO, "cannot open: %s", strerror(errno));
    FMBD_GCHECK(!S_ISDIR(st.st_mode), FMBD_ERR_IO, "cannot open: is a directory");
    if (hash || !S_ISREG(st.st_mode)) {  // a FIFO or device cannot be read twice: hashed now
      FMBD_GCALL(input_sha256(name, f->sha));
    } else {
      f->unhashed = true;
      f->st = st;
    }
    FMBD_H5(f->fid = H5Fopen(name, H5F_ACC_RDONLY, H5P_DEFAULT), FMBD_ERR_FORMAT,
            "not an HDF5 file, or truncated");
  }
  *out = f;
  f = NULL;
done:
  close_id(&fapl, H5Pclose);
  fmbd_free(image);
  if (rc) {
    fmbd_err_context(!strcmp(name, "-") ? "<stdin>" : name, "");
    if (f) h5_free(f);
  }
  return rc;
}

int fmbd_h5_open(const char *name, fmbd_h5 **out) {
  return open_read(name, true, out);
}

int fmbd_h5_open_unhashed(const char *name, fmbd_h5 **out) {
  return open_read(name, false, out);
}

// The hash of a file opened unhashed: the file as opened (device, inode, size, both times),
// before and after it is hashed, so the bytes hashed are the bytes read (the memo's caveat:
// an in-place rewrite of the same size within one clock tick is not seen)
int fmbd_h5_sha256_now(fmbd_h5 *f, const char **sha) {
  int rc = FMBD_OK;
  if (f->unhashed) {
    sha_memo was = {.dev = f->st.st_dev,
                    .ino = f->st.st_ino,
                    .size = f->st.st_size,
                    .mt = f->st.st_mtim,
                    .ct = f->st.st_ctim};
    struct stat st;
    char hex[65];
    bool same = stat(f->name, &st) == 0 && memo_same(&was, &st);
    if (same) FMBD_GCALL(input_sha256(f->name, hex));
    same = same && stat(f->name, &st) == 0 && memo_same(&was, &st);
    FMBD_GCHECK(same, FMBD_ERR_IO, "changed since it was opened: not recorded as an input");
    memcpy(f->sha, hex, sizeof hex);
    f->unhashed = false;
  }
  *sha = f->sha;
done:
  if (rc) ctx(f, "");
  return rc;
}

static int parse_version(const char *s, int *major, int *minor) {
  char *end = NULL;
  errno = 0;
  long a = strtol(s, &end, 10);
  if (end == s || *end != '.' || a < 0 || errno) return -1;
  const char *p = end + 1;
  long b = strtol(p, &end, 10);
  if (end == p || *end != '\0' || b < 0 || errno) return -1;
  *major = (int)a;
  *minor = (int)b;
  return 0;
}

// The file an input recorded as `name` in the file `of` is now: the name joined to of's folder
// (the usual case: made in one folder), the name as given (relative to the current folder),
// then its last component beside `of`. Only regular files (never a device or a FIFO a hostile
// file could name). 0 and the path in buf when found.
static int find_input(const char *of, const char *name, char *buf, size_t size) {
  struct stat st;
  const char *slash = strrchr(of, '/');
  int dl = slash ? (int)(slash - of) : 0;
  const char *base = strrchr(name, '/') ? strrchr(name, '/') + 1 : name;
  char cand[3][4096];
  int nc = 0;
  if (name[0] != '/' && dl > 0) snprintf(cand[nc++], sizeof cand[0], "%.*s/%s", dl, of, name);
  snprintf(cand[nc++], sizeof cand[0], "%s", name);
  if (base != name || dl > 0)
    snprintf(cand[nc++], sizeof cand[0], "%.*s%s%s", dl, of, dl > 0 ? "/" : "", base);
  for (int i = 0; i < nc; i++) {
    if (stat(cand[i], &st) == 0 && S_ISREG(st.st_mode) && strlen(cand[i]) < size) {
      memcpy(buf, cand[i], strlen(cand[i]) + 1);
      return 0;
    }
  }
  return -1;
}

// Provenance (docs/FORMAT.md, "inputs"): every input recorded in f's `inputs` attribute that is
// at hand and whose SHA-256 differs now gets a warning: f was made from other bytes, and what
// it holds may not match that file any more (remake it). Missing inputs are not a fault (files
// travel alone); standard input cannot be checked. Once per handle; errors here are not
// errors of the read (a file without `inputs` is checked elsewhere, if at all).
static void warn_changed_inputs(fmbd_h5 *f) {
  int n = 0;
  char **names = NULL, **sha = NULL;
  if (f->inputs_checked || !strcmp(f->name, "-") || !fmbd_h5_has_attr(f, "/", "inputs")) return;
  f->inputs_checked = true;
  if (fmbd_h5_read_inputs(f, &n, &names, &sha) != FMBD_OK) {
    fmbd_err_clear();
    return;
  }
  for (int i = 0; i < n; i++) {
    char path[4096], now[65];
    if (!names[i][0] || !strcmp(names[i], "-") || names[i][0] == '<' || names[i][0] == '(')
      continue;  // standard input: "(stdin)" (older files "-", "<stdin>")
    if (find_input(f->name, names[i], path, sizeof path) != 0) {
      fmbd_log(FMBD_LOG_DEBUG, "%s: input %s is not at hand: not compared", f->name, names[i]);
      continue;
    }
    if (input_sha256(path, now) != FMBD_OK) {
      fmbd_err_clear();
      continue;
    }
    if (strcmp(now, sha[i]) != 0)
      fmbd_log(FMBD_LOG_WARN,
               "%s: its input %s changed since it was made (SHA-256 %.12s..., recorded "
               "%.12s...): remake %s",
               f->name, path, now, sha[i], f->name);
  }
  for (int i = 0; i < n; i++) {
    fmbd_free(names[i]);
    fmbd_free(sha[i]);
  }
  fmbd_free(names);
  fmbd_free(sha);
}

int fmbd_h5_check_format(fmbd_h5 *f, const char *format, int major) {
  int rc = FMBD_OK;
  char *fmt = NULL, *ver = NULL;
  if (!fmbd_h5_has_attr(f, "/", "format")) {
    FMBD_GFAIL(FMBD_ERR_FORMAT, "not a toolchain file (no 'format' attribute), expected %s",
               format);
  }
  FMBD_GCALL(fmbd_h5_read_attr_str(f, "/", "format", &fmt));
  FMBD_GCHECK(fmt[0], FMBD_ERR_FORMAT, "the 'format' attribute is empty, expected %s", format);
  if (strcmp(fmt, format) != 0)
    FMBD_GFAIL(FMBD_ERR_FORMAT, "is a %s file, expected %s", fmt, format);
  FMBD_GCHECK(fmbd_h5_has_attr(f, "/", "format_version"), FMBD_ERR_FORMAT,
              "no 'format_version' attribute");
  FMBD_GCALL(fmbd_h5_read_attr_str(f, "/", "format_version", &ver));
  int fmaj, fmin;
  FMBD_GCHECK(parse_version(ver, &fmaj, &fmin) == 0, FMBD_ERR_FORMAT,
              "format_version '%s' is not MAJOR.MINOR", ver);
  FMBD_GCHECK(fmaj <= major, FMBD_ERR_VERSION,
              "%s format version %s is newer than this program reads (%d.x)", format, ver, major);
  if (!f->writing) warn_changed_inputs(f);
done:
  fmbd_free(fmt);
  fmbd_free(ver);
  if (rc) ctx(f, "");  // "rod.cb.h5: is a fmbd-cb file, expected fmbd-fe"
  return rc;
}

const char *fmbd_h5_name(const fmbd_h5 *f) {
  return f->name;
}
const char *fmbd_h5_sha256(const fmbd_h5 *f) {
  return f->sha;
}

// --- the output being written, for a signal handler ------------------------------------------
// One slot: every program writes one output at a time. Set when a .part is created, cleared
// after the rename (commit), the removal (close) or the hand-over (abandon).
static char g_part[4096];
static volatile sig_atomic_t g_part_set = 0;

static void part_register(const char *part) {
  g_part_set = 0;
  if (part && strlen(part) < sizeof g_part) {
    memcpy(g_part, part, strlen(part) + 1);
    g_part_set = 1;
  }
}

static void part_forget(const char *part) {
  if (part && g_part_set && !strcmp(part, g_part)) g_part_set = 0;
}

void fmbd_h5_signal_cleanup(void) {
  if (g_part_set) unlink(g_part);  // async-signal-safe
}

void fmbd_h5_close(fmbd_h5 **pf) {
  if (!pf || !*pf) return;
  fmbd_h5 *f = *pf;
  if (f->fid >= 0) H5Fclose(f->fid);
  if (f->writing && f->part) unlink(f->part);  // an uncommitted output is discarded
  part_forget(f->part);
  h5_free(f);
  *pf = NULL;
}

void fmbd_h5_abandon(fmbd_h5 **pf) {
  if (!pf || !*pf) return;
  fmbd_h5 *f = *pf;
  if (f->fid >= 0) H5Fclose(f->fid);  // "<name>.part" stays; an image for stdout is dropped
  part_forget(f->part);
  h5_free(f);
  *pf = NULL;
}

// --- provenance of the files created (set by the program: fmbd_cli_init) ---------------------
#ifndef FMBD_VERSION
#define FMBD_VERSION "unknown"
#endif
static const char *g_version = FMBD_VERSION, *g_command_line = "";

void fmbd_h5_set_provenance(const char *version, const char *command_line) {
  g_version = version ? version : FMBD_VERSION;
  g_command_line = command_line ? command_line : "";
}

// --- creating -------------------------------------------------------------------------------
int fmbd_h5_create(const char *name, const char *format, const char *format_version,
                   fmbd_h5 **out) {
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  hid_t fapl = -1;
  *out = NULL;
  lazy_init();
  FMBD_GCALL(h5_alloc(name, true, &f));
  FMBD_H5(fapl = H5Pcreate(H5P_FILE_ACCESS), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  // closing the file closes objects left open (a series not closed by the caller)
  FMBD_H5(H5Pset_fclose_degree(fapl, H5F_CLOSE_STRONG), FMBD_ERR_EXTERNAL,
          "H5Pset_fclose_degree failed");
  // an existing output that is not a regular file (/dev/null, a FIFO, a terminal) is written
  // in place at commit, never replaced by a renamed .part (which would turn /dev/null into a
  // regular file for every other program)
  struct stat st;
  bool device = strcmp(name, "-") && stat(name, &st) == 0 && !S_ISREG(st.st_mode);
  FMBD_GCHECK(!(device && S_ISDIR(st.st_mode)), FMBD_ERR_IO, "cannot create %s: Is a directory",
              name);
  if (!strcmp(name, "-") || device) {
    f->to_stdout = true;
    f->to_device = device;
    FMBD_H5(H5Pset_fapl_core(fapl, 1 << 20, 0), FMBD_ERR_EXTERNAL, "H5Pset_fapl_core failed");
    FMBD_H5(f->fid = H5Fcreate("fmbd-stdout-image", H5F_ACC_TRUNC, H5P_DEFAULT, fapl), FMBD_ERR_IO,
            "cannot create the in-memory file");
  } else {
    size_t n = strlen(name);
    FMBD_GALLOC(f->part = fmbd_malloc(n + 6));
    memcpy(f->part, name, n);
    memcpy(f->part + n, ".part", 6);
    // create the file ourselves first, for an errno-based message (unwritable folder ...)
    FILE *fp = fopen(f->part, "wb");
    if (!fp) {
      int e = errno;
      fmbd_free(f->part);
      f->part = NULL;  // nothing to remove
      FMBD_GFAIL(FMBD_ERR_IO, "cannot create %s.part: %s", name, strerror(e));
    }
    fclose(fp);
    part_register(f->part);
    FMBD_H5(f->fid = H5Fcreate(f->part, H5F_ACC_TRUNC, H5P_DEFAULT, fapl), FMBD_ERR_IO,
            "cannot create %s", f->part);
  }
  f->last_flush_s = fmbd_wall_s();
  // --- root attributes known now; inputs and times follow at commit ---
  char creator[256];
  snprintf(creator, sizeof creator, "%s %s", fmbd_log_prog(), g_version);
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/", "format", format));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/", "format_version", format_version));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/", "creator", creator));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/", "command_line", g_command_line));
  *out = f;
  f = NULL;
done:
  close_id(&fapl, H5Pclose);
  if (rc) {
    fmbd_err_context(!strcmp(name, "-") ? "<stdout>" : name, "");
    fmbd_h5_close(&f);  // removes the .part
  }
  return rc;
}

int fmbd_h5_add_input(fmbd_h5 *f, const char *name, const char *sha256) {
  int rc = FMBD_OK;
  char hex[65];
  char *n = NULL, *s = NULL;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "add_input on a read handle");
  if (!sha256) {
    FMBD_GCHECK(strcmp(name, "-") != 0, FMBD_ERR_INTERNAL,
                "standard input cannot be hashed again; pass fmbd_h5_sha256() of its handle");
    FMBD_GCALL(input_sha256(name, hex));
    sha256 = hex;
  }
  if (f->ninputs == f->cap) {
    int cap = f->cap ? 2 * f->cap : 4;
    char **a = fmbd_realloc(f->input_name, (size_t)cap * sizeof *a);
    FMBD_GALLOC(a);
    f->input_name = a;
    char **b = fmbd_realloc(f->input_sha, (size_t)cap * sizeof *b);
    FMBD_GALLOC(b);
    f->input_sha = b;
    f->cap = cap;
  }
  FMBD_GALLOC(n = fmbd_strdup(name));
  FMBD_GALLOC(s = fmbd_strdup(sha256));
  f->input_name[f->ninputs] = n;
  f->input_sha[f->ninputs] = s;
  f->ninputs++;
  n = s = NULL;
done:
  fmbd_free(n);
  fmbd_free(s);
  if (rc && !fmbd_err_get()->file[0]) ctx(f, "/");
  return rc;
}

int fmbd_h5_flush(fmbd_h5 *f) {
  int rc = FMBD_OK;
  FMBD_H5(H5Fflush(f->fid, H5F_SCOPE_GLOBAL), FMBD_ERR_IO, "cannot flush");
  f->last_flush_s = fmbd_wall_s();
done:
  if (rc) ctx(f, "/");
  return rc;
}

// Write a string-valued 2-D (n, 2) attribute `inputs` (name, SHA-256 hex).
static int write_inputs(fmbd_h5 *f) {
  int rc = FMBD_OK;
  const char **v = NULL;
  hid_t t = -1, sp = -1, a = -1;
  size_t n = (size_t)f->ninputs;
  FMBD_GALLOC(v = fmbd_malloc((2 * n + 1) * sizeof *v));
  for (size_t i = 0; i < n; i++) {
    v[2 * i] = f->input_name[i];
    v[2 * i + 1] = f->input_sha[i];
  }
  hsize_t dims[2] = {n, 2};
  FMBD_H5(t = H5Tcopy(H5T_C_S1), FMBD_ERR_EXTERNAL, "H5Tcopy failed");
  FMBD_H5(H5Tset_size(t, H5T_VARIABLE), FMBD_ERR_EXTERNAL, "H5Tset_size failed");
  FMBD_H5(H5Tset_cset(t, H5T_CSET_UTF8), FMBD_ERR_EXTERNAL, "H5Tset_cset failed");
  FMBD_H5(sp = H5Screate_simple(2, dims, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  if (H5Aexists(f->fid, "inputs") > 0) H5Adelete(f->fid, "inputs");
  FMBD_H5(a = H5Acreate2(f->fid, "inputs", t, sp, H5P_DEFAULT, H5P_DEFAULT), FMBD_ERR_IO,
          "cannot create attribute 'inputs'");
  if (n) FMBD_H5(H5Awrite(a, t, v), FMBD_ERR_IO, "cannot write attribute 'inputs'");
done:
  close_id(&a, H5Aclose);
  close_id(&sp, H5Sclose);
  close_id(&t, H5Tclose);
  fmbd_free(v);
  return rc;
}

int fmbd_h5_commit(fmbd_h5 **pf, double wall_s, double cpu_s) {
  int rc = FMBD_OK;
  fmbd_h5 *f = *pf;
  void *image = NULL;
  FMBD_GCHECK(f && f->writing, FMBD_ERR_INTERNAL, "commit of a read handle");
  FMBD_GCALL(write_inputs(f));
  FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/", "wall_time_s", 1, &wall_s));
  FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/", "cpu_time_s", 1, &cpu_s));
  FMBD_H5(H5Fflush(f->fid, H5F_SCOPE_GLOBAL), FMBD_ERR_IO, "cannot write");
  if (f->to_stdout) {
    ssize_t size;
    FMBD_H5(size = H5Fget_file_image(f->fid, NULL, 0), FMBD_ERR_IO, "cannot get the file image");
    FMBD_GALLOC(image = fmbd_malloc((size_t)size));
    FMBD_H5(H5Fget_file_image(f->fid, image, (size_t)size), FMBD_ERR_IO,
            "cannot get the file image");
    herr_t e = H5Fclose(f->fid);
    f->fid = -1;
    FMBD_H5(e, FMBD_ERR_IO, "cannot close the in-memory file");
    if (f->to_device) {
      FILE *fp = fopen(f->name, "wb");
      FMBD_GCHECK(fp, FMBD_ERR_IO, "cannot open %s: %s", f->name, strerror(errno));
      size_t put = fwrite(image, 1, (size_t)size, fp);
      int bad = put != (size_t)size;
      bad |= fclose(fp) != 0;
      FMBD_GCHECK(!bad, FMBD_ERR_IO, "cannot write to %s: %s", f->name, strerror(errno));
    } else {
      size_t put = fwrite(image, 1, (size_t)size, stdout);
      int bad = put != (size_t)size || fflush(stdout) != 0;
      FMBD_GCHECK(!bad, FMBD_ERR_IO, "cannot write to standard output: %s", strerror(errno));
    }
  } else {
    herr_t e = H5Fclose(f->fid);
    f->fid = -1;
    FMBD_H5(e, FMBD_ERR_IO, "cannot close %s", f->part);
    if (rename(f->part, f->name) != 0) {
      FMBD_GFAIL(FMBD_ERR_IO, "cannot rename %s to %s: %s", f->part, f->name, strerror(errno));
    }
    part_forget(f->part);
    fmbd_free(f->part);
    f->part = NULL;  // committed: nothing to remove
  }
done:
  fmbd_free(image);
  if (rc) ctx(f, "");
  fmbd_h5_close(pf);  // on failure removes the .part
  return rc;
}

// --- datasets ------------------------------------------------------------------------------
#define CHUNK_MIN_ELEMS 8192  // smaller datasets are stored contiguous, uncompressed
// Compression policy (measured on this machine, 20 M values, CPU time of the write): int64
// index arrays compress many times over and cheaply (deflate 4: 1.0 s, against 0.57 s
// uncompressed); float data barely compresses and shuffle+deflate costs ~0.2 us a value
// (4.1 s at level 4, 4.0 s at level 1, 0.55 s uncompressed). So integers get level 4 always,
// floats level 1 up to FLOAT_DEFLATE_MAX values (32 MB, well under a second) and none beyond
// (chunked still), keeping 1 M-dof matrices and mode sets quick to write. FMBD_H5_DEFLATE=N
// (0..9) in the environment forces level N for every chunked dataset (0: no compression).
#define FLOAT_DEFLATE_MAX ((hsize_t)1 << 22)
// ... and only when they compress: the first values (TRIAL_ELEMS below) (shuffled, deflate 1, as
// HDF5 will) must shrink by FLOAT_DEFLATE_MIN_RATIO, else the dataset is stored uncompressed.
// A stiffness matrix's values compress 1.12:1 (the 51 k-dof rod of bench/cbcheck.sh): storing
// them plain costs 3.5 MB of a 37 MB fe file and saves their inflation at every read (cbcheck's
// fe file read 0.44-0.52 -> 0.31 s CPU); a consistent mass (5.5:1) stays compressed.
#define FLOAT_DEFLATE_MIN_RATIO 1.25

static int deflate_level(hid_t ftype, hsize_t nelem) {
  const char *env = getenv("FMBD_H5_DEFLATE");
  if (env && *env >= '0' && *env <= '9' && !env[1]) return *env - '0';
  if (H5Tget_class(ftype) == H5T_INTEGER) return 4;
  return nelem <= FLOAT_DEFLATE_MAX ? 1 : 0;
}
#define CHUNK_TARGET_ELEMS 131072  // 1 MiB of doubles: fits HDF5's default 1 MiB chunk cache

// The compression trials below read the first TRIAL_ELEMS values (128 KiB, four of deflate's
// 32 KiB windows): a whole chunk's 1 MiB took 20-25 ms a dataset, 0.1 s of fe2cb's 0.12 s
// write at 51 k dofs (five dense blocks, none of which compresses); the first 16,384 values
// gave ratios within 0.01-0.05 of the whole chunk's on the rod's cb blocks (1.03-1.14:1), K
// (1.11-1.14), M (5.6 and 8.1) and the node coordinates (1.12-1.19), on the same side of the
// thresholds below (bench/README.md "fe2cb's fixed costs")
#define TRIAL_ELEMS 16384

// The ratio by which deflate 1 shrinks the first TRIAL_ELEMS of the doubles x[0..n), shuffled
// first (as HDF5's shuffle filter does) or not; 0 when the trial itself cannot run. The trial
// deflates with libdeflate's level 1, 2.4x zlib's speed (0.82-0.88 against 1.98-2.22 ms on
// 128 KiB shuffled, 0.9-1.0 against 2.7-2.9 ms plain); HDF5 writes with zlib, whose ratios it
// matched within 0.01-0.03 on the 51 k rod's cb blocks, K's values and the node coordinates
// (1.03-1.19, all below 1.25 either way) and within 0.6 on M's (5.6-8.5, above 2 either way):
// the same filters (bench/README.md "fe2cb at 51 k: the read decompressed by us")
static double float_ratio(const double *x, hsize_t n, bool shuffle) {
  if (n > TRIAL_ELEMS) n = TRIAL_ELEMS;
  size_t nb = (size_t)n * sizeof(double);
  struct libdeflate_compressor *c = libdeflate_alloc_compressor(1);
  size_t zn = c ? libdeflate_zlib_compress_bound(c, nb) : 0;
  unsigned char *sh = shuffle ? fmbd_malloc(nb) : NULL, *z = c ? fmbd_malloc(zn) : NULL;
  double r = 0.0;
  if ((sh || !shuffle) && z) {
    const unsigned char *b = (const unsigned char *)x;
    if (shuffle) {
      for (size_t i = 0; i < (size_t)n; i++) {
        for (size_t k = 0; k < sizeof(double); k++)
          sh[k * (size_t)n + i] = b[i * sizeof(double) + k];
      }
    }
    size_t got = libdeflate_zlib_compress(c, shuffle ? sh : b, nb, z, zn);
    if (got > 0) r = (double)nb / (double)got;
  }
  if (c) libdeflate_free_compressor(c);
  fmbd_free(sh);
  fmbd_free(z);
  return r;
}

// Whether doubles like x[0..n) are worth HDF5's shuffle + deflate (FLOAT_DEFLATE_MIN_RATIO on
// the first TRIAL_ELEMS of them); true when the trial itself cannot run
static bool floats_compress(const double *x, hsize_t n) {
  double r = float_ratio(x, n, true);
  return r == 0.0 || r >= FLOAT_DEFLATE_MIN_RATIO;
}

// The arrays of a CSR group (fmbd_h5_write_csr*) have filters of their own, chosen for the
// reader: cbcheck's estimate run reads the fe file's K and M whole, and inflating them was most
// of that read (bench/README.md, cbcheck: "The fe file's CSR arrays"). Index arrays: shuffle +
// deflate 2 (51 k-dof rod, /K/indices of 3.9 M values: 1.26 MB, inflated in 0.030 s CPU, where
// deflate 4 gave 1.15 MB in 0.073 s). Values: deflate 1 without shuffle when that shrinks the
// first TRIAL_ELEMS values CSR_DEFLATE_MIN_RATIO times (a consistent mass: Ms (x) I3 repeats whole
// doubles, which LZ77 finds and shuffle hides: 8.4:1, inflated in 0.032 s, against 5.5:1 in 0.065 s
// shuffled), else shuffle + deflate 1 if that does, else none (a stiffness: 1.1-1.25:1, read
// plain in 0.004 s against 0.10 s inflated); beyond FLOAT_DEFLATE_MAX values none, as for any
// float dataset. FMBD_H5_DEFLATE still overrides all of it.
#define CSR_INDEX_LEVEL 2
#define CSR_DEFLATE_MIN_RATIO 2.0

// Chunk shape: trailing dimensions whole while the chunk stays under the target, the first
// that does not fit cut, leading dimensions 1. Every chunk extent is in [1, dim].
static void chunk_shape(int rank, const hsize_t *dims, hsize_t *chunk) {
  hsize_t prod = 1;
  int k = rank - 1;
  for (; k >= 0; k--) {
    hsize_t d = dims[k] ? dims[k] : 1;
    if (prod * d > CHUNK_TARGET_ELEMS) break;
    chunk[k] = d;
    prod *= d;
  }
  if (k >= 0) {
    hsize_t c = CHUNK_TARGET_ELEMS / prod;
    chunk[k] = c < 1 ? 1 : c;
    for (int j = k - 1; j >= 0; j--) chunk[j] = 1;
  }
}

// Create a dataset of the given file type (replacing any object at path). *rows_per_block
// gets the number of leading-dimension rows per chunk (all rows if contiguous).
static int create_dataset(fmbd_h5 *f, const char *path, hid_t ftype, int rank, const int64_t *dims,
                          const double *values, hid_t *out, hsize_t *rows_per_block) {
  int rc = FMBD_OK;
  hid_t sp = -1, dcpl = -1, lcpl = -1;
  hsize_t hd[4], chunk[4];
  hsize_t nelem = 1;
  *out = -1;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "write to a read handle");
  FMBD_GCHECK(rank >= 0 && rank <= 4, FMBD_ERR_INTERNAL, "rank %d not in 0..4", rank);
  for (int k = 0; k < rank; k++) {
    FMBD_GCHECK(dims[k] >= 0, FMBD_ERR_INTERNAL, "negative extent %lld", (long long)dims[k]);
    hd[k] = (hsize_t)dims[k];
    nelem *= hd[k];
  }
  FMBD_GCALL(unlink_existing(f, path));
  if (rank == 0) {
    FMBD_H5(sp = H5Screate(H5S_SCALAR), FMBD_ERR_EXTERNAL, "H5Screate failed");
  } else {
    FMBD_H5(sp = H5Screate_simple(rank, hd, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  }
  FMBD_H5(dcpl = H5Pcreate(H5P_DATASET_CREATE), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  *rows_per_block = rank ? hd[0] : 1;
  if (rank > 0 && nelem >= CHUNK_MIN_ELEMS) {
    chunk_shape(rank, hd, chunk);
    FMBD_H5(H5Pset_chunk(dcpl, rank, chunk), FMBD_ERR_EXTERNAL, "H5Pset_chunk failed");
    int level = deflate_level(ftype, nelem);
    bool shuffle = true;
    if (f->csr != CSR_NONE && !getenv("FMBD_H5_DEFLATE")) {  // a CSR group's array
      if (f->csr == CSR_INDEX) {
        level = CSR_INDEX_LEVEL;
      } else if (level > 0 && values) {
        shuffle = float_ratio(values, nelem, false) < CSR_DEFLATE_MIN_RATIO;
        if (shuffle && float_ratio(values, nelem, true) < CSR_DEFLATE_MIN_RATIO) level = 0;
      }
    } else if (level > 0 && values && !getenv("FMBD_H5_DEFLATE") &&
               !floats_compress(values, nelem)) {
      level = 0;  // values: the doubles to be written (when at hand), for the trial
    }
    if (level > 0) {
      if (shuffle) FMBD_H5(H5Pset_shuffle(dcpl), FMBD_ERR_EXTERNAL, "H5Pset_shuffle failed");
      FMBD_H5(H5Pset_deflate(dcpl, (unsigned)level), FMBD_ERR_EXTERNAL, "H5Pset_deflate failed");
    }
    *rows_per_block = chunk[0];
  }
  FMBD_H5(lcpl = lcpl_intermediate(), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  FMBD_H5(*out = H5Dcreate2(f->fid, path, ftype, sp, lcpl, dcpl, H5P_DEFAULT), FMBD_ERR_IO,
          "cannot create dataset");
done:
  close_id(&lcpl, H5Pclose);
  close_id(&dcpl, H5Pclose);
  close_id(&sp, H5Sclose);
  return rc;
}

static int write_dense(fmbd_h5 *f, const char *path, hid_t ftype, hid_t mtype, int rank,
                       const int64_t *dims, const void *data) {
  int rc = FMBD_OK;
  hid_t d = -1;
  hsize_t rows;
  const double *values =
      H5Tget_class(ftype) == H5T_FLOAT && mtype == H5T_NATIVE_DOUBLE ? data : NULL;
  FMBD_GCALL(create_dataset(f, path, ftype, rank, dims, values, &d, &rows));
  int64_t nelem = 1;
  for (int k = 0; k < rank; k++) nelem *= dims[k];
  if (nelem > 0)
    FMBD_H5(H5Dwrite(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), FMBD_ERR_IO,
            "cannot write dataset");
done:
  close_id(&d, H5Dclose);
  if (rc) ctx(f, path);
  return rc;
}

int fmbd_h5_write_f64(fmbd_h5 *f, const char *path, int rank, const int64_t *dims,
                      const double *data) {
  return write_dense(f, path, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, rank, dims, data);
}

int fmbd_h5_write_i64(fmbd_h5 *f, const char *path, int rank, const int64_t *dims,
                      const int64_t *data) {
  return write_dense(f, path, H5T_STD_I64LE, H5T_NATIVE_INT64, rank, dims, data);
}

// Open a numeric dataset and check its rank and extents against rank/dims (see header).
static int open_numeric(fmbd_h5 *f, const char *path, int rank, int64_t *dims, hid_t *out,
                        bool *is_float) {
  int rc = FMBD_OK;
  hid_t d = -1, sp = -1, t = -1;
  *out = -1;
  FMBD_GCHECK(fmbd_h5_exists(f, path), FMBD_ERR_FORMAT, "missing dataset");
  FMBD_H5(d = H5Dopen2(f->fid, path, H5P_DEFAULT), FMBD_ERR_FORMAT, "not a dataset");
  FMBD_H5(t = H5Dget_type(d), FMBD_ERR_FORMAT, "cannot read the type");
  H5T_class_t cls = H5Tget_class(t);
  FMBD_GCHECK(cls == H5T_INTEGER || cls == H5T_FLOAT, FMBD_ERR_FORMAT, "not a numeric dataset");
  *is_float = cls == H5T_FLOAT;
  FMBD_H5(sp = H5Dget_space(d), FMBD_ERR_FORMAT, "cannot read the shape");
  int r = H5Sget_simple_extent_ndims(sp);
  FMBD_GCHECK(r == rank, FMBD_ERR_FORMAT, "rank %d, expected %d", r, rank);
  hsize_t hd[H5S_MAX_RANK];
  H5Sget_simple_extent_dims(sp, hd, NULL);
  for (int k = 0; k < rank; k++) {
    if (dims[k] >= 0 && (hsize_t)dims[k] != hd[k]) {
      FMBD_GFAIL(FMBD_ERR_FORMAT, "extent %d is %llu, expected %lld", k, (unsigned long long)hd[k],
                 (long long)dims[k]);
    }
    dims[k] = (int64_t)hd[k];
  }
  // the element count must fit memory arithmetic (a corrupt header could claim anything)
  {
    uint64_t total = 1;
    for (int k = 0; k < rank; k++) {
      if (hd[k] && total > (uint64_t)(INT64_MAX / 16) / hd[k]) {
        FMBD_GFAIL(FMBD_ERR_FORMAT, "dataset too large (extent %d is %llu)", k,
                   (unsigned long long)hd[k]);
      }
      total *= hd[k];
    }
    // nor claim more than its bytes in the file can hold: a small corrupt file may declare a
    // dataset of 1e15 elements (chunks never written read as fill values). Deflate expands at
    // most ~1032:1, so 2048 x the storage (+ 1 MiB for small or compact datasets) bounds real
    // data; beyond it the header is corrupt, not the memory short
    hsize_t st = H5Dget_storage_size(d);
    if (total > ((uint64_t)st * 2048 + (1u << 20)) / 8) {
      FMBD_GFAIL(FMBD_ERR_FORMAT,
                 "the dataset claims %llu elements, but holds %llu bytes in the file (a corrupt "
                 "header?)",
                 (unsigned long long)total, (unsigned long long)st);
    }
  }
  *out = d;
  d = -1;
done:
  close_id(&t, H5Tclose);
  close_id(&sp, H5Sclose);
  close_id(&d, H5Dclose);
  return rc;
}

static int64_t count(int rank, const int64_t *dims) {
  int64_t n = 1;
  for (int k = 0; k < rank; k++) n *= dims[k];
  return n;
}

static int check_finite(const double *x, int64_t n) {
  for (int64_t i = 0; i < n; i++) {
    if (!isfinite(x[i])) {
      FMBD_FAIL(FMBD_ERR_VALUE, "%s at element %lld", isnan(x[i]) ? "NaN" : "Inf", (long long)i);
    }
  }
  return FMBD_OK;
}

static int read_chunks(hid_t d, hid_t mtype, int64_t n, void *buf);

int fmbd_h5_read_f64(fmbd_h5 *f, const char *path, int rank, int64_t *dims, double **data) {
  int rc = FMBD_OK;
  hid_t d = -1;
  double *x = NULL;
  bool fl;
  *data = NULL;
  FMBD_GCHECK(rank >= 0 && rank <= 4, FMBD_ERR_INTERNAL, "rank %d not in 0..4", rank);
  FMBD_GCALL(open_numeric(f, path, rank, dims, &d, &fl));
  int64_t n = count(rank, dims);
  FMBD_GALLOC(x = fmbd_malloc((size_t)(n ? n : 1) * sizeof *x));
  if (n && !read_chunks(d, H5T_NATIVE_DOUBLE, n, x))
    FMBD_H5(H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, x), FMBD_ERR_FORMAT,
            "cannot read dataset");
  FMBD_GCALL(check_finite(x, n));
  *data = x;
  x = NULL;
done:
  close_id(&d, H5Dclose);
  fmbd_free(x);
  if (rc) ctx(f, path);
  return rc;
}

int fmbd_h5_read_i64(fmbd_h5 *f, const char *path, int rank, int64_t *dims, int64_t **data) {
  int rc = FMBD_OK;
  hid_t d = -1;
  int64_t *x = NULL;
  double *tmp = NULL;
  bool fl;
  *data = NULL;
  FMBD_GCHECK(rank >= 0 && rank <= 4, FMBD_ERR_INTERNAL, "rank %d not in 0..4", rank);
  FMBD_GCALL(open_numeric(f, path, rank, dims, &d, &fl));
  int64_t n = count(rank, dims);
  FMBD_GALLOC(x = fmbd_malloc((size_t)(n ? n : 1) * sizeof *x));
  if (n && !fl) {
    if (!read_chunks(d, H5T_NATIVE_INT64, n, x))
      FMBD_H5(H5Dread(d, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, x), FMBD_ERR_FORMAT,
              "cannot read dataset");
  } else if (n) {  // floating point holding integers (written by another tool): exact only
    FMBD_GALLOC(tmp = fmbd_malloc((size_t)n * sizeof *tmp));
    FMBD_H5(H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, tmp), FMBD_ERR_FORMAT,
            "cannot read dataset");
    for (int64_t i = 0; i < n; i++) {
      FMBD_GCHECK(tmp[i] == floor(tmp[i]) && fabs(tmp[i]) <= 9007199254740992.0, FMBD_ERR_FORMAT,
                  "element %lld = %g is not an integer", (long long)i, tmp[i]);
      x[i] = (int64_t)tmp[i];
    }
  }
  *data = x;
  x = NULL;
done:
  close_id(&d, H5Dclose);
  fmbd_free(x);
  fmbd_free(tmp);
  if (rc) ctx(f, path);
  return rc;
}

// Transposing writer/reader of column-major matrices, a block of rows at a time so that no
// full row-major copy is made.
int fmbd_h5_write_f64_cm(fmbd_h5 *f, const char *path, int64_t rows, int64_t cols,
                         const double *A) {
  int rc = FMBD_OK;
  hid_t d = -1, fsp = -1, msp = -1;
  double *buf = NULL;
  hsize_t block;
  int64_t dims[2] = {rows, cols};
  // A for the compression trial (its first values: the leading columns, the same kind of data)
  FMBD_GCALL(create_dataset(f, path, H5T_IEEE_F64LE, 2, dims, A, &d, &block));
  if (rows == 0 || cols == 0) goto done;
  if ((int64_t)block * cols < 65536) block = (hsize_t)((65536 + cols - 1) / cols);
  if ((int64_t)block > rows) block = (hsize_t)rows;
  FMBD_GALLOC(buf = fmbd_malloc((size_t)block * (size_t)cols * sizeof *buf));
  FMBD_H5(fsp = H5Dget_space(d), FMBD_ERR_EXTERNAL, "H5Dget_space failed");
  for (int64_t r0 = 0; r0 < rows; r0 += (int64_t)block) {
    int64_t nr = rows - r0 < (int64_t)block ? rows - r0 : (int64_t)block;
    for (int64_t i = 0; i < nr; i++) {
      for (int64_t j = 0; j < cols; j++) buf[i * cols + j] = A[(r0 + i) + j * rows];
    }
    hsize_t start[2] = {(hsize_t)r0, 0}, cnt[2] = {(hsize_t)nr, (hsize_t)cols};
    FMBD_H5(H5Sselect_hyperslab(fsp, H5S_SELECT_SET, start, NULL, cnt, NULL), FMBD_ERR_EXTERNAL,
            "H5Sselect_hyperslab failed");
    FMBD_H5(msp = H5Screate_simple(2, cnt, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
    FMBD_H5(H5Dwrite(d, H5T_NATIVE_DOUBLE, msp, fsp, H5P_DEFAULT, buf), FMBD_ERR_IO,
            "cannot write dataset");
    close_id(&msp, H5Sclose);
  }
done:
  close_id(&msp, H5Sclose);
  close_id(&fsp, H5Sclose);
  close_id(&d, H5Dclose);
  fmbd_free(buf);
  if (rc) ctx(f, path);
  return rc;
}

int fmbd_h5_read_f64_cm(fmbd_h5 *f, const char *path, int64_t *rows, int64_t *cols, double **A) {
  int rc = FMBD_OK;
  hid_t d = -1, fsp = -1, msp = -1;
  double *buf = NULL, *x = NULL;
  int64_t dims[2] = {*rows, *cols};
  bool fl;
  *A = NULL;
  FMBD_GCALL(open_numeric(f, path, 2, dims, &d, &fl));
  int64_t m = dims[0], n = dims[1];
  int64_t mn = m * n;
  FMBD_GALLOC(x = fmbd_malloc((size_t)(mn > 0 ? mn : 1) * sizeof *x));
  if (m && n) {
    int64_t block = (65536 + n - 1) / n;
    if (block > m) block = m;
    FMBD_GALLOC(buf = fmbd_malloc((size_t)block * (size_t)n * sizeof *buf));
    FMBD_H5(fsp = H5Dget_space(d), FMBD_ERR_EXTERNAL, "H5Dget_space failed");
    for (int64_t r0 = 0; r0 < m; r0 += block) {
      int64_t nr = m - r0 < block ? m - r0 : block;
      hsize_t start[2] = {(hsize_t)r0, 0}, cnt[2] = {(hsize_t)nr, (hsize_t)n};
      FMBD_H5(H5Sselect_hyperslab(fsp, H5S_SELECT_SET, start, NULL, cnt, NULL), FMBD_ERR_EXTERNAL,
              "H5Sselect_hyperslab failed");
      FMBD_H5(msp = H5Screate_simple(2, cnt, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
      FMBD_H5(H5Dread(d, H5T_NATIVE_DOUBLE, msp, fsp, H5P_DEFAULT, buf), FMBD_ERR_FORMAT,
              "cannot read dataset");
      close_id(&msp, H5Sclose);
      for (int64_t i = 0; i < nr; i++) {
        for (int64_t j = 0; j < n; j++) {
          double v = buf[i * n + j];
          if (!isfinite(v)) {
            FMBD_GFAIL(FMBD_ERR_VALUE, "%s at row %lld, column %lld", isnan(v) ? "NaN" : "Inf",
                       (long long)(r0 + i), (long long)j);
          }
          x[(r0 + i) + j * m] = v;
        }
      }
    }
  }
  *rows = m;
  *cols = n;
  *A = x;
  x = NULL;
done:
  close_id(&msp, H5Sclose);
  close_id(&fsp, H5Sclose);
  close_id(&d, H5Dclose);
  fmbd_free(buf);
  fmbd_free(x);
  if (rc) ctx(f, path);
  return rc;
}

// --- CSR groups ------------------------------------------------------------------------------
static int join(char *buf, size_t n, const char *group, const char *member) {
  size_t g = strlen(group);
  int k = snprintf(buf, n, "%s%s%s", group, g && group[g - 1] == '/' ? "" : "/", member);
  if (k < 0 || (size_t)k >= n) FMBD_FAIL(FMBD_ERR_INTERNAL, "path too long");
  return FMBD_OK;
}

int fmbd_h5_write_csr(fmbd_h5 *f, const char *path, const fmbd_csr *A) {
  int rc = FMBD_OK;
  char p[1100];
  int64_t nnz = fmbd_csr_nnz(A), np1 = A->nrows + 1, shape[2] = {A->nrows, A->ncols};
  // files hold symmetric matrices in full (docs/FORMAT.md), never fmbd_csr_keep_lower's form
  FMBD_GCHECK(!A->lower, FMBD_ERR_INTERNAL, "lower-triangle storage written as a CSR group");
  FMBD_GCALL(unlink_existing(f, path));
  FMBD_GCALL(fmbd_h5_make_group(f, path));
  FMBD_GCALL(join(p, sizeof p, path, "data"));
  f->csr = CSR_VALUES;
  FMBD_GCALL(fmbd_h5_write_f64(f, p, 1, &nnz, A->data));
  FMBD_GCALL(join(p, sizeof p, path, "indices"));
  f->csr = CSR_INDEX;
  FMBD_GCALL(fmbd_h5_write_i64(f, p, 1, &nnz, A->indices));
  FMBD_GCALL(join(p, sizeof p, path, "indptr"));
  FMBD_GCALL(fmbd_h5_write_i64(f, p, 1, &np1, A->indptr));
  f->csr = CSR_NONE;
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "encoding-type", "csr_matrix"));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "encoding-version", "0.1.0"));
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, path, "shape", 2, shape));
done:
  f->csr = CSR_NONE;
  if (rc) ctx(f, path);
  return rc;
}

int fmbd_h5_write_csr_like(fmbd_h5 *f, const char *path, const fmbd_csr *A, const char *like) {
  int rc = FMBD_OK;
  char p[1100], q[1100];
  int64_t nnz = fmbd_csr_nnz(A), shape[2] = {A->nrows, A->ncols}, ls[2] = {-1, -1};
  hid_t lcpl = -1;
  FMBD_GCHECK(!A->lower, FMBD_ERR_INTERNAL, "lower-triangle storage written as a CSR group");
  // the caller compared A's pattern with the one written at `like`; the shape guards misuse
  FMBD_GCALL(fmbd_h5_read_attr_i64(f, like, "shape", 2, ls));
  FMBD_GCHECK(ls[0] == shape[0] && ls[1] == shape[1], FMBD_ERR_INTERNAL,
              "write_csr_like: shape differs from %s's", like);
  FMBD_GCALL(unlink_existing(f, path));
  FMBD_GCALL(fmbd_h5_make_group(f, path));
  FMBD_GCALL(join(p, sizeof p, path, "data"));
  f->csr = CSR_VALUES;
  FMBD_GCALL(fmbd_h5_write_f64(f, p, 1, &nnz, A->data));
  f->csr = CSR_NONE;
  FMBD_H5(lcpl = H5Pcreate(H5P_LINK_CREATE), FMBD_ERR_IO, "cannot create a link property list");
  H5Pset_char_encoding(lcpl, H5T_CSET_UTF8);
  const char *member[2] = {"indices", "indptr"};
  for (int k = 0; k < 2; k++) {
    FMBD_GCALL(join(p, sizeof p, path, member[k]));
    FMBD_GCALL(join(q, sizeof q, like, member[k]));
    FMBD_H5(H5Lcreate_hard(f->fid, q, f->fid, p, lcpl, H5P_DEFAULT), FMBD_ERR_IO,
            "cannot link %s to %s", p, q);
  }
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "encoding-type", "csr_matrix"));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "encoding-version", "0.1.0"));
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, path, "shape", 2, shape));
done:
  f->csr = CSR_NONE;
  close_id(&lcpl, H5Pclose);
  if (rc) ctx(f, path);
  return rc;
}

// --- whole chunks of a deflated dataset, decompressed by us ---------------------------------
// HDF5's filter pipeline inflates each chunk into a buffer of its own, unshuffles it into a
// second, and copies the result into the caller's array; zlib checks each chunk's Adler-32 a
// byte at a time. Here each chunk's stored bytes (H5Dread_chunk) are decompressed by
// libdeflate (its inflate and Adler-32 check vectorised) straight into the caller's array, or,
// when shuffled, into one scratch chunk unshuffled into the array. Only the layouts the
// toolchain writes take this path (chunks of whole rows, every chunk allocated, the file type
// the memory type, filters deflate or shuffle + deflate); anything else, and any chunk that does
// not decompress to exactly its size, goes to H5Dread, whose messages stay those of bad files.

// the 8-byte elements of a shuffled chunk of c elements (byte b of element i at b c + i) back in
// order: 16 elements at a time by an SSE2 byte transpose (bytes, then pairs, then quads of the
// eight planes interleaved), the rest a byte at a time (HDF5's own loop took 20 ms for the 51 k
// rod's /K/indices, this 4 ms)
static void unshuffle8(const unsigned char *in, size_t c, unsigned char *out) {
  size_t i = 0;
#ifdef __SSE2__
  for (; i + 16 <= c; i += 16) {
    __m128i a[8], b[8], q[8];
    for (int k = 0; k < 8; k++) a[k] = _mm_loadu_si128((const __m128i *)(in + (size_t)k * c + i));
    for (int k = 0; k < 4; k++) {  // bytes 2k, 2k+1 of elements i..i+7 (lo), i+8..i+15 (hi)
      b[2 * k] = _mm_unpacklo_epi8(a[2 * k], a[2 * k + 1]);
      b[2 * k + 1] = _mm_unpackhi_epi8(a[2 * k], a[2 * k + 1]);
    }
    for (int h = 0; h < 2; h++) {  // bytes 0-3 (q[0..3]) and 4-7 (q[4..7]) of four elements each
      for (int k = 0; k < 2; k++) {
        q[4 * h + 2 * k] = _mm_unpacklo_epi16(b[4 * h + k], b[4 * h + k + 2]);
        q[4 * h + 2 * k + 1] = _mm_unpackhi_epi16(b[4 * h + k], b[4 * h + k + 2]);
      }
    }
    // q[0]: elements 0-3, q[1]: 4-7, q[2]: 8-11, q[3]: 12-15 (bytes 0-3), q[4..7] their bytes 4-7
    for (int k = 0; k < 4; k++) {
      _mm_storeu_si128((__m128i *)(out + 8 * i + 32 * k), _mm_unpacklo_epi32(q[k], q[k + 4]));
      _mm_storeu_si128((__m128i *)(out + 8 * i + 32 * k + 16), _mm_unpackhi_epi32(q[k], q[k + 4]));
    }
  }
#endif
  for (; i < c; i++) {
    for (int b = 0; b < 8; b++) out[8 * i + (size_t)b] = in[(size_t)b * c + i];
  }
}

// 1: buf holds the n elements; 0: not this path's layout or a chunk refused (the caller reads
// with H5Dread); mtype an 8-byte native type (the chunk cache is not used)
static int read_chunks(hid_t d, hid_t mtype, int64_t n, void *buf) {
  int ok = 0;
  hid_t dcpl = -1, t = -1, sp = -1;
  unsigned char *raw = NULL, *scratch = NULL, *seen = NULL;
  size_t raw_cap = 0;
  struct libdeflate_decompressor *dz = NULL;
  hsize_t dims[H5S_MAX_RANK], cdims[H5S_MAX_RANK], c = 0, w = 1, nch = 0;
  bool shuffle = false;
  int deflate_at = -1, shuffle_at = -1, rank;
  if (n <= 0 || (dcpl = H5Dget_create_plist(d)) < 0 || (sp = H5Dget_space(d)) < 0) goto out;
  rank = H5Sget_simple_extent_ndims(sp);
  if (rank < 1 || H5Sget_simple_extent_dims(sp, dims, NULL) != rank) goto out;
  if (H5Pget_layout(dcpl) != H5D_CHUNKED || H5Pget_chunk(dcpl, rank, cdims) != rank) goto out;
  // chunks of whole rows (every trailing extent whole): each one block of the array
  for (int k = 1; k < rank; k++) {
    if (cdims[k] != dims[k]) goto out;
    w *= dims[k];
  }
  if (cdims[0] == 0 || cdims[0] > dims[0] || dims[0] * w != (hsize_t)n) goto out;
  c = cdims[0] * w;
  if ((t = H5Dget_type(d)) < 0 || H5Tequal(t, mtype) <= 0 || H5Tget_size(t) != 8) goto out;
  int nf = H5Pget_nfilters(dcpl);
  if (nf < 1 || nf > 2) goto out;
  for (int k = 0; k < nf; k++) {
    unsigned flags, cd[4];
    size_t ncd = 4;
    H5Z_filter_t id = H5Pget_filter2(dcpl, (unsigned)k, &flags, &ncd, cd, 0, NULL, NULL);
    if (id == H5Z_FILTER_DEFLATE && deflate_at < 0) {
      deflate_at = k;
    } else if (id == H5Z_FILTER_SHUFFLE && k == 0 && ncd >= 1 && cd[0] == 8) {
      shuffle_at = k;
    } else {
      goto out;
    }
  }
  if (deflate_at < 0) goto out;
  // (HDF5 1.10.8 takes no H5S_ALL here: the dataset's own space)
  if (H5Dget_num_chunks(d, sp, &nch) < 0 || nch != (dims[0] + cdims[0] - 1) / cdims[0]) goto out;
  // each chunk once: a corrupt index naming one offset twice would leave another unread
  if (!(seen = fmbd_calloc((size_t)nch, 1)) || !(dz = libdeflate_alloc_decompressor())) goto out;
  const size_t cb = (size_t)c * 8;
  for (hsize_t k = 0; k < nch; k++) {
    hsize_t offv[H5S_MAX_RANK];
    unsigned mask;
    haddr_t addr;
    hsize_t size;
    if (H5Dget_chunk_info(d, sp, k, offv, &mask, &addr, &size) < 0) goto out;
    for (int j = 1; j < rank; j++) {
      if (offv[j]) goto out;
    }
    hsize_t row = offv[0], off = row * w;  // the chunk's first row and element
    if (row % cdims[0] || row >= dims[0] || size == 0 || seen[row / cdims[0]]) goto out;
    seen[row / cdims[0]] = 1;
    if (size > raw_cap) {
      fmbd_free(raw);
      raw_cap = (size_t)size;
      if (!(raw = fmbd_malloc(raw_cap))) goto out;
    }
    uint32_t fm = 0;
    if (H5Dread_chunk(d, H5P_DEFAULT, offv, &fm, raw) < 0) goto out;
    shuffle = shuffle_at >= 0 && !(fm & (1u << shuffle_at));
    bool inflate = !(fm & (1u << deflate_at));
    bool whole = off + c <= (hsize_t)n;
    unsigned char *dst = (unsigned char *)buf + off * 8;
    unsigned char *to = dst;  // where the chunk's bytes go first
    if (shuffle || !whole) {
      if (!scratch && !(scratch = fmbd_malloc(cb))) goto out;
      to = scratch;
    }
    if (inflate) {
      size_t got = 0;
      if (libdeflate_zlib_decompress(dz, raw, (size_t)size, to, cb, &got) != LIBDEFLATE_SUCCESS ||
          got != cb)
        goto out;
    } else {
      if (size != cb) goto out;
      memcpy(to, raw, cb);
    }
    size_t m = whole ? (size_t)c : (size_t)((hsize_t)n - off);
    if (shuffle) {
      if (whole) {
        unshuffle8(scratch, (size_t)c, dst);
      } else {  // the edge chunk: unshuffled whole, its first m elements kept
        unsigned char *tmp = fmbd_malloc(cb);
        if (!tmp) goto out;
        unshuffle8(scratch, (size_t)c, tmp);
        memcpy(dst, tmp, m * 8);
        fmbd_free(tmp);
      }
    } else if (!whole) {
      memcpy(dst, scratch, m * 8);
    }
  }
  ok = 1;
out:
  if (dz) libdeflate_free_decompressor(dz);
  fmbd_free(raw);
  fmbd_free(scratch);
  fmbd_free(seen);
  if (sp >= 0) H5Sclose(sp);
  if (t >= 0) H5Tclose(t);
  if (dcpl >= 0) H5Pclose(dcpl);
  return ok;
}

// Read a 1-D integer or float dataset of exactly n elements into buf (type mtype).
// The whole dataset is read once: opened again without a chunk cache, HDF5 reads its unfiltered
// chunks straight into buf (through the cache, each 1 MiB chunk of a CSR array's values was
// read into the cache and copied; the 51 k rod's /K/data: 32 MB copied for nothing).
static int read_exact(fmbd_h5 *f, const char *path, hid_t mtype, int64_t n, void *buf) {
  int rc = FMBD_OK;
  hid_t d = -1, dapl = -1;
  int64_t dims[1] = {n};
  bool fl;
  FMBD_GCALL(open_numeric(f, path, 1, dims, &d, &fl));
  FMBD_GCHECK(!(fl && mtype == H5T_NATIVE_INT64), FMBD_ERR_FORMAT,
              "floating-point dataset where integers are expected");
  FMBD_H5(dapl = H5Pcreate(H5P_DATASET_ACCESS), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  FMBD_H5(H5Pset_chunk_cache(dapl, 0, 0, 1.0), FMBD_ERR_EXTERNAL, "H5Pset_chunk_cache failed");
  close_id(&d, H5Dclose);
  FMBD_H5(d = H5Dopen2(f->fid, path, dapl), FMBD_ERR_FORMAT, "not a dataset");
  if (n && !read_chunks(d, mtype, n, buf))
    FMBD_H5(H5Dread(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf), FMBD_ERR_FORMAT,
            "cannot read dataset");
done:
  close_id(&dapl, H5Pclose);
  close_id(&d, H5Dclose);
  return rc;
}

// the two paths name one object of the file (hard links to it)
static bool same_object(fmbd_h5 *f, const char *a, const char *b) {
  H5O_info_t ia, ib;
  if (H5Oget_info_by_name(f->fid, a, &ia, H5P_DEFAULT) < 0 ||
      H5Oget_info_by_name(f->fid, b, &ib, H5P_DEFAULT) < 0)
    return false;
  return ia.fileno == ib.fileno && ia.addr == ib.addr;
}

int fmbd_h5_read_csr(fmbd_h5 *f, const char *path, fmbd_csr **out) {
  return fmbd_h5_read_csr_like(f, path, NULL, NULL, false, out);
}

int fmbd_h5_read_csr_like(fmbd_h5 *f, const char *path, const fmbd_csr *B, const char *like,
                          bool share, fmbd_csr **out) {
  int rc = FMBD_OK;
  char p[1100];
  char *enc = NULL;
  fmbd_csr *A = NULL;
  int64_t shape[2], nnz = -1;
  hid_t d = -1;
  const char *at = path;  // where an error is: the group, or the member dataset being read
  bool shared = false;    // A's indptr and indices are B's arrays (share)
  *out = NULL;
  FMBD_GCHECK(fmbd_h5_exists(f, path), FMBD_ERR_FORMAT, "missing sparse matrix");
  FMBD_GCHECK(is_group(f, path), FMBD_ERR_FORMAT, "not a CSR group");
  if (fmbd_h5_has_attr(f, path, "encoding-type")) {
    FMBD_GCALL(fmbd_h5_read_attr_str(f, path, "encoding-type", &enc));
    FMBD_GCHECK(!strcmp(enc, "csr_matrix"), FMBD_ERR_FORMAT,
                "encoding-type is '%s', expected csr_matrix", enc);
  }
  FMBD_GCALL(fmbd_h5_read_attr_i64(f, path, "shape", 2, shape));
  FMBD_GCHECK(shape[0] >= 0 && shape[1] >= 0 && shape[0] < INT64_MAX / 16, FMBD_ERR_FORMAT,
              "bad shape (%lld, %lld)", (long long)shape[0], (long long)shape[1]);
  // nnz from the data dataset, checked against indptr afterwards; the shape against the
  // length of indptr and nnz against the shape before anything of that size is allocated (a
  // corrupt shape is a format defect, not "out of memory")
  {
    bool fl;
    int64_t dims[1] = {-1}, ip[1] = {-1};
    FMBD_GCALL(join(p, sizeof p, path, "data"));
    at = p;
    FMBD_GCALL(open_numeric(f, p, 1, dims, &d, &fl));
    at = path;
    close_id(&d, H5Dclose);
    nnz = dims[0];
    FMBD_GCALL(join(p, sizeof p, path, "indptr"));
    at = p;
    FMBD_GCALL(open_numeric(f, p, 1, ip, &d, &fl));
    at = path;
    close_id(&d, H5Dclose);
    FMBD_GCHECK(ip[0] == shape[0] + 1, FMBD_ERR_FORMAT,
                "shape (%lld, %lld) does not match indptr, which has %lld entries (%lld rows)",
                (long long)shape[0], (long long)shape[1], (long long)ip[0], (long long)(ip[0] - 1));
    FMBD_GCHECK(shape[1] == 0 ? nnz == 0 : nnz / shape[1] <= shape[0], FMBD_ERR_FORMAT,
                "data has %lld entries, more than a (%lld, %lld) matrix holds", (long long)nnz,
                (long long)shape[0], (long long)shape[1]);
  }
  bool same = B && like && !B->lower && B->nrows == shape[0] && B->ncols == shape[1] &&
              fmbd_csr_nnz(B) == nnz;
  if (same) {
    char q[1100];
    const char *member[2] = {"indices", "indptr"};
    for (int k = 0; k < 2 && same; k++) {
      FMBD_GCALL(join(p, sizeof p, path, member[k]));
      FMBD_GCALL(join(q, sizeof q, like, member[k]));
      same = same_object(f, p, q);
    }
  }
  if (same && share) {  // B's arrays themselves: one pattern in memory
    // only the values allocated: an index block allocated and freed here (32 MB at 51 k dofs,
    // mmapped) would raise glibc's mmap threshold to its size, and the later arrays of that
    // size (fe2cb's parked Ks and Ms) would come from the heap and stay resident when freed:
    // fe2cb's LL' peak 241 -> 271 MB (bench/README.md "fe2cb's fixed costs")
    FMBD_GALLOC(A = fmbd_calloc(1, sizeof *A));
    A->nrows = shape[0];
    A->ncols = shape[1];
    A->indptr = B->indptr;
    A->indices = B->indices;
    shared = true;
    FMBD_GALLOC(A->data = fmbd_malloc((size_t)(nnz ? nnz : 1) * sizeof(double)));
  } else if (same) {
    FMBD_GCALL(fmbd_csr_create(shape[0], shape[1], nnz, &A));
    memcpy(A->indptr, B->indptr, (size_t)(shape[0] + 1) * sizeof(int64_t));
    memcpy(A->indices, B->indices, (size_t)nnz * sizeof(int64_t));
  } else {
    FMBD_GCALL(fmbd_csr_create(shape[0], shape[1], nnz, &A));
    FMBD_GCALL(join(p, sizeof p, path, "indptr"));
    at = p;
    FMBD_GCALL(read_exact(f, p, H5T_NATIVE_INT64, shape[0] + 1, A->indptr));
    at = path;
    FMBD_GCHECK(A->indptr[shape[0]] == nnz, FMBD_ERR_FORMAT,
                "indptr ends at %lld but data has %lld entries", (long long)A->indptr[shape[0]],
                (long long)nnz);
    FMBD_GCALL(join(p, sizeof p, path, "indices"));
    at = p;
    FMBD_GCALL(read_exact(f, p, H5T_NATIVE_INT64, nnz, A->indices));
    at = path;
  }
  FMBD_GCALL(join(p, sizeof p, path, "data"));
  at = p;
  FMBD_GCALL(read_exact(f, p, H5T_NATIVE_DOUBLE, nnz, A->data));
  at = path;
  // a shared pattern is B's, checked when B was made (51 k dofs: M checked whole 3.5 ms, its
  // values alone 1.6 ms)
  FMBD_GCALL(shared ? fmbd_csr_check_values(A) : fmbd_csr_check(A));
  *out = A;
  A = NULL;
done:
  close_id(&d, H5Dclose);
  fmbd_free(enc);
  if (A && shared) A->indptr = A->indices = NULL;  // B's
  fmbd_csr_destroy(&A);
  if (rc) ctx(f, at);
  return rc;
}

// count entries from start of a 1-D dataset (any length >= start + count) into buf
static int read_slab(fmbd_h5 *f, const char *path, hid_t mtype, int64_t start, int64_t count,
                     void *buf) {
  int rc = FMBD_OK;
  hid_t d = -1, fsp = -1, msp = -1;
  int64_t dims[1] = {-1};
  bool fl;
  FMBD_GCALL(open_numeric(f, path, 1, dims, &d, &fl));
  FMBD_GCHECK(!(fl && mtype == H5T_NATIVE_INT64), FMBD_ERR_FORMAT,
              "floating-point dataset where integers are expected");
  FMBD_GCHECK(start >= 0 && count >= 0 && start + count <= dims[0], FMBD_ERR_FORMAT,
              "entries %lld .. %lld asked for, the dataset has %lld", (long long)start,
              (long long)(start + count - 1), (long long)dims[0]);
  if (count > 0) {
    hsize_t st[1] = {(hsize_t)start}, cnt[1] = {(hsize_t)count};
    FMBD_H5(fsp = H5Dget_space(d), FMBD_ERR_EXTERNAL, "H5Dget_space failed");
    FMBD_H5(H5Sselect_hyperslab(fsp, H5S_SELECT_SET, st, NULL, cnt, NULL), FMBD_ERR_EXTERNAL,
            "H5Sselect_hyperslab failed");
    FMBD_H5(msp = H5Screate_simple(1, cnt, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
    FMBD_H5(H5Dread(d, mtype, msp, fsp, H5P_DEFAULT, buf), FMBD_ERR_FORMAT, "cannot read dataset");
  }
done:
  close_id(&msp, H5Sclose);
  close_id(&fsp, H5Sclose);
  close_id(&d, H5Dclose);
  return rc;
}

int fmbd_h5_read_csr_rows(fmbd_h5 *f, const char *path, int64_t r0, int64_t r1, int64_t *nrows_all,
                          fmbd_csr **out) {
  int rc = FMBD_OK;
  char p[1100];
  fmbd_csr *A = NULL;
  int64_t shape[2], *ip = NULL;
  const char *at = path;
  *out = NULL;
  FMBD_GCHECK(fmbd_h5_exists(f, path), FMBD_ERR_FORMAT, "missing sparse matrix");
  FMBD_GCHECK(is_group(f, path), FMBD_ERR_FORMAT, "not a CSR group");
  FMBD_GCALL(fmbd_h5_read_attr_i64(f, path, "shape", 2, shape));
  FMBD_GCHECK(shape[0] >= 0 && shape[1] >= 0 && shape[0] < INT64_MAX / 16, FMBD_ERR_FORMAT,
              "bad shape (%lld, %lld)", (long long)shape[0], (long long)shape[1]);
  FMBD_GCHECK(0 <= r0 && r0 <= r1 && r1 <= shape[0], FMBD_ERR_VALUE,
              "rows %lld .. %lld asked for, the matrix has %lld", (long long)r0,
              (long long)(r1 - 1), (long long)shape[0]);
  int64_t nr = r1 - r0;
  FMBD_GALLOC(ip = fmbd_malloc((size_t)(nr + 1) * sizeof *ip));
  FMBD_GCALL(join(p, sizeof p, path, "indptr"));
  at = p;
  FMBD_GCALL(read_slab(f, p, H5T_NATIVE_INT64, r0, nr + 1, ip));
  int64_t base = ip[0], nnz = ip[nr] - ip[0];
  FMBD_GCHECK(base >= 0 && nnz >= 0 && (shape[1] == 0 ? nnz == 0 : nnz / shape[1] <= nr),
              FMBD_ERR_FORMAT, "indptr[%lld] = %lld, indptr[%lld] = %lld: not a row block",
              (long long)r0, (long long)ip[0], (long long)r1, (long long)ip[nr]);
  FMBD_GCALL(fmbd_csr_create(nr, shape[1], nnz, &A));
  for (int64_t i = 0; i <= nr; i++) A->indptr[i] = ip[i] - base;
  FMBD_GCALL(join(p, sizeof p, path, "indices"));
  FMBD_GCALL(read_slab(f, p, H5T_NATIVE_INT64, base, nnz, A->indices));
  FMBD_GCALL(join(p, sizeof p, path, "data"));
  FMBD_GCALL(read_slab(f, p, H5T_NATIVE_DOUBLE, base, nnz, A->data));
  at = path;
  FMBD_GCALL(fmbd_csr_check(A));
  if (nrows_all) *nrows_all = shape[0];
  *out = A;
  A = NULL;
done:
  fmbd_free(ip);
  fmbd_csr_destroy(&A);
  if (rc) ctx(f, at);
  return rc;
}

// --- listing ---------------------------------------------------------------------------------
typedef struct list_ctx {
  int n, cap;
  char **names;
  int rc;
} list_ctx;

static herr_t list_cb(hid_t g, const char *name, const H5L_info_t *info, void *data) {
  (void)g;
  (void)info;
  list_ctx *c = data;
  if (c->n == c->cap) {
    int cap = c->cap ? 2 * c->cap : 16;
    char **a = fmbd_realloc(c->names, (size_t)cap * sizeof *a);
    if (!a) {
      c->rc = FMBD_ERR_NOMEM;
      return -1;
    }
    c->names = a;
    c->cap = cap;
  }
  c->names[c->n] = fmbd_strdup(name);
  if (!c->names[c->n]) {
    c->rc = FMBD_ERR_NOMEM;
    return -1;
  }
  c->n++;
  return 0;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

int fmbd_h5_list(fmbd_h5 *f, const char *group, int *n, char ***names) {
  int rc = FMBD_OK;
  list_ctx c = {0, 0, NULL, 0};
  hid_t g = -1;
  *n = 0;
  *names = NULL;
  if (!fmbd_h5_exists(f, group)) return FMBD_OK;
  FMBD_GCHECK(is_group(f, group), FMBD_ERR_FORMAT, "not a group");
  FMBD_H5(g = H5Gopen2(f->fid, group, H5P_DEFAULT), FMBD_ERR_FORMAT, "cannot open group");
  hsize_t idx = 0;
  herr_t e = H5Literate(g, H5_INDEX_NAME, H5_ITER_INC, &idx, list_cb, &c);
  if (c.rc) FMBD_GFAIL(c.rc, "out of memory");
  FMBD_H5(e, FMBD_ERR_FORMAT, "cannot list group");
  if (c.n > 1) qsort(c.names, (size_t)c.n, sizeof *c.names, cmp_str);
  *n = c.n;
  *names = c.names;
  c.names = NULL;
  c.n = 0;
done:
  close_id(&g, H5Gclose);
  for (int i = 0; i < c.n; i++) fmbd_free(c.names[i]);
  fmbd_free(c.names);
  if (rc) ctx(f, group);
  return rc;
}

int fmbd_h5_copy(fmbd_h5 *src, const char *path, fmbd_h5 *dst) {
  int rc = FMBD_OK;
  hid_t lcpl = -1;
  if (!fmbd_h5_exists(src, path)) {
    ctx(src, path);
    FMBD_FAIL(FMBD_ERR_FORMAT, "missing object to copy");
  }
  FMBD_GCHECK(dst->writing, FMBD_ERR_INTERNAL, "copy into a read handle");
  FMBD_GCALL(unlink_existing(dst, path));
  FMBD_H5(lcpl = lcpl_intermediate(), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  FMBD_H5(H5Ocopy(src->fid, path, dst->fid, path, H5P_DEFAULT, lcpl), FMBD_ERR_IO,
          "cannot copy from %s", disp(src));
done:
  close_id(&lcpl, H5Pclose);
  if (rc) ctx(dst, path);
  return rc;
}

int fmbd_h5_delete(fmbd_h5 *f, const char *path) {
  int rc = FMBD_OK;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "delete in a read handle");
  FMBD_GCALL(unlink_existing(f, path));
done:
  if (rc) ctx(f, path);
  return rc;
}

// --- attributes --------------------------------------------------------------------------------
// Open the object an attribute belongs to; for writing, groups are created when missing.
static int open_obj(fmbd_h5 *f, const char *obj, bool create, hid_t *out) {
  int rc = FMBD_OK;
  *out = -1;
  if (!fmbd_h5_exists(f, obj)) {
    FMBD_GCHECK(create, FMBD_ERR_FORMAT, "missing object");
    FMBD_GCALL(fmbd_h5_make_group(f, obj));
  }
  FMBD_H5(*out = H5Oopen(f->fid, obj, H5P_DEFAULT), FMBD_ERR_FORMAT, "cannot open object");
done:
  return rc;
}

static hid_t vlen_str_type(void) {
  hid_t t = H5Tcopy(H5T_C_S1);
  if (t >= 0 && (H5Tset_size(t, H5T_VARIABLE) < 0 || H5Tset_cset(t, H5T_CSET_UTF8) < 0)) {
    H5Tclose(t);
    return -1;
  }
  return t;
}

// Create attribute `name` on o (replacing an existing one) of type t and space sp.
static int new_attr(hid_t o, const char *name, hid_t t, hid_t sp, hid_t *out) {
  int rc = FMBD_OK;
  if (H5Aexists(o, name) > 0) {
    FMBD_H5(H5Adelete(o, name), FMBD_ERR_IO, "cannot replace attribute '%s'", name);
  }
  FMBD_H5(*out = H5Acreate2(o, name, t, sp, H5P_DEFAULT, H5P_DEFAULT), FMBD_ERR_IO,
          "cannot create attribute '%s'", name);
done:
  return rc;
}

int fmbd_h5_write_attr_str(fmbd_h5 *f, const char *obj, const char *name, const char *value) {
  int rc = FMBD_OK;
  hid_t o = -1, t = -1, sp = -1, a = -1;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "write to a read handle");
  FMBD_GCALL(open_obj(f, obj, true, &o));
  FMBD_H5(t = vlen_str_type(), FMBD_ERR_EXTERNAL, "cannot make a string type");
  FMBD_H5(sp = H5Screate(H5S_SCALAR), FMBD_ERR_EXTERNAL, "H5Screate failed");
  FMBD_GCALL(new_attr(o, name, t, sp, &a));
  if (!value) value = "";
  FMBD_H5(H5Awrite(a, t, &value), FMBD_ERR_IO, "cannot write attribute '%s'", name);
done:
  close_id(&a, H5Aclose);
  close_id(&sp, H5Sclose);
  close_id(&t, H5Tclose);
  close_id(&o, H5Oclose);
  if (rc) ctx(f, obj);
  return rc;
}

int fmbd_h5_write_attr_strv(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                            const char *const *values) {
  int rc = FMBD_OK;
  hid_t o = -1, t = -1, sp = -1, a = -1;
  hsize_t dims[1] = {(hsize_t)(n > 0 ? n : 0)};
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "write to a read handle");
  FMBD_GCHECK(n >= 0, FMBD_ERR_INTERNAL, "negative count");
  FMBD_GCALL(open_obj(f, obj, true, &o));
  FMBD_H5(t = vlen_str_type(), FMBD_ERR_EXTERNAL, "cannot make a string type");
  FMBD_H5(sp = H5Screate_simple(1, dims, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  FMBD_GCALL(new_attr(o, name, t, sp, &a));
  if (n) FMBD_H5(H5Awrite(a, t, values), FMBD_ERR_IO, "cannot write attribute '%s'", name);
done:
  close_id(&a, H5Aclose);
  close_id(&sp, H5Sclose);
  close_id(&t, H5Tclose);
  close_id(&o, H5Oclose);
  if (rc) ctx(f, obj);
  return rc;
}

static int write_attr_num(fmbd_h5 *f, const char *obj, const char *name, int64_t n, hid_t ftype,
                          hid_t mtype, const void *values) {
  int rc = FMBD_OK;
  hid_t o = -1, sp = -1, a = -1;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "write to a read handle");
  FMBD_GCHECK(n >= 0, FMBD_ERR_INTERNAL, "negative count");
  FMBD_GCALL(open_obj(f, obj, true, &o));
  if (n == 1) {  // one number: a scalar attribute (h5py gives a number, not an array)
    FMBD_H5(sp = H5Screate(H5S_SCALAR), FMBD_ERR_EXTERNAL, "H5Screate failed");
  } else {
    hsize_t dims[1] = {(hsize_t)n};
    FMBD_H5(sp = H5Screate_simple(1, dims, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  }
  FMBD_GCALL(new_attr(o, name, ftype, sp, &a));
  if (n) FMBD_H5(H5Awrite(a, mtype, values), FMBD_ERR_IO, "cannot write attribute '%s'", name);
done:
  close_id(&a, H5Aclose);
  close_id(&sp, H5Sclose);
  close_id(&o, H5Oclose);
  if (rc) ctx(f, obj);
  return rc;
}

int fmbd_h5_write_attr_f64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                           const double *values) {
  return write_attr_num(f, obj, name, n, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, values);
}

int fmbd_h5_write_attr_i64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                           const int64_t *values) {
  return write_attr_num(f, obj, name, n, H5T_STD_I64LE, H5T_NATIVE_INT64, values);
}

bool fmbd_h5_has_attr(fmbd_h5 *f, const char *obj, const char *name) {
  if (!fmbd_h5_exists(f, obj)) return false;
  return H5Aexists_by_name(f->fid, obj, name, H5P_DEFAULT) > 0;
}

// Open attribute name on obj, or FMBD_ERR_FORMAT "missing attribute".
static int open_attr(fmbd_h5 *f, const char *obj, const char *name, hid_t *out) {
  int rc = FMBD_OK;
  *out = -1;
  FMBD_GCHECK(fmbd_h5_exists(f, obj), FMBD_ERR_FORMAT,
              "missing object (looking for attribute '%s')", name);
  FMBD_GCHECK(H5Aexists_by_name(f->fid, obj, name, H5P_DEFAULT) > 0, FMBD_ERR_FORMAT,
              "missing attribute '%s'", name);
  FMBD_H5(*out = H5Aopen_by_name(f->fid, obj, name, H5P_DEFAULT, H5P_DEFAULT), FMBD_ERR_FORMAT,
          "cannot open attribute '%s'", name);
done:
  return rc;
}

// Read n strings (fixed or variable length) of attribute a into fmbd_strdup'ed copies.
static int read_strings(hid_t a, const char *name, int64_t n, char **out) {
  int rc = FMBD_OK;
  hid_t ft = -1, mt = -1;
  char **vl = NULL;
  char *fixed = NULL;
  for (int64_t i = 0; i < n; i++) out[i] = NULL;
  FMBD_H5(ft = H5Aget_type(a), FMBD_ERR_FORMAT, "cannot read the type of '%s'", name);
  FMBD_GCHECK(H5Tget_class(ft) == H5T_STRING, FMBD_ERR_FORMAT, "attribute '%s' is not a string",
              name);
  if (n == 0) goto done;
  if (H5Tis_variable_str(ft) > 0) {
    FMBD_H5(mt = vlen_str_type(), FMBD_ERR_EXTERNAL, "cannot make a string type");
    FMBD_GALLOC(vl = fmbd_calloc((size_t)n, sizeof *vl));
    FMBD_H5(H5Aread(a, mt, vl), FMBD_ERR_FORMAT, "cannot read attribute '%s'", name);
    for (int64_t i = 0; i < n && rc == FMBD_OK; i++) {
      out[i] = fmbd_strdup(vl[i] ? vl[i] : "");
      if (!out[i]) rc = fmbd_err_set(FMBD_ERR_NOMEM, __FILE__, __LINE__, __func__, "out of memory");
    }
    for (int64_t i = 0; i < n; i++) H5free_memory(vl[i]);
    if (rc) goto done;
  } else {
    size_t sz = H5Tget_size(ft);
    FMBD_H5(mt = H5Tcopy(H5T_C_S1), FMBD_ERR_EXTERNAL, "H5Tcopy failed");
    FMBD_H5(H5Tset_size(mt, sz), FMBD_ERR_EXTERNAL, "H5Tset_size failed");
    FMBD_H5(H5Tset_strpad(mt, H5T_STR_NULLPAD), FMBD_ERR_EXTERNAL, "H5Tset_strpad failed");
    FMBD_GALLOC(fixed = fmbd_calloc((size_t)n, sz));
    FMBD_H5(H5Aread(a, mt, fixed), FMBD_ERR_FORMAT, "cannot read attribute '%s'", name);
    for (int64_t i = 0; i < n; i++) {
      FMBD_GALLOC(out[i] = fmbd_malloc(sz + 1));
      memcpy(out[i], fixed + (size_t)i * sz, sz);
      out[i][sz] = '\0';
    }
  }
done:
  if (rc) {
    for (int64_t i = 0; i < n; i++) {
      fmbd_free(out[i]);
      out[i] = NULL;
    }
  }
  fmbd_free(vl);
  fmbd_free(fixed);
  close_id(&mt, H5Tclose);
  close_id(&ft, H5Tclose);
  return rc;
}

static int64_t attr_npoints(hid_t a, int *rank) {
  hid_t sp = H5Aget_space(a);
  if (sp < 0) return -1;
  int64_t n = (int64_t)H5Sget_simple_extent_npoints(sp);
  if (rank) *rank = H5Sget_simple_extent_ndims(sp);
  H5Sclose(sp);
  return n;
}

int fmbd_h5_read_attr_str(fmbd_h5 *f, const char *obj, const char *name, char **value) {
  int rc = FMBD_OK;
  hid_t a = -1;
  *value = NULL;
  FMBD_GCALL(open_attr(f, obj, name, &a));
  FMBD_GCHECK(attr_npoints(a, NULL) == 1, FMBD_ERR_FORMAT, "attribute '%s' is not one string",
              name);
  FMBD_GCALL(read_strings(a, name, 1, value));
done:
  close_id(&a, H5Aclose);
  if (rc) ctx(f, obj);
  return rc;
}

int fmbd_h5_read_attr_strv(fmbd_h5 *f, const char *obj, const char *name, int64_t *n,
                           char ***values) {
  int rc = FMBD_OK;
  hid_t a = -1;
  char **v = NULL;
  int64_t m = 0;
  *n = 0;
  *values = NULL;
  FMBD_GCALL(open_attr(f, obj, name, &a));
  FMBD_GCHECK((m = attr_npoints(a, NULL)) >= 0, FMBD_ERR_FORMAT, "cannot read the shape of '%s'",
              name);
  FMBD_GALLOC(v = fmbd_calloc((size_t)(m ? m : 1), sizeof *v));
  FMBD_GCALL(read_strings(a, name, m, v));
  *n = m;
  *values = v;
  v = NULL;
done:
  fmbd_free(v);
  close_id(&a, H5Aclose);
  if (rc) ctx(f, obj);
  return rc;
}

int fmbd_h5_read_inputs(fmbd_h5 *f, int *n, char ***names, char ***sha256) {
  int rc = FMBD_OK;
  hid_t a = -1;
  char **all = NULL, **nm = NULL, **sh = NULL;
  int64_t m = 0;
  int rank = 0;
  *n = 0;
  *names = *sha256 = NULL;
  FMBD_GCALL(open_attr(f, "/", "inputs", &a));
  FMBD_GCHECK((m = attr_npoints(a, &rank)) >= 0 && rank == 2 && m % 2 == 0, FMBD_ERR_FORMAT,
              "attribute 'inputs' is not an (n, 2) string array");
  FMBD_GALLOC(all = fmbd_calloc((size_t)(m ? m : 1), sizeof *all));
  FMBD_GCALL(read_strings(a, "inputs", m, all));
  FMBD_GALLOC(nm = fmbd_calloc((size_t)(m / 2 ? m / 2 : 1), sizeof *nm));
  FMBD_GALLOC(sh = fmbd_calloc((size_t)(m / 2 ? m / 2 : 1), sizeof *sh));
  for (int64_t i = 0; i < m / 2; i++) {
    nm[i] = all[2 * i];
    sh[i] = all[2 * i + 1];
  }
  fmbd_free(all);
  all = NULL;
  *n = (int)(m / 2);
  *names = nm;
  *sha256 = sh;
  nm = sh = NULL;
done:
  if (all) {
    for (int64_t i = 0; i < m; i++) fmbd_free(all[i]);
    fmbd_free(all);
  }
  fmbd_free(nm);
  fmbd_free(sh);
  close_id(&a, H5Aclose);
  if (rc) ctx(f, "/");
  return rc;
}

static int read_attr_num(fmbd_h5 *f, const char *obj, const char *name, int64_t n, hid_t mtype,
                         void *values) {
  int rc = FMBD_OK;
  hid_t a = -1, t = -1;
  FMBD_GCALL(open_attr(f, obj, name, &a));
  FMBD_H5(t = H5Aget_type(a), FMBD_ERR_FORMAT, "cannot read the type of '%s'", name);
  H5T_class_t cls = H5Tget_class(t);
  FMBD_GCHECK(cls == H5T_INTEGER || cls == H5T_FLOAT, FMBD_ERR_FORMAT,
              "attribute '%s' is not numeric", name);
  FMBD_GCHECK(!(cls == H5T_FLOAT && mtype == H5T_NATIVE_INT64), FMBD_ERR_FORMAT,
              "attribute '%s' is floating point, expected integers", name);
  int64_t m = attr_npoints(a, NULL);
  FMBD_GCHECK(m == n, FMBD_ERR_FORMAT, "attribute '%s' has %lld values, expected %lld", name,
              (long long)m, (long long)n);
  if (n) FMBD_H5(H5Aread(a, mtype, values), FMBD_ERR_FORMAT, "cannot read attribute '%s'", name);
  if (mtype == H5T_NATIVE_DOUBLE) {
    const double *x = values;
    for (int64_t i = 0; i < n; i++) {
      FMBD_GCHECK(isfinite(x[i]), FMBD_ERR_VALUE, "attribute '%s': %s at element %lld", name,
                  isnan(x[i]) ? "NaN" : "Inf", (long long)i);
    }
  }
done:
  close_id(&t, H5Tclose);
  close_id(&a, H5Aclose);
  if (rc) ctx(f, obj);
  return rc;
}

int fmbd_h5_read_attr_f64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                          double *values) {
  return read_attr_num(f, obj, name, n, H5T_NATIVE_DOUBLE, values);
}

int fmbd_h5_read_attr_i64(fmbd_h5 *f, const char *obj, const char *name, int64_t n,
                          int64_t *values) {
  return read_attr_num(f, obj, name, n, H5T_NATIVE_INT64, values);
}

// --- time series -------------------------------------------------------------------------------
#define SERIES_FLUSH_S 0.5  // a file of series is due for a flush this often while it grows

bool fmbd_h5_flush_due(const fmbd_h5 *f) {
  return fmbd_wall_s() - f->last_flush_s >= SERIES_FLUSH_S;
}

// Keep the file's dirty metadata in memory until the next fmbd_h5_flush: HDF5's metadata cache
// otherwise writes an evicted object header (one series' new extent) at any moment, and a file
// killed between two flushes shows series of unequal lengths or does not open. With evictions
// off, what is on disk changes only inside H5Fflush (HDF5 1.10 reference, H5Pset_mdc_config:
// evictions may be disabled only with the automatic resizing modes off). The cache then holds
// every metadata entry of the file: a few per series and per chunk-index node, small.
static int hold_metadata(fmbd_h5 *f) {
  int rc = FMBD_OK;
  if (f->metadata_held) return FMBD_OK;
  H5AC_cache_config_t cfg;
  memset(&cfg, 0, sizeof cfg);
  cfg.version = H5AC__CURR_CACHE_CONFIG_VERSION;
  FMBD_H5(H5Fget_mdc_config(f->fid, &cfg), FMBD_ERR_EXTERNAL, "H5Fget_mdc_config failed");
  cfg.incr_mode = H5C_incr__off;
  cfg.flash_incr_mode = H5C_flash_incr__off;
  cfg.decr_mode = H5C_decr__off;
  cfg.evictions_enabled = 0;
  FMBD_H5(H5Fset_mdc_config(f->fid, &cfg), FMBD_ERR_EXTERNAL, "H5Fset_mdc_config failed");
  f->metadata_held = true;
done:
  return rc;
}

int fmbd_h5_series_create(fmbd_h5 *f, const char *path, int64_t ncols, fmbd_h5_series **out) {
  int rc = FMBD_OK;
  fmbd_h5_series *s = NULL;
  hid_t sp = -1, dcpl = -1, lcpl = -1;
  *out = NULL;
  FMBD_GCHECK(f->writing, FMBD_ERR_INTERNAL, "series in a read handle");
  FMBD_GCHECK(ncols >= 0, FMBD_ERR_INTERNAL, "negative column count");
  FMBD_GCALL(hold_metadata(f));
  FMBD_GALLOC(s = fmbd_calloc(1, sizeof *s));
  s->dset = -1;
  FMBD_GALLOC(s->path = fmbd_strdup(path));
  s->f = f;
  s->ncols = ncols;
  int rank = ncols ? 2 : 1;
  hsize_t dims[2] = {0, (hsize_t)ncols}, maxd[2] = {H5S_UNLIMITED, (hsize_t)ncols};
  hsize_t rows = (hsize_t)(ncols ? 8192 / ncols : 8192);
  hsize_t chunk[2] = {rows < 16 ? 16 : rows, (hsize_t)ncols};
  FMBD_GCALL(unlink_existing(f, path));
  FMBD_H5(sp = H5Screate_simple(rank, dims, maxd), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  FMBD_H5(dcpl = H5Pcreate(H5P_DATASET_CREATE), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  FMBD_H5(H5Pset_chunk(dcpl, rank, chunk), FMBD_ERR_EXTERNAL, "H5Pset_chunk failed");
  FMBD_H5(lcpl = lcpl_intermediate(), FMBD_ERR_EXTERNAL, "H5Pcreate failed");
  FMBD_H5(s->dset = H5Dcreate2(f->fid, path, H5T_IEEE_F64LE, sp, lcpl, dcpl, H5P_DEFAULT),
          FMBD_ERR_IO, "cannot create series");
  *out = s;
  s = NULL;
done:
  close_id(&lcpl, H5Pclose);
  close_id(&dcpl, H5Pclose);
  close_id(&sp, H5Sclose);
  fmbd_h5_series_close(&s);
  if (rc) ctx(f, path);
  return rc;
}

int fmbd_h5_series_append(fmbd_h5_series *s, int64_t nrows, const double *rows) {
  int rc = FMBD_OK;
  hid_t fsp = -1, msp = -1;
  if (nrows <= 0) return FMBD_OK;
  int rank = s->ncols ? 2 : 1;
  hsize_t newd[2] = {(hsize_t)(s->nrows + nrows), (hsize_t)s->ncols};
  hsize_t start[2] = {(hsize_t)s->nrows, 0}, cnt[2] = {(hsize_t)nrows, (hsize_t)s->ncols};
  FMBD_H5(H5Dset_extent(s->dset, newd), FMBD_ERR_IO, "cannot extend series");
  FMBD_H5(fsp = H5Dget_space(s->dset), FMBD_ERR_EXTERNAL, "H5Dget_space failed");
  FMBD_H5(H5Sselect_hyperslab(fsp, H5S_SELECT_SET, start, NULL, cnt, NULL), FMBD_ERR_EXTERNAL,
          "H5Sselect_hyperslab failed");
  FMBD_H5(msp = H5Screate_simple(rank, cnt, NULL), FMBD_ERR_EXTERNAL, "H5Screate_simple failed");
  FMBD_H5(H5Dwrite(s->dset, H5T_NATIVE_DOUBLE, msp, fsp, H5P_DEFAULT, rows), FMBD_ERR_IO,
          "cannot write series");
  s->nrows += nrows;
done:
  close_id(&msp, H5Sclose);
  close_id(&fsp, H5Sclose);
  if (rc) ctx(s->f, s->path);
  return rc;
}

int64_t fmbd_h5_series_rows(const fmbd_h5_series *s) {
  return s->nrows;
}

void fmbd_h5_series_close(fmbd_h5_series **ps) {
  if (!ps || !*ps) return;
  fmbd_h5_series *s = *ps;
  if (s->dset >= 0 && H5Iis_valid(s->dset) > 0) H5Dclose(s->dset);
  fmbd_free(s->path);
  fmbd_free(s);
  *ps = NULL;
}
