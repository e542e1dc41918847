// common/fmbd_mbs.h: the multibody dynamics core of fmbd-run: rigid and reduced flexible
// (floating frame of reference) bodies, joints, drivers, loads, index-3 generalized-alpha
// SPDX-License-Identifier: MIT
//
// USE
//   fmbd_mbs *m; fmbd_mbs_create(&m);
//   fmbd_mbs_add_rigid / fmbd_mbs_add_flex -> body ids 0, 1, ...   (FMBD_MBS_GROUND = -1)
//   fmbd_mbs_add_point(m, body, ...)       -> point ids (points on ground allowed)
//   fmbd_mbs_add_joint(m, &joint_desc)     -> joint ids
//   fmbd_mbs_add_driver_joint / _body, fmbd_mbs_add_load, fmbd_mbs_set_gravity
//   fmbd_mbs_settings s; fmbd_mbs_settings_defaults(&s); ... ; fmbd_mbs_init(m, &s);
//   fmbd_mbs_run(m, callback, user)  (or fmbd_mbs_step in a loop), query functions;
//   fmbd_mbs_destroy(&m).
// Nothing may be added after fmbd_mbs_init. Names are copied. Every array argument is
// borrowed for the duration of the call and copied (FMBD_COPY) unless said otherwise.
// The library never prints except through fmbd_log (redundant constraints: WARN; steps: DEBUG).
//
// CONVENTIONS. SI units. 3x3 matrices are ROW-major (A[3*i + j] = A_ij, as in the scene and
// the fmbd-fe /body attribute). Modal arrays use the layout of fmbd_rflex (fmbd_rflex.h):
// first index fastest, so an fmbd_rflex's arrays can be passed as they are:
//   S1[a + 3k], XS[a + 3b + 9k], SS[a + 3b + 9k + 9 nm l], Mff/Kff[k + nm l],
//   point modal translation / rotation T[a + 3k] (3 x nm).
//
// EQUATIONS (docs/THEORY.md sections 4, 5; Shabana, Dynamics of Multibody Systems, 3rd ed. 2005,
// ch. 5 (floating frame) and ch. 7; Nikravesh, Computer-Aided Analysis of Mechanical
// Systems, 1988, ch. 6 (Euler parameters)).
//   Coordinates of body i: x_i = [R (3); p (4); q (nm)]: R the body-frame origin (world), p a
//   quaternion (Euler parameters e0, e1, e2, e3) with the normalisation constraint
//   (s/2)(p.p - 1) = 0 (s = a body inertia scale, for conditioning) in the constraint set,
//   q the modal coordinates (nm = 0 for a rigid body). Choice: Euler parameters with their
//   constraint rather than a Lie-group update, because the index-3 generalized-alpha scheme
//   of Arnold & Bruls then applies unchanged on a vector space (no tangent-operator or
//   rotation-interpolation approximations), all joint Jacobians are exact polynomials in p,
//   and there is no singular orientation; the cost is one extra coordinate and one extra
//   constraint per body. The rotation matrix A(p) is evaluated from p/|p| so that the
//   iterates off the unit sphere stay rotations.
//   A material point: r = R + A u, u = x0 + S(x0) q. Body-frame angular velocity
//   wb = 2 G(p) p' with G = [-e, -e~ + e0 I] (G p = 0, G G' = I, G(p') p' = 0), so
//   wb' = 2 G p''. Virtual rotation d(pi) = 2 G dp, hence the rotational equations are the
//   body-frame moment equations premultiplied by 2 G'.
//   Inertia from the invariants (docs/THEORY.md section 9, the "inertia shape integrals" of
//   Shabana):
//     c(q) = c0 + S1 q                                   (first moment, body frame)
//     J(q) = J0 + XSq + XSq' + sum_kl SS_kl q_k q_l  (second moment; (XSq)_ab = sum_k XS_abk q_k)
//     I(q) = tr(J) 1 - J                                  (inertia about the frame origin)
//     M_RR = m 1,  M_Rw = -A c~,  M_Rf = A S1,  M_ww = I(q),
//     M_wf[:,k] = int rho u x S_k = eps_abc (XS_bck + sum_l SS_bc,lk q_l),  M_ff = Mff.
//   Equations (D'Alembert with r'' = R'' + A[wb' x u + wb x (wb x u) + 2 wb x S q' + S q'']):
//     m R'' - A c~ wb' + A S1 q'' + A[wb x (wb x c) + 2 wb x S1 q']             = F
//     2G'{ c~ A' R'' + I wb' + M_wf q'' + wb x I wb + 2 (tr(H) 1 - H) wb - N }  + (Phi_p' lambda)
//     S1' A' R'' + M_wf' wb' + Mff q'' + h(wb, q, q') + Kff q + D q'              = Q_f
//   with H_ab = int rho (S q')_a u_b and h_k = wb' H_k wb - |wb|^2 tr(H_k) + 2 wb . sum_l q'_l
//   int rho S_l x S_k, H_k,ab = int rho S_k,a u_b; D = diag(2 zeta_k sqrt(K_kk)) modal
//   damping (zeta = damping ratio). A rigid body is the case nm = 0 with c0 = m com,
//   J0 = (tr(Ic)/2) 1 - Ic + m com com' (no flexible term is evaluated).
//   FULL FE BODIES (fmbd_mbs_add_fe; docs/THEORY.md section 4b): q = every FE dof the frame
//   does not fix, S_k the nodal interpolation of dof k; the same equations with the
//   invariants evaluated as sparse products with the nodal map E and the scalar nodal mass Mn
//   (never an n x n dense array), Mff, Kff, D the sparse FE matrices; the body's block in the
//   iteration matrix is [7 x 7, 7 x n coupling, n x n on the pattern of M + K + D].
//   Constraints Phi(x, t) = 0 of joints (below), drivers and normalisations:
//     M(x) x'' + Phi_x' lambda = Q(x, x', t),  Phi(x, t) = 0.                 [H8, C6]
// INTEGRATOR: generalized-alpha for the index-3 system in the form of Arnold & Bruls (2007,
//   Multibody Syst. Dyn. 18:185): the equations hold exactly at t_{n+1}; pseudo-accelerations
//   a with (1-am) a_{n+1} + am a_n = (1-af) x''_{n+1} + af x''_n; Newmark updates of x and x'
//   with a; Chung & Hulbert (1993) parameters am = (2 rho - 1)/(rho + 1), af = rho/(rho + 1),
//   gamma = 1/2 + af - am, beta = (gamma + 1/2)^2 / 4 from rho = rho_inf. Predictor: x''_{n+1}
//   extrapolated linearly from the last two steps, lambda_{n+1} = lambda_n. Newton on the
//   SCALED iteration matrix (Bottasso, Dopico & Trainelli 2008, Multibody Syst. Dyn. 19:3;
//   Bottasso, Bauchau & Cardona 2007, SIAM J. Sci. Comput. 29:397): rows of the dynamics
//   divided by beta' = (1-am)/(beta h^2 (1-af)), multipliers lambda = beta' lambda~:
//     [ M + (gamma'/beta') C_t + K_t/beta'   Phi_x' ] [ dx       ]   = -[ r / beta' ]
//     [ Phi_x                                0      ] [ dlambda~ ]      [ Phi       ]
//   gamma' = gamma/(beta h). Tangent: M exact (plus a mass mu p p' on the Euler parameters,
//   mu = snorm/4: it makes the block regular and leaves the physics unchanged since G p = 0;
//   the normalisation multiplier absorbs it); C_t the complete derivative of the quadratic
//   velocity vector with respect to [R', wb, q'] and the modal damping (FE bodies: the same,
//   with their damping D and gyroscopic block); K_t = Kff only.
//   Neglected (convergence is monitored every iteration): the derivatives with respect to x
//   of M x'', of the quadratic velocity vector, of gravity and loads (follower loads too), and
//   the geometric stiffness (Phi_x' lambda)_x; they carry a factor h^2 relative to M.
//   The residual's Phi_x' lambda: from the Jacobians where the matrix is formed, else from each
//   joint side's force and moments on its point and directions (the same sum, another order).
//   Sparse matrix (one dense (7+nm)^2 block per body, constraint rows on the coordinates of
//   their two bodies) in compressed columns, factored with KLU (SuiteSparse klu_l_*): the
//   symbolic analysis once at fmbd_mbs_init (AMD, with or without KLU's block triangular
//   form, whichever predicts the smaller factor: without, on these KKT matrices), the numeric
//   factor kept across iterations and steps while Newton converges (modified Newton); refactored
//   (klu_l_refactor with the old pivoting, full klu_l_factor if KLU's rcond estimate drops below
//   1e-13) when the contraction rate exceeds 0.1, when h differs by more than 25 % from the h of
//   the factor, and before retrying a step whose Newton failed with an old factor. Modal bodies
//   with at least 10 modes (not full FE bodies, not shared GM sets) have their modal coordinates
//   eliminated instead (fmbd_mbs_schur.c): their block's constant part cm Mff + cc Dff + ck Kff
//   by dense Cholesky once per step size, the rest (frames, other bodies, constraint rows) by
//   KLU on the Schur complement; the modal block's gyroscopic part is left out of the matrix
//   (the residual keeps it). Environment FMBD_MBS_SCHUR=0 / 1 forces the whole-matrix KLU /
//   the elimination of every modal body.
// NEWTON convergence: with theta the contraction rate of successive increments, stop when
//   max_i |dx_i|/tx_i <= 1 and theta/(1-theta) max_i |dx_i|/tx_i <= 1 (Hairer & Wanner II,
//   IV.8), or |dx_i| <= 1e-3 tx_i in the first iteration, or |dx_i| <= tx_i with theta >= 1
//   (round-off stagnation); or (the early stop, from the third iteration on) when theta <= 0.1
//   and theta/(1-theta) max_i |dx_i|/tx_i <= 1 and the same holds for the multipliers'
//   increments (lambda = beta' y) measured in ty_k = max(min_i A_ii tx_i / |J_ki|, 1e3 eps
//   |lambda_k| / beta'), i over the coordinates of equation k whose diagonal A_ii of the
//   iteration matrix is formed (the force that moves each of them by its tolerance), where
//   tx_i = max(newton_tol min(nscale_i, ascale_i/beta'), 1e3 eps max(|x_i|, rscale_i)),
//   rscale_i = nscale_i for R, max(1, L_ref / (2 gyr)) for Euler parameters (gyr: the body's
//   radius of gyration; R's floor in displacement), L_ref (L_ref sqrt(m) for modal
//   coordinates) for elastic ones, which the constraints' round-off reaches via the frame:
//   newton_tol is relative to the size of the coordinate AND of its acceleration (an error
//   dx in x is an error beta' dx in x''; bounding only dx leaves a spurious force that, at
//   small steps, spoils momentum and energy conservation). nscale_i = L_ref for positions, 1
//   for Euler parameters, max(largest modal amplitude of the body, 1e-3 L_ref sqrt(m)) for
//   modal coordinates; ascale_i = the largest |x''_i| seen (modal: per body), at least
//   nscale_i / t_end^2.
// STEP-SIZE CONTROL (variable steps): local error estimate of the Newmark-type position
//   update (Geradin & Cardona, Flexible Multibody Dynamics, 2001, ch. 11; Zienkiewicz & Xie
//   1991): e_i = h^2 |beta - 1/6| |a_{n+1,i} - a_{n,i}|, tested as max_i e_i/(tol s_i) <= 1,
//   s_i = max(largest |x_i| seen, floor_i); floors 1e-3 L_ref (positions), 1e-3 (Euler
//   parameters), 1e-5 L_ref sqrt(m) (modal: deformations below 1e-5 L_ref do not tighten the
//   test); all modal coordinates of a body share the body's largest modal amplitude as s_i.
//   L_ref = the size of the system (largest distance of a body or point from the origin,
//   with the bodies' gyration radii). A failed test rejects the step and retries with
//   h max(0.2, 0.9 err^(-1/3)); after an accepted step h becomes h * 0.9 err^(-1/3), limited
//   to [0.2, 2], kept unchanged for ratios in [0.85, 1.25] (the factor stays valid) and not
//   increased right after a rejection (Hairer, Norsett & Wanner I, II.4), then clipped to
//   [min_step, max_step]. A Newton failure divides h by 4; at min_step the run fails with
//   FMBD_ERR_CONVERGE naming the time, the step, the equation (joint or driver equation,
//   or a body's translational / rotational / modal equation of motion) with the largest
//   scaled residual in the last iteration and the coordinate with the largest correction
//   (near a singular configuration the residuals are small and the corrections blow up).
//   Fixed steps: h = step always (divided by 4 only after a Newton failure, then back to
//   step), no error test.
// INITIAL CONDITIONS (fmbd_mbs_init): redundant constraint equations (joints and drivers) are
//   found at the initial configuration by QR with column pivoting (LAPACK dgeqp3) of Phi_x'
//   with unit-normalised rows (the Euler-parameter direction projected out), rank from
//   |R_kk| > 1e-8 |R_11|; the equations dropped are chosen greedily in the order joints were
//   added (Gram-Schmidt), so that the joint closing a loop loses its dependent equations;
//   they are removed from the system (fmbd_log WARN naming them; fmbd_mbs_redundant) and must
//   still hold after the projection, else the assembly is inconsistent (FMBD_ERR_CONVERGE).
//   With shared modal coordinates (fmbd_mbs_share_modal) an equation dependent on the frame
//   coordinates alone is removed too (global modes cannot keep it independent: fmbd_mbs_init.c).
//   Positions are projected onto Phi = 0 by minimum-change Newton steps in the mass metric,
//   velocities onto Phi_x x' + Phi_t = 0 (mass-weighted least change), and consistent
//   accelerations and multipliers solved from [M Phi_x'; Phi_x 0] with the right-hand side
//   -(Phi_x x')_x x' - Phi_tt (a central difference of Phi_x x' along x', error O(eps^2)).
//
// JOINTS between point P1 (side 1) and P2 (side 2); a point on FMBD_MBS_GROUND is fixed in
// the world. Axes are given in WORLD coordinates at the initial configuration and attached
// to each side's body there (for a flexible body the point's frame also turns with the
// modal rotation Psi_r q, linearised). With z the axis and (x, y) a right-handed pair
// normal to it, identical on both sides at assembly (x from ref if given, else chosen),
// d = r2 - r1:
//   SPHERICAL   r1 = r2                                     3 equations
//   REVOLUTE    r1 = r2, z1.x2 = 0, z1.y2 = 0               5   coordinate: angle x1 -> x2 about z1
//   UNIVERSAL   r1 = r2, a1.a2 = 0 (axis on 1, axis2 on 2)   4
//   CYLINDRICAL z1.x2 = 0, z1.y2 = 0, d.x1 = 0, d.y1 = 0    4   coordinate: d.z1 (m)
//   PRISMATIC   cylindrical + x1.y2 = 0                     5   coordinate: d.z1 (m)
//   FIXED       r1 = r2, z1.x2 = 0, z1.y2 = 0, x1.y2 = 0    6
// Equation names in messages: "joint 'J' equation k (meaning)", k from 1.
//
// LIMITS. Linear floating-frame model: no geometric (centrifugal) stiffening of the modes, so
// fast-spinning slender bodies are too soft; the rotation of a flexible attachment point is
// the linearised modal rotation. Index 3: velocity constraints hold only to O(h^2).
// Redundancy is decided once, at the initial configuration, with dense factorisations of
// the n x m Jacobian (O(n m^2): fine for a few hundred bodies). KLU allocates outside
// fmbd_malloc (the allocation countdown of the tests does not reach it).
// Not in this module: file I/O, stress recovery (from fmbd_mbs_modal and the body's modal
// stress), outputs at points other than those added here.
#ifndef FMBD_MBS_H
#define FMBD_MBS_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"

