// common/fmbd_scene.h: the scene of fmbd-run: a YAML file read into plain structs
// SPDX-License-Identifier: MIT
//
// docs/SCENE.md documents the format key by key. The reader (libyaml's document API) keeps
// the line and column of every item, rejects unknown and duplicate keys, checks types,
// ranges and references between items (joint -> body, driver -> joint, output -> body), and
// reports the first fault as `FILE:LINE:COLUMN: message` (fmbd_err_contextf), e.g.
// `quad.yaml:12:5: unknown key 'foo' in joint 'j1'`. Nothing is computed here: body files
// are named, not opened (fmbd_scene_build, fmbd_scene_build.h, turns a scene into a
// multibody system). The scene speaks the multibody library's types: its time functions are
// fmbd_mbs_fn, its joint kinds FMBD_MBS_*, its solver section a fmbd_mbs_settings.
//
// Units SI; angles in radians unless a key ends in `_deg`. Vectors are world components
// unless documented as body-frame.
#ifndef FMBD_SCENE_H
#define FMBD_SCENE_H

/// most bodies that one GMs basis file shares its coordinates among (scene key basis_kind)
#define FMBD_SCENE_GMS_MAX 256

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fmbd_mbs.h"

/// Where an item starts in the scene file (1-based, as editors count).
typedef struct fmbd_scene_loc {
  int line, column;
} fmbd_scene_loc;

enum fmbd_scene_body_kind { FMBD_SCENE_RIGID = 0, FMBD_SCENE_FLEXIBLE };

/// How a flexible body file is made (only for `fmbd-run -M`): geometry -> fe -> cb -> rflex.
typedef struct fmbd_scene_chain {
  char *geometry, *mesh2fe_args;  ///< geometry file and mesh2fe options (NULL: not named)
  char *fe, *fe2cb_args;          ///< fe file and fe2cb options
  char *cb, *cbcheck_args;        ///< cb file and cbcheck options (rflex bodies)
  bool whole;  ///< `whole: true`: the whole body, not one made for this scene (--for-scene)
  char *gm_scene, *gmsolve_args;  ///< the scene gmsolve makes the `basis` file from, options
} fmbd_scene_chain;

typedef struct fmbd_scene_body {
  char *name;
  fmbd_scene_loc loc;
  int kind;  ///< fmbd_scene_body_kind
  // --- rigid: inertia in the body frame (geometry shorthand filled these) ---
  double mass;        ///< kg
  double com[3];      ///< centre of mass, body frame
  double inertia[9];  ///< 3x3 row-major about the centre of mass, body frame
  // --- flexible ---
  char *file;  ///< .rflex.h5 or .cb.h5, resolved against the scene's folder
  fmbd_scene_loc file_loc;
  char *basis;  ///< a gmsolve .gm.h5 whose GMc basis of this body replaces the file's modes
                ///< (NULL: the file's modes), resolved as file
  fmbd_scene_loc basis_loc;
  char *basis_body;  ///< the body's name in the basis file (NULL: this body's name)
  bool basis_gms;    ///< basis_kind gms: the GMs basis, its coordinates shared by every body
                     ///< naming the same basis file with gms (else the body's GMc basis)
  int64_t modes;     ///< first N flexible modes kept; 0 = all in the file
  bool damping_set;
  double damping_ratio;  ///< modal damping ratio of every kept mode (default 0)
  bool inertia_partial;  ///< inertia_coupling: partial (default full; docs/SCENE.md)
  fmbd_scene_loc inertia_loc;
  fmbd_scene_chain chain;
  // --- initial state (world) ---
  double position[3];  ///< body-frame origin
  double rotation[9];  ///< body -> world, row-major
  double velocity[3];  ///< of the body-frame origin
  double angular_velocity[3];
} fmbd_scene_body;

/// @brief The scene keyword of a joint kind ("spherical", ...).
const char *fmbd_scene_joint_name(int kind);

/// Where a joint, load or output sits on a body.
enum fmbd_scene_at_kind {
  FMBD_AT_DEFAULT = 0,  ///< joint: the joint's world point; load: the body-frame origin
  FMBD_AT_POINT,        ///< p: body-frame coordinates
  FMBD_AT_INTERFACE,    ///< interface: an interface node of a flexible body
  FMBD_AT_NODE,         ///< node: a node index of a flexible body
  FMBD_AT_NEAREST,      ///< p: the flexible-body node nearest to this body-frame point
};
typedef struct fmbd_scene_at {
  int kind;  ///< fmbd_scene_at_kind
  double p[3];
  char *interface;
  int64_t node;
  fmbd_scene_loc loc;
} fmbd_scene_at;

typedef struct fmbd_scene_joint {
  char *name;
  fmbd_scene_loc loc;
  int kind;     ///< fmbd_mbs_joint_kind (FMBD_MBS_SPHERICAL, ...)
  int body[2];  ///< body indices, -1 = ground
  fmbd_scene_loc body_loc[2];
  fmbd_scene_at at[2];  ///< attachment on each side
  bool has_point;
  double point[3];  ///< world point at the initial configuration
  fmbd_scene_loc point_loc;
  double axis[3];   ///< unit, world: revolute/prismatic/cylindrical axis, universal axis on body 1
  double axis2[3];  ///< unit, world: universal axis on body 2 (orthogonal to axis)
} fmbd_scene_joint;

