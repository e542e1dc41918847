// common/fmbd_sha256.c: SHA-256 (FIPS 180-4, section 6.2), written from the standard
// SPDX-License-Identifier: MIT
#include "fmbd_sha256.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_err.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <cpuid.h>
#include <immintrin.h>
#define FMBD_SHA_X86 1
#endif

// FIPS 180-4 section 4.2.2: the first 32 bits of the fractional parts of the cube roots of
// the first 64 primes.
static const uint32_t K256[64] = {
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
    0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
    0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
    0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
    0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
    0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
    0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
    0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2};

static uint32_t rotr(uint32_t x, int n) {
  return (x >> n) | (x << (32 - n));
}

static void compress(uint32_t H[8], const unsigned char *blk) {
  uint32_t W[64];
  for (int t = 0; t < 16; t++) {
    W[t] = (uint32_t)blk[4 * t] << 24 | (uint32_t)blk[4 * t + 1] << 16 |
           (uint32_t)blk[4 * t + 2] << 8 | (uint32_t)blk[4 * t + 3];
  }
  for (int t = 16; t < 64; t++) {
    uint32_t s0 = rotr(W[t - 15], 7) ^ rotr(W[t - 15], 18) ^ (W[t - 15] >> 3);
    uint32_t s1 = rotr(W[t - 2], 17) ^ rotr(W[t - 2], 19) ^ (W[t - 2] >> 10);
    W[t] = W[t - 16] + s0 + W[t - 7] + s1;
  }
  uint32_t a = H[0], b = H[1], c = H[2], d = H[3], e = H[4], f = H[5], g = H[6], h = H[7];
  for (int t = 0; t < 64; t++) {
    uint32_t S1 = rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25);
    uint32_t ch = (e & f) ^ (~e & g);
    uint32_t T1 = h + S1 + ch + K256[t] + W[t];
    uint32_t S0 = rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22);
    uint32_t maj = (a & b) ^ (a & c) ^ (b & c);
    uint32_t T2 = S0 + maj;
    h = g;
    g = f;
    f = e;
    e = d + T1;
    d = c;
    c = b;
    b = a;
    a = T1 + T2;
  }
  H[0] += a;
  H[1] += b;
  H[2] += c;
  H[3] += d;
  H[4] += e;
  H[5] += f;
  H[6] += g;
  H[7] += h;
}

#ifdef FMBD_SHA_X86
// The same compression with the x86 SHA extensions (Intel, "Intel SHA Extensions", Gulley et
// al. 2013: SHA256RNDS2 does two rounds on the state held as the pairs ABEF and CDGH,
// SHA256MSG1/MSG2 the message schedule of section 6.2.2 step 1, four words at a time); nblk
// consecutive 64-byte blocks. About ten times the portable code's speed: the whole-file hash
// of every input (provenance) costs as much as reading it.
__attribute__((target("sha,sse4.1,ssse3"))) static void compress_ni(uint32_t H[8],
                                                                    const unsigned char *p,
                                                                    uint64_t nblk) {
  const __m128i bswap = _mm_set_epi64x(0x0c0d0e0f08090a0bLL, 0x0405060700010203LL);
  __m128i t = _mm_loadu_si128((const __m128i *)H), s1 = _mm_loadu_si128((const __m128i *)(H + 4));
  t = _mm_shuffle_epi32(t, 0xB1);          // lanes B A D C
  s1 = _mm_shuffle_epi32(s1, 0x1B);        // lanes H G F E
  __m128i s0 = _mm_alignr_epi8(t, s1, 8);  // lanes F E B A: the pair ABEF
  s1 = _mm_blend_epi16(s1, t, 0xF0);       // lanes H G D C: the pair CDGH
  for (; nblk > 0; nblk--, p += 64) {
    const __m128i a0 = s0, c0 = s1;
    __m128i w[4];
    for (int g = 0; g < 16; g++) {  // rounds 4g .. 4g + 3 with the words W[4g .. 4g + 3]
      __m128i x;
      if (g < 4) {
        x = _mm_shuffle_epi8(_mm_loadu_si128((const __m128i *)(p + 16 * g)), bswap);
      } else {  // W[t-16] + s0(W[t-15]) + W[t-7] + s1(W[t-2])
        x = _mm_sha256msg1_epu32(w[g & 3], w[(g + 1) & 3]);
        x = _mm_add_epi32(x, _mm_alignr_epi8(w[(g + 3) & 3], w[(g + 2) & 3], 4));
        x = _mm_sha256msg2_epu32(x, w[(g + 3) & 3]);
      }
      w[g & 3] = x;
      __m128i k = _mm_add_epi32(x, _mm_loadu_si128((const __m128i *)(K256 + 4 * g)));
      s1 = _mm_sha256rnds2_epu32(s1, s0, k);  // two rounds: s1 is the new ABEF
      s0 = _mm_sha256rnds2_epu32(s0, s1, _mm_shuffle_epi32(k, 0x0E));
    }
    s0 = _mm_add_epi32(s0, a0);
    s1 = _mm_add_epi32(s1, c0);
  }
  t = _mm_shuffle_epi32(s0, 0x1B);    // lanes A B E F
  s1 = _mm_shuffle_epi32(s1, 0xB1);   // lanes G H C D
  s0 = _mm_blend_epi16(t, s1, 0xF0);  // lanes A B C D
  s1 = _mm_alignr_epi8(s1, t, 8);     // lanes E F G H
  _mm_storeu_si128((__m128i *)H, s0);
  _mm_storeu_si128((__m128i *)(H + 4), s1);
}