typedef struct fmbd_mbs fmbd_mbs;

/// The ground "body" id.
#define FMBD_MBS_GROUND (-1)

// --- functions of time -------------------------------------------------------------------
enum fmbd_mbs_fn_kind {
  FMBD_MBS_FN_CONSTANT = 0,  ///< value
  FMBD_MBS_FN_RAMP,          ///< v0 until t0, linear (smooth: 3s^2 - 2s^3) to v1 at t1, v1 after
  FMBD_MBS_FN_SINE,          ///< offset + amplitude sin(2 pi frequency_hz t + phase)
  FMBD_MBS_FN_TABLE,         ///< piecewise linear through (t[i], v[i]), constant outside
  FMBD_MBS_FN_LINEAR,        ///< v0 + rate (t - t0) for all t (a constant-speed driver)
  FMBD_MBS_FN_SPINUP,        ///< v0 until t0, speed rising smoothly from 0 to rate over t1 - t0
                             ///< (Kane, Ryan and Banerjee 1987), then v0 + rate (t - (t0 + t1) / 2)
};
/// A scalar function of time. Build it with the fmbd_mbs_fn_* helpers or by hand.
typedef struct fmbd_mbs_fn {
  int kind;               ///< fmbd_mbs_fn_kind
  double value;           ///< CONSTANT
  double t0, t1, v0, v1;  ///< RAMP (t1 > t0); LINEAR uses t0, v0; SPINUP t0, t1 (> t0), v0
  bool smooth;            ///< RAMP: C1 cubic blend
  double rate;            ///< LINEAR: slope; SPINUP: final speed (unit/s)
  double amplitude, frequency_hz, phase, offset;  ///< SINE
  int64_t n;                                      ///< TABLE: points (>= 1), t strictly increasing
  const double *t, *v;  ///< TABLE: borrowed here; the mbs copies them when added
} fmbd_mbs_fn;