typedef struct fmbd_scene_driver {
  char *name;
  fmbd_scene_loc loc;
  int joint;       ///< joint index (revolute/prismatic/cylindrical coordinate), or -1
  int body;        ///< body index for a body coordinate, or -1
  int coordinate;  ///< body coordinate 0..2 = x y z of the origin (world)
  fmbd_mbs_fn fn;  ///< table points owned by the scene
} fmbd_scene_driver;

enum fmbd_scene_load_kind { FMBD_LOAD_FORCE = 0, FMBD_LOAD_TORQUE };
typedef struct fmbd_scene_load {
  char *name;
  fmbd_scene_loc loc;
  int kind;  ///< fmbd_scene_load_kind
  int body;
  fmbd_scene_at at;     ///< point of application (forces)
  bool body_frame;      ///< direction given in the body frame (default world)
  double direction[3];  ///< load = direction * fn(t)
  fmbd_mbs_fn fn;       ///< default constant 1; table points owned by the scene
} fmbd_scene_load;

/// Quantities of a point output (bit flags).
enum {
  FMBD_OUT_POSITION = 1,
  FMBD_OUT_VELOCITY = 2,
  FMBD_OUT_ACCELERATION = 4,
  FMBD_OUT_VON_MISES = 8,  ///< flexible nodes; needs /modes/stress
  FMBD_OUT_STRESS = 16,    ///< the 6 components xx yy zz xy yz zx
  FMBD_OUT_STRAIN = 32,    ///< von Mises equivalent strain and the 6 components (Hooke)
};
typedef struct fmbd_scene_output {
  char *name;
  fmbd_scene_loc loc;
  int body;
  fmbd_scene_at at;
  unsigned quantities;  ///< FMBD_OUT_* flags
} fmbd_scene_output;

typedef struct fmbd_scene {
  char *file;      ///< the scene file's name as given
  char *dir;       ///< its folder ("." if none), against which body files resolve
  char *body_dir;  ///< the body_dir it was read with (NULL: none; -M reads gm_scene with it)
  char *title;
  char *text;         ///< the scene file's text as read (provenance in the run file)
  double gravity[3];  ///< default 0
  /// The solver section with the library's defaults (fmbd_mbs_settings_defaults); output.every
  /// is its output_every, reactions are asked when the outputs name joints. t_end is required.
  fmbd_mbs_settings solver;
  int nbodies;
  fmbd_scene_body *bodies;
  int njoints;
  fmbd_scene_joint *joints;
  int ndrivers;
  fmbd_scene_driver *drivers;
  int nloads;
  fmbd_scene_load *loads;
  int noutputs;
  fmbd_scene_output *outputs;
  int nreactions;
  int *reactions;  ///< joint indices whose reactions are written
  fmbd_scene_loc *reaction_locs;
  bool energy;    ///< write /energy/{kinetic,potential,strain}
  bool momentum;  ///< write /momentum/{linear,angular} (about the world origin)
} fmbd_scene;

/// @brief Read a scene file ("-": standard input). Every fault is reported with
/// FILE:LINE:COLUMN (FMBD_ERR_SCENE), a missing file with FMBD_ERR_IO.
/// @param[out] out caller destroys with fmbd_scene_destroy
int fmbd_scene_read(const char *file, fmbd_scene **out);
/// @brief Same from a string (`file` only names it in messages; body files resolve against
/// its folder).
int fmbd_scene_parse(const char *file, const char *text, int64_t len, fmbd_scene **out);
/// @brief Same, with body files (`file`, and the `make` chain's fe and cb) resolved against
/// body_dir instead of the scene's folder (NULL: the scene's folder); the chain's geometry
/// stays relative to the scene. Lets a build keep made files out of the source tree.
int fmbd_scene_read_dir(const char *file, const char *body_dir, fmbd_scene **out);
int fmbd_scene_parse_dir(const char *file, const char *body_dir, const char *text, int64_t len,
                         fmbd_scene **out);
/// @brief Release a scene; NULL fine; *s = NULL.
void fmbd_scene_destroy(fmbd_scene **s);
/// @brief Body index by name, -1 if none ("ground" is -1 too).
int fmbd_scene_find_body(const fmbd_scene *s, const char *name);
/// @brief Set the error context to the scene file and loc (for errors found later).
void fmbd_scene_context(const fmbd_scene *s, fmbd_scene_loc loc);

/// @brief The interfaces of a flexible body that the scene's joints hold beyond translations
/// (fixed, revolute, universal, prismatic, cylindrical joints attached at an interface), as a
/// comma-separated list into buf (n bytes): of body index `body`, or (body < 0) of every body
/// whose file is `file`. These are what cbcheck --hold must know (docs/THEORY.md section 12).
void fmbd_scene_held_interfaces(const fmbd_scene *s, const char *file, int body, char *buf,
                                size_t n);
/// @brief Whether the comma-separated list holds name.
bool fmbd_scene_list_has(const char *list, const char *name);

/// @brief Write make rules of the files the scene needs (as `cc -M`): `target: scene
/// files...`, and for each flexible body whose chain is named, the rules that make it from
/// upstream (with recipes calling cbcheck, fe2cb, mesh2fe; cbcheck gets --hold for the
/// interfaces the scene's joints hold, fmbd_scene_held_interfaces). Paths as the program sees them
/// (relative to the current folder). Rigid-only scenes depend on the scene file alone.
/// @param[out] text caller frees with fmbd_free
int fmbd_scene_make_rules(const fmbd_scene *s, const char *target, char **text);

#endif
