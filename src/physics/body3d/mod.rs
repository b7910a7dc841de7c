//! # 3-D articulated rigid-body trees with a floating base
//!
//! A [`Tree3d`] is a tree of rigid bodies: body 0, the root, moves freely in space
//! ([`Joint3d::Free`]); every other body hangs from an earlier one on a ball joint
//! ([`Joint3d::Ball`]) or a revolute joint about an arbitrary unit axis
//! ([`Joint3d::Revolute`]). Each body has a mass, a centre of mass and a full (non-diagonal)
//! inertia tensor; each non-root joint has viscous damping and, optionally, motors (controls).
//! The ground's penalty contact ([`crate::physics::ground`], the law the planar bodies use)
//! acts on named points of the bodies through [`OnGround3d`] ([`mod@contact`]).
//! [`chain3d()`] is the small test model checked against MuJoCo.
//!
//! ## Conventions
//! - World frame z up; gravity g along −z.
//! - Quaternions are (w, x, y, z), Hamilton product, rotating body coordinates into parent
//!   (for the root: world) coordinates.
//! - State `x = [q, v]`: all position coordinates, then all velocity coordinates, body by body
//!   in tree order, MuJoCo's `qpos` and `qvel` exactly. The root contributes its origin p (m,
//!   world) and quaternion to q, and ṗ (m/s, **world** coordinates) then ω (rad/s, **body**
//!   coordinates) to v, MuJoCo's free-joint convention; a ball contributes its quaternion
//!   relative to its joint frame and its relative angular velocity in **its own body's**
//!   coordinates; a revolute joint its angle and rate.
//! - Quaternion kinematics in the body-frame convention: q̇ = ½ q ⊗ (0, ω), ω in the rotated
//!   (child) frame. Since q · q̇ = 0 the exact flow keeps |q|; the dynamics read only q / |q|
//!   (a zero quaternion reads as the identity), so a drift of |q| never feeds back. RK4 lets
//!   |q| drift by O(dt⁴) (below 1e-12 over 2 s of `chain3d` at its 1 ms step);
//!   [`Tree3d::normalize_state`] projects back when a caller wants to. Because nq ≠ nv the
//!   model has no `position_dim`: semi-implicit Euler does not apply, every other integrator
//!   does.
//! - Spatial vectors follow Featherstone: motion `[ω; v]`, force `[n; f]`, each body's in its
//!   own coordinates ([`spatial`]).
//!
//! ## Equations
//! Body i with parent λ(i) is placed by ⁱX_λ = X_J(q_i) X_T: X_T the fixed offset and joint-frame
//! rotation, X_J the joint's rotation (for the root, the whole pose). Its motion subspace S_i
//! (6 × n_i) maps joint velocities to relative spatial velocity: [e_k; 0] for a ball's three
//! body axes, [a; 0] for a revolute axis a, and for the root S = [0, 1; Rᵀ, 0] (world ṗ,
//! body ω), whose linear columns turn with the body: S̊ q̇ = [0; −ω × Rᵀ ṗ].
//!
//! - velocities: v_i = ⁱX_λ v_λ + S_i q̇_i, with v_world = 0;
//! - velocity-product accelerations: c_i = v_i ×ₘ S_i q̇_i + S̊_i q̇_i;
//! - bias forces C(q, q̇) (Coriolis, centrifugal, gravity) by the recursive Newton–Euler
//!   algorithm with q̈ = 0 and gravity as a fictitious base acceleration a_world = [0; 0, 0, g]:
//!   a_i = ⁱX_λ a_λ + c_i, f_i = I_i a_i + v_i ×* I_i v_i, then from the leaves
//!   C_i = S_iᵀ f_i, f_λ += ⁱX_λᵀ f_i;
//! - the joint-space inertia H(q) by the composite-rigid-body algorithm: I^c_i = I_i +
//!   Σ_children ᶜX_iᵀ I^c_c ᶜX_i, H_ii = S_iᵀ I^c_i S_i, and H_ji = S_jᵀ (ⁱX_jᵀ I^c_i S_i)
//!   for every ancestor j of i;
//! - forward dynamics: H v̇ = τ − D q̇ − C, τ the motor torques and D the joint damping
//!   (the root is neither damped nor driven), solved by Cholesky (H is symmetric positive
//!   definite).
//!
//! Everything lives in fixed arrays ([`tree::MAX_BODIES`], [`tree::MAX_DOF`]): `derivative`
//! never allocates. O(n²) for H and O(n³) for the solve, negligible at these sizes.
//!
//! ## Checks
//! `scripts/mujoco/chain3d.py` builds `chain3d` in MuJoCo from `motionlab describe chain3d` and
//! stores three 2 s RK4 trajectories (1 ms step) in `tests/data/chain3d/`; the tests in
//! [`mod@chain3d`] replay them and agree to about 1e-11 rad in every joint angle. MuJoCo's RK4
//! moves quaternions on the manifold (second order when ω turns), ours steps q̇ in R⁴ (fourth
//! order); at this step both sit within 3e-11 rad of the converged solution, which the
//! script measures (`--converge`). The tests in [`dynamics`] check energy conservation and its
//! RK4 order, the power balance of torques and damping, momentum conservation without gravity,
//! quaternion rates, point velocities against finite differences, and a single body against
//! Newton–Euler.
//!
//! ## Contact with the ground
//! External forces act at [`BodyPoint`]s (a body and an offset in its coordinates):
//! [`Tree3d::derivative_with_point_forces`] turns world forces fₖ on them into generalized
//! forces Σₖ Jₖᵀ fₖ by a leaves-to-root sweep of the spatial forces [rₖ × fₖ; fₖ] (body
//! coordinates), the RNEA's second sweep, without allocation; [`Tree3d::generalized_force`]
//! returns them. [`OnGround3d`] is a tree touching the ground at such points, the forces those
//! of [`crate::physics::ground::Contact::force3d`], the planar law lifted to 3-D (z up, the
//! terrain's height h(x) varying along world x: the planar
//! [`Terrain`](crate::physics::ground::Terrain) extruded along y). At signed distance
//! d = (z − h) / √(1 + h′²) along the unit normal
//! n = (−h′, 0, 1) / √(1 + h′²), with v_n = v · n and v_t = v − v_n n:
//!
//! ```text
//! f_n = F softplus((k ε softplus(−d/ε) − c σ(−d/ε) v_n) / F)    (N; F = 1 N, the planar law)
//! f_t = −μ f_n tanh(s)/s · v_t / v_s,   s = |v_t| / v_s          (|f_t| = μ f_n tanh s ≤ μ f_n)
//! ```
//!
//! tanh(s)/s is an even analytic function of s (a series below s = 0.01), so f is C∞ in the
//! state, also at v_t = 0 and across the contact boundary. Parameters (per contact point): k
//! stiffness (N/m), c damping (N·s/m), μ friction coefficient, v_s slip speed (m/s), ε the
//! length over which contact switches on (m).
//!
//! **Stability rule** ([`contact::resting_contact`], [`contact::resting_step`]): for a body of
//! mass m resting on n points with static penetration δ (a few mm), k = m g / (n δ),
//! c = 2 √(k m / n) (critical for one point's share of the mass), ε = δ / 4; the body bounces
//! on its contact springs at ω = √(k n / m) = √(g / δ), and RK4 steps dt = 0.07 / ω (1.0 ms
//! at δ = 2 mm). Below the slip speed, regularized friction is a viscous damper μ f_n / v_s on
//! a point's tangential motion, inside RK4's stability region while μ f_n dt / (v_s m_p) < 2.8
//! for a point's share m_p of the mass (0.18 for the tests' box at rest, v_s = 0.05 m/s; the
//! impacts' larger f_n pass for a few steps). Measured on the tests' 2 kg box (8 corners,
//! δ = 2 mm, μ = 0.9) dropped from 0.3 m: it comes to rest within 3 s at every step up to
//! 5 ms (5× the rule's), has not settled by then at 6 ms and above, and blew up at no step
//! tried up to 30 ms. A resting corner sinks 1.7 mm (a little under δ: the softened
//! penetration ε softplus(−d/ε) exceeds −d); on a slope of angle θ < atan μ a body creeps at
//! v_s atanh(tan θ / μ), the price of smooth friction.
//!
//! The tests in [`mod@contact`] check the virtual work of Σ Jᵀ f (Q · q̇ = Σ f · v for any q̇,
//! and H Δv̇ = Q), the contact force's and the whole dynamics' smoothness against central
//! differences in and out of contact and across the boundary, the Coulomb bound and direction
//! of friction, a dropped box and a dropped `chain3d` coming to rest without sinking, a sliding
//! box losing energy (kinetic, gravitational and contact-spring) at every step and stopping,
//! horizontal momentum kept with μ = 0, a box held on a 10° slope with μ = 0.9 and sliding with
//! μ = 0.1, and the quaternion's norm through the impacts.
//!
//! ## References
//! - R. Featherstone, *Rigid Body Dynamics Algorithms*, Springer, 2008: ch. 2 (spatial
//!   algebra), 4 (joint models, the floating base), 5 (RNEA), 6 (CRBA).
//! - MuJoCo documentation, `mjData.qpos` / `qvel` (joint conventions), and
//!   `engine_core_smooth.c` (mj_comPos, mj_crb, mj_rne), `engine_forward.c` (mj_RungeKutta).
//! - J. Diebel, *Representing Attitude: Euler Angles, Unit Quaternions, and Rotation Vectors*,
//!   Stanford, 2006, §6 (quaternion kinematics).

pub mod chain3d;
pub mod contact;
pub mod dynamics;
pub mod leaper3d;
pub mod spatial;
pub mod tree;

pub use chain3d::chain3d;
pub use contact::OnGround3d;
pub use leaper3d::leaper3d;
pub use tree::{Body3d, BodyPoint, Joint3d, Tree3d, TreeError};