/// @brief f(t) and its first and second derivatives (dfdt, d2fdt2 may be NULL). Piecewise
/// functions give the right-hand derivative at a kink.
double fmbd_mbs_fn_eval(const fmbd_mbs_fn *f, double t, double *dfdt, double *d2fdt2);
/// @brief Helpers returning a filled fmbd_mbs_fn.
fmbd_mbs_fn fmbd_mbs_fn_constant(double value);
fmbd_mbs_fn fmbd_mbs_fn_linear(double t0, double v0, double rate);
fmbd_mbs_fn fmbd_mbs_fn_ramp(double t0, double v0, double t1, double v1, bool smooth);
fmbd_mbs_fn fmbd_mbs_fn_sine(double offset, double amplitude, double frequency_hz, double phase);
fmbd_mbs_fn fmbd_mbs_fn_table(int64_t n, const double *t, const double *v);
fmbd_mbs_fn fmbd_mbs_fn_spinup(double t0, double v0, double t1, double speed);

// --- bodies ------------------------------------------------------------------------------
/// Initial state of a body (world frame).
typedef struct fmbd_mbs_state0 {
  double position[3];          ///< body-frame origin R
  double rotation[9];          ///< body -> world, row-major, orthonormal (checked to 1e-6)
  double velocity[3];          ///< of the body-frame origin
  double angular_velocity[3];  ///< world components
} fmbd_mbs_state0;
/// @brief Identity rotation, zero position and velocities.
fmbd_mbs_state0 fmbd_mbs_state0_default(void);

