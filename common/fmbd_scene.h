// common/fmbd_scene.h: the scene of fmbd-run: a YAML file read into plain structs
// SPDX-License-Identifier: MIT
//
// docs/SCENE.md documents the format key by key. The reader (libyaml's document API) keeps
// the line and column of every item, rejects unknown and duplicate keys, checks types,
// ranges and references between items (joint -> body, driver -> joint, output -> body), and
// reports the first fault as `FILE:LINE:COLUMN: message` (fmbd_err_contextf), e.g.
// `quad.yaml:12:5: unknown key 'foo' in joint 'j1'`. Nothing is computed here: body files
// are named, not opened (fmbd_scene_build in fmbd_scene_build.c turns a scene into a
// multibody system).
//
// Units SI; angles in radians unless a key ends in `_deg`. Vectors are world components
// unless documented as body-frame.
#ifndef FMBD_SCENE_H
#define FMBD_SCENE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fmbd_mbs.h"

/// Where an item starts in the scene file (1-based, as editors count).
typedef struct fmbd_scene_loc {
  int line, column;
} fmbd_scene_loc;

/// A scalar function of time (drivers, loads).
enum fmbd_scene_fn_kind {
  FMBD_FN_CONSTANT = 0,  ///< value
  FMBD_FN_RAMP,          ///< v0 until t0, linear (or smooth: C1 cubic) to v1 at t1, then v1
  FMBD_FN_SINE,          ///< offset + amplitude * sin(2 pi frequency_hz t + phase)
  FMBD_FN_TABLE,         ///< piecewise linear through (t[i], v[i]), constant outside
  FMBD_FN_LINEAR,        ///< v0 + rate (t - t0) for all t (constant-speed drivers)
};
typedef struct fmbd_scene_fn {
  int kind;                                       ///< fmbd_scene_fn_kind
  double value;                                   ///< constant
  double t0, t1, v0, v1;                          ///< ramp; linear uses t0, v0
  double rate;                                    ///< linear: slope (unit/s)
  bool smooth;                                    ///< ramp: 3s^2 - 2s^3 blend instead of linear
  double amplitude, frequency_hz, phase, offset;  ///< sine
  int64_t n;      ///< table: number of points (>= 2, t strictly increasing)
  double *t, *v;  ///< table points (owned)
} fmbd_scene_fn;

/// @brief The same function as the multibody core's fmbd_mbs_fn (table points borrowed from
/// f), evaluated with fmbd_mbs_fn_eval: the one implementation of the time functions.
fmbd_mbs_fn fmbd_scene_fn_to_mbs(const fmbd_scene_fn *f);

enum fmbd_scene_body_kind { FMBD_SCENE_RIGID = 0, FMBD_SCENE_FLEXIBLE };

/// How a flexible body file is made (only for `fmbd-run -M`): geometry -> fe -> cb -> rflex.
typedef struct fmbd_scene_chain {
  char *geometry, *mesh2fe_args;  ///< geometry file and mesh2fe options (NULL: not named)
  char *fe, *fe2cb_args;          ///< fe file and fe2cb options
  char *cb, *cbcheck_args;        ///< cb file and cbcheck options (rflex bodies)
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
  int64_t modes;  ///< first N flexible modes kept; 0 = all in the file
  bool damping_set;
  double damping_ratio;  ///< modal damping ratio of every kept mode (default 0)
  fmbd_scene_chain chain;
  // --- initial state (world) ---
  double position[3];  ///< body-frame origin
  double rotation[9];  ///< body -> world, row-major
  double velocity[3];  ///< of the body-frame origin
  double angular_velocity[3];
} fmbd_scene_body;

enum fmbd_scene_joint_kind {
  FMBD_JOINT_SPHERICAL = 0,
  FMBD_JOINT_REVOLUTE,
  FMBD_JOINT_UNIVERSAL,
  FMBD_JOINT_PRISMATIC,
  FMBD_JOINT_CYLINDRICAL,
  FMBD_JOINT_FIXED,
};
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
  int kind;     ///< fmbd_scene_joint_kind
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
  fmbd_scene_fn fn;
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
  fmbd_scene_fn fn;     ///< default constant 1
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

