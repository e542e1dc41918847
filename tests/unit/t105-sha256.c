// tests/unit/t105-sha256.c: SHA-256 against the FIPS 180-4 / NIST example vectors and sha256sum
// SPDX-License-Identifier: MIT
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd.h"

// The NIST CSRC example values for SHA-256 (FIPS 180-4 appendix examples) are exact: any
// difference in any bit is a failure, so the comparison is string equality.
static void vec(const char *msg, const char *want) {
  char hex[65];
  fmbd_sha256_hex(msg, strlen(msg), hex);
  EXPECT(!strcmp(hex, want), "sha256(\"%.20s...\") = %s, expected %s", msg, hex, want);
  // the same message fed in pieces of 1, 7 and 63 bytes through the streaming interface
  const size_t pieces[] = {1, 7, 63};
  for (int k = 0; k < 3; k++) {
    fmbd_sha256 s;
    fmbd_sha256_init(&s);
    size_t n = strlen(msg);
    for (size_t i = 0; i < n; i += pieces[k]) {
      fmbd_sha256_update(&s, msg + i, n - i < pieces[k] ? n - i : pieces[k]);
    }
    fmbd_sha256_final(&s, hex);
    EXPECT(!strcmp(hex, want), "streamed by %zu: %s, expected %s", pieces[k], hex, want);
  }
}

// every check below runs twice where the processor has the x86 SHA extensions: with them (the
// default) and with the portable code, so that both paths meet the same exact vectors
static void all_checks(void);
int main(void) {
  int hw = fmbd_sha256_hw(-1);
  printf("SHA extensions: %s\n", hw ? "used" : "not available");
  all_checks();
  if (hw) {
    EXPECT(fmbd_sha256_hw(0) == 0, "cannot switch to the portable code");
    all_checks();
    // random lengths and offsets, both paths on the same bytes
    unsigned char *buf = malloc(70000);
    uint32_t st = 12345;
    for (int i = 0; i < 70000; i++)
      st = st * 1664525u + 1013904223u, buf[i] = (unsigned char)(st >> 24);
    for (int t = 0; t < 200; t++) {
      st = st * 1664525u + 1013904223u;
      size_t off = st % 64, n = (st >> 8) % 69000;
      char h0[65], h1[65];
      fmbd_sha256_hw(0);
      fmbd_sha256_hex(buf + off, n, h0);
      fmbd_sha256_hw(1);
      fmbd_sha256_hex(buf + off, n, h1);
      EXPECT(!strcmp(h0, h1), "length %zu at offset %zu: portable %s, SHA extensions %s", n, off,
             h0, h1);
    }
    free(buf);
  }
  TEST_EXIT();
}

static void all_checks(void) {
  vec("abc", "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  vec("", "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  vec("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq",  // 448 bits
      "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  vec("abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmnoijklmnopjklmnopqklmnopqrlm"
      "nopqrsmnopqrstnopqrstu",  // 896 bits
      "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
  // one million 'a'
  char *a = malloc(1000000);
  memset(a, 'a', 1000000);
  char hex[65];
  fmbd_sha256_hex(a, 1000000, hex);
  EXPECT(!strcmp(hex, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0"),
         "1M 'a': %s", hex);
  free(a);

  // --- against coreutils sha256sum for every length around the padding boundaries ---
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  char dir[1024], path[1100], cmd[1300];
  snprintf(dir, sizeof dir, "%s/%s/test-tmp/t105-sha256", root ? root : ".",
           build ? build : "build");
  snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
  EXPECT(system(cmd) == 0, "cannot make %s", dir);
  snprintf(path, sizeof path, "%s/bytes", dir);
  const int lengths[] = {0, 1, 55, 56, 57, 63, 64, 65, 119, 120, 127, 128, 129, 100000};
  for (size_t t = 0; t < sizeof lengths / sizeof *lengths; t++) {
    int n = lengths[t];
    FILE *fp = fopen(path, "wb");
    EXPECT(fp, "cannot write %s", path);
    if (!fp) break;
    for (int i = 0; i < n; i++) fputc((i * 131 + 7) & 0xff, fp);
    fclose(fp);
    char mine[65], theirs[65] = "";
    EXPECT(fmbd_sha256_file(path, mine) == FMBD_OK, "fmbd_sha256_file failed");
    snprintf(cmd, sizeof cmd, "sha256sum '%s'", path);
    FILE *p = popen(cmd, "r");
    EXPECT(p && fscanf(p, "%64s", theirs) == 1, "sha256sum did not run");
    if (p) pclose(p);
    EXPECT(!strcmp(mine, theirs), "length %d: %s, sha256sum %s", n, mine, theirs);
  }
  // a missing file is an I/O error naming the file
  fmbd_err_clear();
  EXPECT(fmbd_sha256_file("/no/such/file", hex) == FMBD_ERR_IO, "missing file");
  EXPECT(!strcmp(fmbd_err_get()->file, "/no/such/file"), "context %s", fmbd_err_get()->file);
}