/// The invariants of a modal flexible body (docs/THEORY.md section 9), in fmbd_rflex's layout.
typedef struct fmbd_mbs_flex_data {
  int64_t nm;               ///< number of modes (>= 0)
  double mass;              ///< m > 0
  double first_moment[3];   ///< c0 = int rho x0 dV
  double second_moment[9];  ///< J0 (symmetric)
  const double *S1;         ///< 3 x nm: S1[a + 3k]
  const double *XS;         ///< 3 x 3 x nm: XS[a + 3b + 9k] = int rho x0_a S_k,b
  const double *SS;         ///< 3 x 3 x nm x nm: SS[a + 3b + 9k + 9 nm l] = int rho S_k,a S_l,b
  const double *Mff;        ///< nm x nm (symmetric positive definite; semidefinite allowed with
                            ///< shared, the set's sum is checked by fmbd_mbs_init)
  const double *Kff;        ///< nm x nm (symmetric positive semidefinite)
  double damping_ratio;     ///< modal damping ratio zeta of every mode (0: none)
  const double *q0, *qd0;   ///< initial modal coordinates and rates (nm each; NULL: zero)
  bool shared;              ///< the body will join a set of fmbd_mbs_share_modal
  bool partial_coupling;    ///< inertia coupling "partial" (MSC Adams/Flex's partial coupling,
                            ///< docs/THEORY.md section 4c): SS taken as zero, so the inertia
                            ///< terms of second order in the modes (SS q, SSx q') vanish
} fmbd_mbs_flex_data;