typedef struct fmbd_scene_solver {
  double t_end;       ///< s (required)
  double rho_inf;     ///< spectral radius at infinity, default 0.9
  bool fixed;         ///< fixed step (`step` given)
  double step;        ///< fixed step, s
  double first_step;  ///< variable: default 1e-6 (paper [H])
  double max_step;    ///< variable: default 1e-2 (paper [H])
  double min_step;    ///< default 1e-12: Newton failure at this size stops the run
  double tolerance;   ///< local error tolerance (variable steps), default 1e-4
  double newton_tol;  ///< scaled Newton increment tolerance, default 1e-8
  int newton_max;     ///< Newton iterations per step, default 10
} fmbd_scene_solver;

typedef struct fmbd_scene {
  char *file;  ///< the scene file's name as given
  char *dir;   ///< its folder ("." if none), against which body files resolve
  char *title;
  char *text;         ///< the scene file's text as read (provenance in the run file)
  double gravity[3];  ///< default 0
  fmbd_scene_solver solver;
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
  bool energy;          ///< write /energy/{kinetic,potential,strain}
  bool momentum;        ///< write /momentum/{linear,angular} (about the world origin)
  double output_every;  ///< output interval in s; 0 = every accepted step
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

// --- the scene as a multibody system (fmbd_scene_build.c) ----------------------------------
#include "fmbd_rflex.h"

/// A scene turned into an fmbd_mbs system, with what the outputs need to be evaluated.
typedef struct fmbd_scene_model {
  fmbd_mbs *mbs;      ///< owned; fmbd_mbs_init not yet called
  int nbodies;        ///< = scene nbodies
  int *body_id;       ///< scene body -> mbs body id
  fmbd_rflex **flex;  ///< per body: the modal body (NULL for rigid), owned
  double *E, *nu;     ///< per body: material of a flexible body (strain outputs)
  char **file_kind;   ///< per body: "fmbd-rflex" / "fmbd-cb" / NULL (rigid)
  int *joint_id;      ///< scene joint -> mbs joint id
  int noutputs;
  int *out_point;         ///< per output: mbs point id
  int *out_body;          ///< per output: scene body index
  int64_t *out_node;      ///< per output: node of a flexible body, or -1
  double **out_sigma;     ///< per output: 6 x nm modal stress (stress/strain asked), or NULL
  int ninputs;            ///< body files read (provenance)
  char **input_name;      ///< owned names
  char (*input_sha)[65];  ///< their SHA-256
} fmbd_scene_model;

/// @brief Build the multibody system of a scene: open every body file (.rflex.h5 or .cb.h5;
/// another kind is an error naming the scene line of `file`), keep the first N modes if
/// asked, place points of joints, loads and outputs (a joint point that is not on its
/// flexible body is an error naming the joint's line and the nearest node), add joints,
/// drivers, loads and gravity. Modal stress is kept only for outputs asking for it.
/// @param[out] out caller destroys with fmbd_scene_model_destroy
int fmbd_scene_build(const fmbd_scene *s, fmbd_scene_model **out);
/// @brief The mbs settings of the scene's solver section (and reactions when asked).
void fmbd_scene_settings(const fmbd_scene *s, fmbd_mbs_settings *set);
/// @brief Stress (xx yy zz xy yz zx, Pa) at output `o` now (out_sigma times the body's
/// modal coordinates). FMBD_ERR_VALUE if that output has no stress.
int fmbd_scene_output_stress(const fmbd_scene_model *m, int o, double sigma[6]);
/// @brief Linear elastic strain (tensor components xx yy zz xy yz zx) of a stress, and its
/// von Mises equivalent 2 (1 + nu) sigma_vm / (3 E) (returned).
double fmbd_scene_strain(double E, double nu, const double sigma[6], double eps[6]);
/// @brief Release the model; NULL fine.
void fmbd_scene_model_destroy(fmbd_scene_model **m);
/// @brief A flexible body from a .cb.h5 (format fmbd-cb): the flexible eigenvectors of the
/// reduced problem (/reduced/eigenvectors without /reduced/rigid), expanded to the FE dofs
/// (qF = [Phi Psi; 0 I] Xi, mass-normalised), built by fmbd_rflex_build (the one producer of
/// reduced bodies, as cbcheck's), its inertia invariants with the mass the modes come from
/// (docs/THEORY.md section 9); with stress, the modal stresses of its modes (the fe
/// description in the cb file carries the elements and the material).
/// @param[out] out caller destroys with fmbd_rflex_destroy
int fmbd_scene_rflex_from_cb(fmbd_h5 *f, bool stress, fmbd_rflex **out);

#endif
