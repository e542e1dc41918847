// fuzz/fuzz_scene.c: the scene parser (fmbd_scene_parse) on any bytes: YAML syntax, the scene's
// keys, types, ranges and cross references. Body files are not opened by the parser.
// SPDX-License-Identifier: MIT
#include "fmbd_scene.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_quiet();
  fmbd_scene *s = NULL;
  if (fmbd_scene_parse("fuzz.yaml", (const char *)data, (int64_t)size, &s) == FMBD_OK) {
    for (int i = 0; i < s->nbodies; i++) (void)fmbd_scene_find_body(s, s->bodies[i].name);
  }
  fmbd_scene_destroy(&s);
  fmbd_err_clear();
  return 0;
}