/// A full finite-element body (docs/THEORY.md section 4b): every FE dof that the frame does
/// not fix is a coordinate (nm = n), in the floating frame of reference. All matrices are
/// sparse and copied; nothing of size n x n is ever dense. The inertia invariants are
/// evaluated on the fly from a scalar nodal mass Mn and the map E from the coordinates to the
/// nodal translations (THEORY 4b): S1 q = 1' Mn U, XS q = x' Mn U, SS q q = U' Mn U with
/// U = E q (U_a: the a components of all nodes).
typedef struct fmbd_mbs_fe_data {
  int64_t n;                ///< coordinates (FE dofs not fixed by the frame), >= 1
  double mass;              ///< m > 0
  double first_moment[3];   ///< c0 = int rho x0 dV
  double second_moment[9];  ///< J0 (symmetric)
  const fmbd_csr *M, *K;    ///< n x n mass and stiffness (full symmetric storage)
  const fmbd_csr *D;        ///< n x n damping (full symmetric storage) or NULL
  int64_t nnodes;           ///< nodes of the body
  const double *node_xyz;   ///< 3 x nnodes reference positions (body frame), xyz[a + 3p]
  const fmbd_csr *Mn;       ///< nnodes x nnodes scalar mass of the invariants (symmetric)
  const fmbd_csr *E;        ///< (3 nnodes) x n: row a nnodes + p = translation a of node p
  const int64_t *dofs;      ///< 2 x n: node and direction (0..5) of each coordinate, or NULL
                            ///< (names in messages)
  /// the rigid-flexible coupling from a mass Mn does not reproduce (beam elements, whose
  /// consistent mass couples translations and rotations; docs/THEORY.md section 4b), or NULL
  /// (from Mn): S1[a + 3k] = T_a' M S_k and Mw0[a + 3k] = R_a' M S_k (M_wf at q = 0), 3 x n
  /// each, both or neither
  const double *S1, *Mw0;
  const double *q0, *qd0;  ///< initial coordinates and rates (n each; NULL: zero)
} fmbd_mbs_fe_data;

/// @brief Create an empty system (no gravity).
/// @param[out] out caller destroys with fmbd_mbs_destroy
int fmbd_mbs_create(fmbd_mbs **out);
/// @brief Release the system; NULL fine; sets *m = NULL.
void fmbd_mbs_destroy(fmbd_mbs **m);

/// @brief Add a rigid body.
/// @param[in] name    unique body name (messages)
/// @param[in] mass    kg, > 0
/// @param[in] com     centre of mass, body frame
/// @param[in] inertia 3x3 row-major about the centre of mass, body frame (symmetric, positive
///                    definite; checked)
/// @param[in] s0      initial state
/// @param[out] id     body id (may be NULL)
/// @return FMBD_OK, FMBD_ERR_VALUE (bad numbers, duplicate name), FMBD_ERR_NOMEM
int fmbd_mbs_add_rigid(fmbd_mbs *m, const char *name, double mass, const double com[3],
                       const double inertia[9], const fmbd_mbs_state0 *s0, int *id);
/// @brief Add a flexible body (modal, floating frame). d's arrays are copied.
/// @return FMBD_OK, FMBD_ERR_VALUE (mass <= 0, Mff not positive definite, ...), FMBD_ERR_NOMEM
int fmbd_mbs_add_flex(fmbd_mbs *m, const char *name, const fmbd_mbs_flex_data *d,
                      const fmbd_mbs_state0 *s0, int *id);

/// @brief Shared modal coordinates (the GMs basis of global modes, Cammarata 2021; docs/THEORY.md
/// section 6): the modal bodies `ids` (added with d.shared, all with the same nm >= 1) use ONE
/// set of nm elastic coordinates. Each body adds its mass, stiffness, damping, quadratic
/// velocity and load terms and its joints' constraint rows into the same columns, so the
/// system has 7 per body plus nm coordinates for the set. fmbd_mbs_init checks the summed
/// elastic mass block (with the frames fixed) is positive definite; initial modal coordinates
/// are the first body's. fmbd_mbs_linearise refuses such a model.
/// @return FMBD_OK, FMBD_ERR_VALUE (after init, not modal, nm differs, already shared)
int fmbd_mbs_share_modal(fmbd_mbs *m, int nids, const int *ids);

/// @brief Add a full FE body (fmbd_mbs_fe_data). Its points (fmbd_mbs_add_point) take T and
/// Rot as for a modal body (3 x n); only their nonzero columns are kept, so a point's
/// equations touch only the coordinates that move it.
/// @return FMBD_OK, FMBD_ERR_VALUE (sizes, mass, non-finite values), FMBD_ERR_NOMEM
int fmbd_mbs_add_fe(fmbd_mbs *m, const char *name, const fmbd_mbs_fe_data *d,
                    const fmbd_mbs_state0 *s0, int *id);

/// @brief Add a point (joint attachment, load point, output point) on a body.
/// @param[in] body  body id or FMBD_MBS_GROUND
/// @param[in] x0    position in the body frame (world for ground)
/// @param[in] T     modal translation 3 x nm (T[a + 3k]) or NULL (zero; rigid bodies: ignored)
/// @param[in] Rot   modal rotation 3 x nm or NULL (zero)
/// @param[out] pid  point id
int fmbd_mbs_add_point(fmbd_mbs *m, int body, const double x0[3], const double *T,
                       const double *Rot, int *pid);
/// @brief Add a point on a body given by its WORLD position at the initial configuration
/// (rigid bodies, or flexible bodies when modal motion is not wanted at the point).
int fmbd_mbs_add_point_world(fmbd_mbs *m, int body, const double xw[3], int *pid);

