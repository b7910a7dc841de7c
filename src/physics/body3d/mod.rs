//! # 3-D articulated rigid-body trees with a floating base
//!
//! A [`Tree3d`] is a tree of rigid bodies: body 0, the root, moves freely in space
//! ([`Joint3d::Free`]); every other body hangs from an earlier one on a ball joint
//! ([`Joint3d::Ball`]) or a revolute joint about an arbitrary unit axis
//! ([`Joint3d::Revolute`]). Each body has a mass, a centre of mass and a full (non-diagonal)
//! inertia tensor; each non-root joint has viscous damping and, optionally, motors (controls).
//! No contact: the ground is its own module, shared by every body that touches it.
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
//! ## References
//! - R. Featherstone, *Rigid Body Dynamics Algorithms*, Springer, 2008: ch. 2 (spatial
//!   algebra), 4 (joint models, the floating base), 5 (RNEA), 6 (CRBA).
//! - MuJoCo documentation, `mjData.qpos` / `qvel` (joint conventions), and
//!   `engine_core_smooth.c` (mj_comPos, mj_crb, mj_rne), `engine_forward.c` (mj_RungeKutta).
//! - J. Diebel, *Representing Attitude: Euler Angles, Unit Quaternions, and Rotation Vectors*,
//!   Stanford, 2006, §6 (quaternion kinematics).

pub mod chain3d;
pub mod dynamics;
pub mod spatial;
pub mod tree;

pub use chain3d::chain3d;
pub use tree::{Body3d, Joint3d, Tree3d, TreeError};