// 1 when the processor has the SHA extensions and SSE4.1 (CPUID leaf 7 EBX bit 29, leaf 1
// ECX bits 19 and 9)
static int cpu_has_sha(void) {
  unsigned a, b, c, d;
  if (!__get_cpuid(1, &a, &b, &c, &d) || !(c & (1u << 19)) || !(c & (1u << 9))) return 0;
  if (__get_cpuid_max(0, NULL) < 7) return 0;
  __cpuid_count(7, 0, a, b, c, d);
  return (b >> 29) & 1u;
}
#endif

// -1: not yet decided; 0: the portable code; 1: the SHA extensions
static int g_hw = -1;

int fmbd_sha256_hw(int enable) {
#ifdef FMBD_SHA_X86
  if (g_hw < 0 || enable >= 0) g_hw = cpu_has_sha() && enable != 0;
#else
  g_hw = 0;
#endif
  return g_hw;
}

static void compress_blocks(uint32_t H[8], const unsigned char *p, uint64_t nblk) {
#ifdef FMBD_SHA_X86
  if (g_hw < 0) fmbd_sha256_hw(-1);
  if (g_hw) {
    compress_ni(H, p, nblk);
    return;
  }
#endif
  for (; nblk > 0; nblk--, p += 64) compress(H, p);
}

void fmbd_sha256_init(fmbd_sha256 *s) {
  // section 5.3.3: the first 32 bits of the fractional parts of the square roots of the
  // first 8 primes
  static const uint32_t H0[8] = {0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
                                 0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19};
  memcpy(s->h, H0, sizeof H0);
  s->nbytes = 0;
  s->nbuf = 0;
}

void fmbd_sha256_update(fmbd_sha256 *s, const void *data, uint64_t n) {
  const unsigned char *p = data;
  s->nbytes += n;
  if (s->nbuf) {
    uint64_t take = 64 - s->nbuf < n ? 64 - s->nbuf : n;
    memcpy(s->buf + s->nbuf, p, (size_t)take);
    s->nbuf += (unsigned)take;
    p += take;
    n -= take;
    if (s->nbuf < 64) return;
    compress_blocks(s->h, s->buf, 1);
    s->nbuf = 0;
  }
  compress_blocks(s->h, p, n / 64);
  p += n / 64 * 64;
  n %= 64;
  if (n) {
    memcpy(s->buf, p, (size_t)n);
    s->nbuf = (unsigned)n;
  }
}

void fmbd_sha256_final(fmbd_sha256 *s, char hex[65]) {
  // section 5.1.1: append bit 1, zeros to 448 mod 512 bits, then the 64-bit message length
  uint64_t bits = s->nbytes * 8;
  unsigned char pad[72] = {0x80};
  unsigned npad = (s->nbuf < 56 ? 56 : 120) - s->nbuf;
  for (int i = 0; i < 8; i++) pad[npad + (unsigned)i] = (unsigned char)(bits >> (56 - 8 * i));
  uint64_t keep = s->nbytes;
  fmbd_sha256_update(s, pad, npad + 8);
  s->nbytes = keep;
  static const char digits[] = "0123456789abcdef";
  for (int i = 0; i < 8; i++) {
    for (int j = 0; j < 4; j++) {
      unsigned byte = (s->h[i] >> (24 - 8 * j)) & 0xffu;
      hex[8 * i + 2 * j] = digits[byte >> 4];
      hex[8 * i + 2 * j + 1] = digits[byte & 15];
    }
  }
  hex[64] = '\0';
}

void fmbd_sha256_hex(const void *data, uint64_t n, char hex[65]) {
  fmbd_sha256 s;
  fmbd_sha256_init(&s);
  fmbd_sha256_update(&s, data, n);
  fmbd_sha256_final(&s, hex);
}

int fmbd_sha256_file(const char *path, char hex[65]) {
  FILE *fp = fopen(path, "rb");
  if (!fp) {
    int e = errno;
    fmbd_err_context(path, "");
    FMBD_FAIL(FMBD_ERR_IO, "cannot open: %s", strerror(e));
  }
  fmbd_sha256 s;
  fmbd_sha256_init(&s);
  unsigned char buf[1 << 16];
  size_t got;
  while ((got = fread(buf, 1, sizeof buf, fp)) > 0) fmbd_sha256_update(&s, buf, got);
  int bad = ferror(fp), e = errno;
  fclose(fp);
  if (bad) {
    fmbd_err_context(path, "");
    FMBD_FAIL(FMBD_ERR_IO, "read error: %s", strerror(e));
  }
  fmbd_sha256_final(&s, hex);
  return FMBD_OK;
}