// --- joints ------------------------------------------------------------------------------
enum fmbd_mbs_joint_kind {
  FMBD_MBS_SPHERICAL = 0,
  FMBD_MBS_REVOLUTE,
  FMBD_MBS_UNIVERSAL,
  FMBD_MBS_PRISMATIC,
  FMBD_MBS_CYLINDRICAL,
  FMBD_MBS_FIXED,
};
typedef struct fmbd_mbs_joint_desc {
  const char *name;  ///< unique joint name (messages)
  int kind;          ///< fmbd_mbs_joint_kind
  int point[2];      ///< point ids of side 1 and side 2 (different bodies)
  double axis[3];    ///< world, initial configuration: revolute/prismatic/cylindrical axis,
                     ///< universal: the cross axis fixed on side 1; fixed: optional (0 = z)
  double axis2[3];   ///< universal: the cross axis fixed on side 2 (orthogonal to axis)
  double ref[3];     ///< optional reference direction normal to axis (zero vector = chosen),
                     ///< the zero of a revolute angle
} fmbd_mbs_joint_desc;
/// @brief Add a joint. The points need not coincide now (fmbd_mbs_init assembles).
/// @return FMBD_OK, FMBD_ERR_VALUE (unknown point, same body on both sides, zero or non
/// orthogonal axes), FMBD_ERR_NOMEM
int fmbd_mbs_add_joint(fmbd_mbs *m, const fmbd_mbs_joint_desc *j, int *jid);
/// @brief The number of equations of a joint kind (3, 5, 4, 5, 4, 6), -1 if unknown.
int fmbd_mbs_joint_equations(int kind);

// --- drivers and loads -------------------------------------------------------------------
/// @brief Prescribe a joint coordinate: revolute angle (rad, 0 at the initial configuration),
/// prismatic or cylindrical slide d.z1 (m, the initial value at the initial configuration;
/// the driver's f gives the absolute value). The fn is copied.
int fmbd_mbs_add_driver_joint(fmbd_mbs *m, const char *name, int joint, const fmbd_mbs_fn *f,
                              int *did);
/// @brief Prescribe a body coordinate: 0..2 = x, y, z of the body-frame origin (world);
/// 3 + k = modal coordinate k of a flexible body.
int fmbd_mbs_add_driver_body(fmbd_mbs *m, const char *name, int body, int coordinate,
                             const fmbd_mbs_fn *f, int *did);

enum fmbd_mbs_load_kind { FMBD_MBS_FORCE = 0, FMBD_MBS_TORQUE };
/// @brief Apply a force at a point or a torque on the point's body (through the point's
/// rotation for a flexible body): load = direction * f(t), direction in the world frame or,
/// with body_frame, in the body frame (a follower load; its derivative is not in the tangent).
/// Loads on ground points are refused.
int fmbd_mbs_add_load(fmbd_mbs *m, const char *name, int kind, int point, bool body_frame,
                      const double direction[3], const fmbd_mbs_fn *f, int *lid);
/// @brief Uniform gravity (m/s^2, world), default zero.
void fmbd_mbs_set_gravity(fmbd_mbs *m, const double g[3]);

// --- solver ------------------------------------------------------------------------------
typedef struct fmbd_mbs_settings {
  double t_end;         ///< end time (s), default 1
  double rho_inf;       ///< spectral radius at infinity in [0, 1], default 0.9
  bool fixed;           ///< fixed step `step` (default false: variable steps)
  double step;          ///< fixed step (s), default 1e-3
  double first_step;    ///< variable: first step, default 1e-6 (paper [H])
  double min_step;      ///< variable: smallest step, default 1e-12
  double max_step;      ///< variable: largest step, default 1e-2 (paper [H])
  double tolerance;     ///< variable: local error tolerance (relative to s_i, STEP-SIZE), 1e-4
  double newton_tol;    ///< Newton tolerance, relative to coordinate and acceleration sizes
                        ///< (see NEWTON), default 1e-8
  int newton_max;       ///< Newton iterations per attempt, default 10
  double output_every;  ///< > 0: steps end exactly on multiples of it (callback flag), default 0
  bool reactions;       ///< the caller will ask for joint reactions (they are computed on
                        ///< query from the multipliers, which are always kept), default false
  int64_t max_steps;    ///< stop with FMBD_ERR_CONVERGE after so many steps (0 = none)
  bool linearise_only;  ///< fmbd_mbs_init stops after the redundancy check and the matrix
                        ///< pattern: the state is the initial coordinates as given (not
                        ///< projected), no velocities, accelerations or multipliers, and no
                        ///< factorisation of [M Cq'; Cq 0] (hours and tens of GB for a 270 k-dof
                        ///< FE body). For callers that linearise at a configuration they make
                        ///< consistent themselves (gmsolve), then check the removed equations
                        ///< with fmbd_mbs_check_removed. fmbd_mbs_step and the joint reactions
                        ///< refuse such a model. Default false
} fmbd_mbs_settings;
/// @brief Fill the documented defaults.
void fmbd_mbs_settings_defaults(fmbd_mbs_settings *s);

/// @brief Prepare the run: check the settings, remove redundant constraints, make the
/// initial conditions consistent (positions, velocities, accelerations, multipliers; none
/// with s->linearise_only), build the sparse pattern and its KLU symbolic analysis.
/// @return FMBD_OK; FMBD_ERR_VALUE (settings, no bodies); FMBD_ERR_CONVERGE (positions cannot
/// be projected: the message names the worst joint equation); FMBD_ERR_SINGULAR (singular
/// mass matrix or constraint system: names the body); FMBD_ERR_EXTERNAL (KLU); NOMEM
int fmbd_mbs_init(fmbd_mbs *m, const fmbd_mbs_settings *s);

/// @brief Advance one accepted step (rejections and Newton retries inside), not past t_end.
/// @param[out] at_output true when the step ended on an output instant (or output_every = 0)
/// @return FMBD_OK; 1 when t_end was already reached (nothing done); FMBD_ERR_CONVERGE
/// (Newton failure at the smallest step: "t = T s, h = H s: Newton did not converge;
/// largest residual: joint 'J' equation k (...) (scaled residual R); largest correction:
/// body 'B' coordinate ..."; the residual may also be a driver's or a body's equation of
/// motion);
/// FMBD_ERR_SINGULAR (a singular iteration matrix at the smallest step; at larger steps a
/// singular matrix at a Newton iterate rejects the attempt and the step shrinks); at the
/// smallest step, constraint rows dependent at the last accepted state (a dead point) give
/// FMBD_ERR_CONVERGE naming their joints and drivers; FMBD_ERR_EXTERNAL. After an error the
/// state is that of the last accepted step (queries still work, e.g. to keep a run's valid
/// prefix).
int fmbd_mbs_step(fmbd_mbs *m, bool *at_output);

/// Called after every accepted step; return nonzero to stop the run (fmbd_mbs_run returns
/// that value).
typedef int (*fmbd_mbs_callback)(fmbd_mbs *m, bool at_output, void *user);
/// @brief Run to t_end, calling cb (may be NULL) after each accepted step. The initial state
/// is not reported (query it after fmbd_mbs_init).
int fmbd_mbs_run(fmbd_mbs *m, fmbd_mbs_callback cb, void *user);

// --- queries (after fmbd_mbs_init) ---------------------------------------------------------
double fmbd_mbs_time(const fmbd_mbs *m);
int fmbd_mbs_nbodies(const fmbd_mbs *m);
int fmbd_mbs_body_nm(const fmbd_mbs *m, int body);
/// @brief Body id by name, or -1.
int fmbd_mbs_find_body(const fmbd_mbs *m, const char *name);
/// @brief World position, velocity, acceleration of a point (includes modal motion).
void fmbd_mbs_point_position(const fmbd_mbs *m, int pid, double x[3]);
void fmbd_mbs_point_velocity(const fmbd_mbs *m, int pid, double v[3]);
void fmbd_mbs_point_acceleration(const fmbd_mbs *m, int pid, double a[3]);
/// @brief Pose of a body: R (may be NULL), rotation body -> world row-major (may be NULL).
void fmbd_mbs_body_pose(const fmbd_mbs *m, int body, double R[3], double A[9]);
/// @brief Velocity of the body origin and angular velocity (world); either may be NULL.
void fmbd_mbs_body_velocity(const fmbd_mbs *m, int body, double v[3], double w[3]);
/// @brief Modal coordinates, rates, accelerations of a body (borrowed, valid until the next
/// step; NULL pointers allowed). @return nm
int64_t fmbd_mbs_modal(const fmbd_mbs *m, int body, const double **q, const double **qd,
                       const double **qdd);
/// @brief Kinetic energy, gravity potential (-m g.r_com summed, zero at the origin), strain
/// energy (1/2 q'Kq); any pointer may be NULL.
void fmbd_mbs_energy(const fmbd_mbs *m, double *kinetic, double *potential, double *strain);
/// @brief Total linear momentum and angular momentum about the world origin (any NULL).
void fmbd_mbs_momentum(const fmbd_mbs *m, double L[3], double H[3]);
/// @brief Reaction of a joint: the force and torque the joint (with a driver acting on it)
/// applies to the body of side 1, torque about its point P1 (world). If side 1 is ground:
/// minus those applied to side 2, torque about P2. From the multipliers: the force is the R
/// part of the generalized constraint force -Phi_x' lambda of that body, the torque its
/// orientation part (N = G Q_p / 2, body frame) moved from the body origin to the point (on
/// a flexible body the deformed point position is used, so the result is the load at the
/// point itself). Redundant equations removed carry zero (their share of the load is
/// carried by the equations kept).
/// @return FMBD_OK; FMBD_ERR_VALUE (bad id, before fmbd_mbs_init)
int fmbd_mbs_joint_reaction(const fmbd_mbs *m, int joint, double F[3], double T[3]);
/// @brief The current value of a joint coordinate (revolute angle, slide) and its rate.
int fmbd_mbs_joint_coordinate(const fmbd_mbs *m, int joint, double *value, double *rate);
/// @brief Largest |Phi| over the position constraints (m or rad-like) and over the velocity
/// constraints |Phi_x x' + Phi_t| (either may be NULL), joints and drivers only.
void fmbd_mbs_constraint_residual(const fmbd_mbs *m, double *pos, double *vel);

typedef struct fmbd_mbs_stats {
  int64_t steps;     ///< accepted steps
  int64_t rejected;  ///< rejected steps (error test) + Newton failures
  int64_t newton_iterations;
  int64_t factorizations;  ///< numeric factorizations (klu factor + refactor)
  int64_t coordinates;     ///< size of x
  int64_t equations;       ///< constraint equations kept (incl. normalisations)
  int64_t redundant;       ///< constraint equations removed as redundant
  double h_last;           ///< last accepted step (s)
  // CPU time (s) of the time steps' Newton iterations, split three ways: the iteration
  // matrix's factorisations, the solves with it, and the rest of the loop (the system
  // evaluation: residual and matrix, with the O(n) residual scaling and updates around it);
  // measured as wall time scaled by the CPU share of the wall time of each window of 8 steps
  double factor_cpu_s, solve_cpu_s, eval_cpu_s;
} fmbd_mbs_stats;
void fmbd_mbs_get_stats(const fmbd_mbs *m, fmbd_mbs_stats *s);

/// @brief The k-th redundant equation found by fmbd_mbs_init (k < stats.redundant).
/// @param[out] joint joint id (-1 for a driver); eq 1-based equation of the joint;
/// @param[out] text  borrowed "joint 'J' equation k (meaning)"
int fmbd_mbs_redundant(const fmbd_mbs *m, int k, int *joint, int *eq, const char **text);

// --- rotation helpers ----------------------------------------------------------------------
/// @brief Rotation matrix (row-major) of the rotation by angle (rad) about axis (any length > 0).
void fmbd_mbs_rotation_axis_angle(const double axis[3], double angle, double A[9]);
/// @brief Rotation matrix (row-major) of the Euler parameters p = (e0, e1, e2, e3), evaluated at
/// p/|p| as the integrator does (body -> world; Nikravesh 1988, eq. 6.19).
void fmbd_mbs_rotation_quat(const double p[4], double A[9]);

// --- the mechanism's equations outside the integrator (for linearisation, global modes) ---
/// The equations of motion linearised at a state, M x'' + C x' + K x = Q (the terms the
/// iteration matrix uses; position-dependent force terms are dropped by design, as there),
/// and the kept constraint equations Phi(x, t) = 0 with their Jacobian Cq. Sparse: M, C, K are
/// block diagonal by body (dense n_i x n_i blocks, n_i = 7 + modes), Cq has one row per kept
/// equation with the coordinates of its one or two bodies; a 100 k-coordinate mechanism stays
/// sparse. Coordinates as everywhere in fmbd_mbs: per body R (3), Euler parameters p (4),
/// modal q. M holds PMASS-regularised inertia in the p direction (mu p p', the direction the
/// normalisation equation removes: on the constraints' null space it plays no role).
typedef struct fmbd_mbs_linear {
  int64_t n;     ///< coordinates
  int64_t nc;    ///< kept constraint equations (redundant ones removed at init)
  fmbd_csr *M;   ///< n x n mass matrix
  fmbd_csr *C;   ///< n x n velocity tangent (gyroscopic, Coriolis, modal damping)
  fmbd_csr *K;   ///< n x n tangent stiffness (modal Kff; the rest dropped by design)
  fmbd_csr *Cq;  ///< nc x n constraint Jacobian (joints, drivers, normalisations)
  double *Q;     ///< (n) generalized forces at zero accelerations (gravity, loads,
                 ///< elastic, quadratic velocity terms): -(residual at x'' = 0)
  double *phi;   ///< (nc) the constraint values Phi(x, t)
  int64_t *eq;   ///< (nc) index of each row among all equations (for names, as
                 ///< fmbd_mbs_redundant numbers them)
} fmbd_mbs_linear;

/// @brief Evaluate the linearised equations at state (x, xd) and time t (x, xd NULL: the
/// model's current state, e.g. the initial configuration projected onto the constraints by
/// fmbd_mbs_init). The model's state is left unchanged. Needs fmbd_mbs_init.
/// @param[in] x, xd (n) or NULL, borrowed
/// @param[out] L filled; release with fmbd_mbs_linear_free
/// @return FMBD_OK, FMBD_ERR_VALUE (not initialised), FMBD_ERR_NOMEM
int fmbd_mbs_linearise(fmbd_mbs *m, double t, const double *x, const double *xd,
                       fmbd_mbs_linear *L);
/// @brief Release the arrays of L (L itself is the caller's); zeroes it. NULL is fine.
void fmbd_mbs_linear_free(fmbd_mbs_linear *L);
/// @brief Check that the equations fmbd_mbs_init removed as redundant hold at (x, t) as they
/// must at a consistent configuration (scaled residual <= 1e-8, fmbd_mbs_init's test): dependent
/// to first order but violated means an inconsistent assembly (two ball joints too far apart
/// on one rod). For a model initialised with linearise_only, at the configuration the caller
/// made consistent. The model's state is left unchanged.
/// @param[in] x (n) or NULL (the model's state), borrowed
/// @return FMBD_OK; FMBD_ERR_CONVERGE (names the equation); FMBD_ERR_VALUE (not initialised)
int fmbd_mbs_check_removed(fmbd_mbs *m, double t, const double *x);
/// @brief Number of coordinates n (after fmbd_mbs_init), and the current state x (n, borrowed).
int64_t fmbd_mbs_ncoordinates(const fmbd_mbs *m);
const double *fmbd_mbs_state(const fmbd_mbs *m);

#endif
