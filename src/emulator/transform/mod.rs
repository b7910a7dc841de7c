//! # Input and output transforms (NeuroAnimator §3.2, Fig. 6, Appendix A)
//!
//! The raw network N_Φ is wrapped in fixed operators that make it easy to train:
//!
//! ```text
//! Tₓ'  : s ↦ s_L = Rᵀ(θ₀)(s − p₀)        world → local frame of the model (pose p₀, θ₀ read from s)
//! Tₓ^σ : a ↦ (a − μₓ) / σₓ                normalize inputs a = [s_L, u]   (Appendix A, eq. 16)
//!        ŷ = N_Φ^σ(â)                     the network proper
//! T_y^σ: ŷ ↦ μ_y + σ_y ŷ                  unnormalize outputs (eq. 19)
//! T_y' : y_L ↦ R(θ₀) y_L (+ p₀)            local → world (a state change is only rotated)
//! T_y^Δ: Δs ↦ s + Δs                      the network predicts the state change (§3.2)
//! ```
//!
//! Every operator here has its forward map, its exact inverse (used to turn simulated
//! transitions into training targets, Fig. 9), and Jacobian–vector and vector–Jacobian products
//! so that backpropagation through time (§4.3) reaches the state and the control through the
//! whole chain — including the dependence of the frame's pose on the state itself.
//!
//! Normalization statistics are shared by groups of variables (Appendix A: state, force and
//! control variables form separate groups). Eq. 18 as printed divides by (N − 1)(K − 1), which is
//! undefined for a one-variable group; we use the unbiased pooled variance Σ(x − μ)² / (NK − 1)
//! and divide by its square root. A group with zero spread (e.g. the model's own local position,
//! identically zero) gets σ = 1.
//!
//! Two local frames: [`PlanarFrame`] (pose x, y, θ; the truck) and [`SpatialFrame`] (origin and
//! orientation quaternion q₀; the lunar lander), where points map to Rᵀ(q₀)(p − o), vectors to
//! Rᵀ(q₀) v and orientation quaternions to q₀⁻¹ ⊗ q. [`LocalFrame`] wraps either and reads the
//! pose from the state, so that its vector–Jacobian products include the pose's dependence on
//! the state.
//!
//! Local angles are θ − θ₀ without wrapping to (−π, π]: wrapping would break both the exact
//! inverse and differentiability.
//!
//! Layout: [`Normalizer`] (normalization), [`PlanarFrame`] and [`SpatialFrame`] (the two
//! frames), here [`FrameMap`], [`LocalFrame`] and the delta transform, and [`Transforms`], the
//! chain of all of them around the network.

mod chain;
mod normalize;
mod planar;
mod spatial;

pub use chain::{TransformConfig, Transforms};
pub use normalize::Normalizer;
pub use planar::{PlanarFrame, Pose2};
pub use spatial::{quat_mul, Attitude, Pose3, SpatialAt, SpatialFrame};

use super::EmulatorError;

/// Which of the four planar frame maps to apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameMap {
    /// State world → local: points `Rᵀ(θ₀)(p − p₀)`, vectors `Rᵀ(θ₀) v`, angles `θ − θ₀`.
    ToLocal,
    /// State local → world, the exact inverse of [`FrameMap::ToLocal`].
    ToWorld,
    /// State change world → local: points and vectors `Rᵀ(θ₀) d`, angles unchanged.
    DeltaToLocal,
    /// State change local → world, the exact inverse of [`FrameMap::DeltaToLocal`].
    DeltaToWorld,
}

impl FrameMap {
    /// The inverse map.
    pub fn inverse(self) -> Self {
        match self {
            Self::ToLocal => Self::ToWorld,
            Self::ToWorld => Self::ToLocal,
            Self::DeltaToLocal => Self::DeltaToWorld,
            Self::DeltaToWorld => Self::DeltaToLocal,
        }
    }
    /// An angle (or its tangent) under the map: a − θ₀ to local, a + θ₀ to world, unchanged
    /// for state changes. Linear in (a, θ₀), so it serves the Jacobian–vector product too.
    fn shift_angle(self, a: f64, theta: f64) -> f64 {
        match self {
            Self::ToLocal => a - theta,
            Self::ToWorld => a + theta,
            _ => a,
        }
    }
    /// +1 for maps that rotate by +θ₀ (to world), −1 for maps that rotate by −θ₀.
    fn sign(self) -> f64 {
        match self {
            Self::ToLocal | Self::DeltaToLocal => -1.0,
            Self::ToWorld | Self::DeltaToWorld => 1.0,
        }
    }
}

fn check_indices(
    state_dim: usize,
    pose: impl Iterator<Item = usize>,
    listed: impl Iterator<Item = usize>,
) -> Result<(), EmulatorError> {
    for i in pose {
        if i >= state_dim {
            return Err(EmulatorError::Index {
                index: i,
                dim: state_dim,
            });
        }
    }
    let mut used = vec![false; state_dim];
    for i in listed {
        if i >= state_dim {
            return Err(EmulatorError::Index {
                index: i,
                dim: state_dim,
            });
        }
        if used[i] {
            return Err(EmulatorError::DuplicateIndex(i));
        }
        used[i] = true;
    }
    Ok(())
}

/// A model's local frame, planar or spatial, with its pose read from the (world) state.
///
/// The `*_at` methods take a *pose source* state `ps` (the state whose pose defines the frame,
/// normally the current state s) and route the pose derivatives to and from it.
#[derive(Debug, Clone, PartialEq)]
pub enum LocalFrame {
    /// Planar pose (x, y, θ).
    Planar(PlanarFrame),
    /// Spatial pose (origin, quaternion).
    Spatial(SpatialFrame),
}

impl From<PlanarFrame> for LocalFrame {
    fn from(f: PlanarFrame) -> Self {
        Self::Planar(f)
    }
}

impl From<SpatialFrame> for LocalFrame {
    fn from(f: SpatialFrame) -> Self {
        Self::Spatial(f)
    }
}

/// A [`LocalFrame`] read from one state ([`LocalFrame::at`]): the pose and, for a spatial
/// frame, the rotation its maps use, computed once for every map at that state (an emulator
/// step maps its input to the frame and its output back, both at the current state).
// The spatial variant is much larger, but boxing it would allocate in the hot loop.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameAt {
    /// A planar pose.
    Planar(Pose2),
    /// A spatial pose with its rotation.
    Spatial(SpatialAt),
}

impl LocalFrame {
    /// The frame read from the pose source `ps`, with what the vector–Jacobian products need
    /// when `derivatives` (the maps alone need less).
    #[inline(always)]
    pub fn at(&self, ps: &[f64], derivatives: bool) -> FrameAt {
        match self {
            Self::Planar(f) => FrameAt::Planar(f.pose(ps)),
            Self::Spatial(f) => FrameAt::Spatial(f.at(ps, derivatives)),
        }
    }

    /// How many values [`LocalFrame::write_tape`] keeps of a frame read from a state (the
    /// spatial heading's; none for the others).
    pub fn tape_len(&self) -> usize {
        match self {
            Self::Planar(_) => 0,
            Self::Spatial(f) => f.tape_len(),
        }
    }

    /// Keeps in `tape` ([`LocalFrame::tape_len`] values) what [`LocalFrame::at_taped`] needs to
    /// read the frame `at` again more cheaply.
    #[inline(always)]
    pub fn write_tape(&self, at: &FrameAt, tape: &mut [f64]) {
        if let (Self::Spatial(f), FrameAt::Spatial(a)) = (self, at) {
            f.write_tape(a, tape);
        }
    }

    /// [`LocalFrame::at`] of the pose source `ps` whose frame [`LocalFrame::write_tape`] kept
    /// in `tape`: the same values.
    #[inline(always)]
    pub fn at_taped(&self, ps: &[f64], tape: &[f64], derivatives: bool) -> FrameAt {
        match self {
            Self::Planar(f) => FrameAt::Planar(f.pose(ps)),
            Self::Spatial(f) => FrameAt::Spatial(f.at_taped(ps, tape, derivatives)),
        }
    }

    /// [`LocalFrame::apply_at`] at a frame read by [`LocalFrame::at`] from the pose source.
    #[inline]
    pub fn apply_with(&self, map: FrameMap, at: &FrameAt, inp: &[f64], out: &mut [f64]) {
        match (self, at) {
            (Self::Planar(f), FrameAt::Planar(pose)) => f.apply(map, *pose, inp, out),
            (Self::Spatial(f), FrameAt::Spatial(a)) => f.apply_at(map, a, inp, out),
            _ => panic!("frame read by a different kind of local frame"),
        }
    }

    /// [`LocalFrame::apply_vjp_self`] at the frame read by [`LocalFrame::at`] from `s`.
    #[inline]
    pub fn apply_vjp_self_with(
        &self,
        map: FrameMap,
        at: &FrameAt,
        s: &[f64],
        out_bar: &[f64],
        s_bar: &mut [f64],
    ) {
        match (self, at) {
            (Self::Planar(f), FrameAt::Planar(pose)) => {
                let mut pb = Pose2::default();
                f.apply_vjp(map, *pose, s, out_bar, s_bar, &mut pb);
                f.pose_vjp(pb, s_bar);
            }
            (Self::Spatial(f), FrameAt::Spatial(a)) => {
                let mut pb = Pose3::default();
                f.apply_vjp_at(map, a, s, out_bar, s_bar, &mut pb);
                f.pose_vjp_at(a, &pb, s_bar);
            }
            _ => panic!("frame read by a different kind of local frame"),
        }
    }

    /// [`LocalFrame::apply_vjp_at`] at the frame read by [`LocalFrame::at`] from the pose
    /// source.
    #[inline]
    pub fn apply_vjp_with(
        &self,
        map: FrameMap,
        at: &FrameAt,
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        ps_bar: &mut [f64],
    ) {
        match (self, at) {
            (Self::Planar(f), FrameAt::Planar(pose)) => {
                let mut pb = Pose2::default();
                f.apply_vjp(map, *pose, inp, out_bar, inp_bar, &mut pb);
                f.pose_vjp(pb, ps_bar);
            }
            (Self::Spatial(f), FrameAt::Spatial(a)) => {
                let mut pb = Pose3::default();
                f.apply_vjp_at(map, a, inp, out_bar, inp_bar, &mut pb);
                f.pose_vjp_at(a, &pb, ps_bar);
            }
            _ => panic!("frame read by a different kind of local frame"),
        }
    }

    /// The state indices the frame's pose is read from (a planar frame's x, y, θ; a spatial
    /// frame's origin and orientation quaternion).
    pub fn pose_indices(&self) -> Vec<usize> {
        match self {
            Self::Planar(f) => vec![f.x, f.y, f.theta],
            Self::Spatial(f) => f.origin.iter().chain(&f.orientation).copied().collect(),
        }
    }

    /// Checks indices against the state dimension.
    pub fn validate(&self, state_dim: usize) -> Result<(), EmulatorError> {
        match self {
            Self::Planar(f) => f.validate(state_dim),
            Self::Spatial(f) => f.validate(state_dim),
        }
    }

    /// Applies `map` at the pose of `ps` to `inp`.
    pub fn apply_at(&self, map: FrameMap, ps: &[f64], inp: &[f64], out: &mut [f64]) {
        match self {
            Self::Planar(f) => f.apply(map, f.pose(ps), inp, out),
            Self::Spatial(f) => f.apply(map, &f.pose(ps), inp, out),
        }
    }

    /// JVP of [`LocalFrame::apply_at`] for tangents `d_ps` of the pose source and `d_inp` of the
    /// input.
    pub fn apply_jvp_at(
        &self,
        map: FrameMap,
        ps: &[f64],
        d_ps: &[f64],
        inp: &[f64],
        d_inp: &[f64],
        d_out: &mut [f64],
    ) {
        match self {
            Self::Planar(f) => f.apply_jvp(map, f.pose(ps), inp, d_inp, f.pose(d_ps), d_out),
            Self::Spatial(f) => {
                f.apply_jvp(map, &f.pose(ps), inp, d_inp, &f.pose_jvp(ps, d_ps), d_out)
            }
        }
    }

    /// VJP of `apply_at(map, s, s, out)` (the input is its own pose source): adds the whole
    /// cotangent, through the input and through the pose, to `s_bar`.
    pub fn apply_vjp_self(&self, map: FrameMap, s: &[f64], out_bar: &[f64], s_bar: &mut [f64]) {
        match self {
            Self::Planar(f) => {
                let mut pb = Pose2::default();
                f.apply_vjp(map, f.pose(s), s, out_bar, s_bar, &mut pb);
                f.pose_vjp(pb, s_bar);
            }
            Self::Spatial(f) => {
                let mut pb = Pose3::default();
                f.apply_vjp(map, &f.pose(s), s, out_bar, s_bar, &mut pb);
                f.pose_vjp(s, &pb, s_bar);
            }
        }
    }

    /// VJP of [`LocalFrame::apply_at`]: adds the input cotangent to `inp_bar` and the pose
    /// cotangent to `ps_bar`.
    pub fn apply_vjp_at(
        &self,
        map: FrameMap,
        ps: &[f64],
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        ps_bar: &mut [f64],
    ) {
        match self {
            Self::Planar(f) => {
                let mut pb = Pose2::default();
                f.apply_vjp(map, f.pose(ps), inp, out_bar, inp_bar, &mut pb);
                f.pose_vjp(pb, ps_bar);
            }
            Self::Spatial(f) => {
                let mut pb = Pose3::default();
                f.apply_vjp(map, &f.pose(ps), inp, out_bar, inp_bar, &mut pb);
                f.pose_vjp(ps, &pb, ps_bar);
            }
        }
    }
}

/// The state-change transform T_y^Δ (§3.2): `s_next = s + Δs`.
pub fn delta_forward(s: &[f64], ds: &[f64], s_next: &mut [f64]) {
    for ((o, a), b) in s_next.iter_mut().zip(s).zip(ds) {
        *o = a + b;
    }
}

/// Inverse of [`delta_forward`]: `Δs = s_next − s`. Its Jacobians are ±identity.
pub fn delta_inverse(s: &[f64], s_next: &[f64], ds: &mut [f64]) {
    for ((o, a), b) in ds.iter_mut().zip(s).zip(s_next) {
        *o = b - a;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn frame() -> PlanarFrame {
        // State: x, y, θ, vx, vy, ω, (px, py) a second point, φ a second angle.
        PlanarFrame {
            x: 0,
            y: 1,
            theta: 2,
            points: vec![(0, 1), (6, 7)],
            vectors: vec![(3, 4)],
            angles: vec![2, 8],
        }
    }

    fn random(n: usize, rng: &mut ChaCha8Rng, scale: f64) -> Vec<f64> {
        (0..n).map(|_| rng.random_range(-scale..scale)).collect()
    }

    #[test]
    fn frame_validation_catches_bad_indices() {
        assert!(frame().validate(9).is_ok());
        assert!(frame().validate(8).is_err());
        let mut f = frame();
        f.vectors.push((5, 0));
        assert_eq!(f.validate(9), Err(EmulatorError::DuplicateIndex(0)));
    }

    #[test]
    fn frame_maps_invert_exactly() {
        let f = frame();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..20 {
            let s = random(9, &mut rng, 50.0);
            let pose = f.pose(&s);
            for map in [FrameMap::ToLocal, FrameMap::DeltaToLocal] {
                let mut l = vec![0.0; 9];
                let mut back = vec![0.0; 9];
                f.apply(map, pose, &s, &mut l);
                f.apply(map.inverse(), pose, &l, &mut back);
                for k in 0..9 {
                    assert!(
                        (back[k] - s[k]).abs() < 1e-12 * (1.0 + s[k].abs()),
                        "{map:?}"
                    );
                }
                f.apply(map.inverse(), pose, &s, &mut l);
                f.apply(map, pose, &l, &mut back);
                for k in 0..9 {
                    assert!(
                        (back[k] - s[k]).abs() < 1e-12 * (1.0 + s[k].abs()),
                        "{map:?}"
                    );
                }
            }
            // The model's own pose is the origin of its local frame.
            let mut l = vec![0.0; 9];
            f.apply(FrameMap::ToLocal, pose, &s, &mut l);
            assert!(l[0].abs() < 1e-12 && l[1].abs() < 1e-12 && l[2] == 0.0);
            assert_eq!(l[5], s[5]);
        }
    }

    #[test]
    fn frame_jacobian_products_match_finite_differences() {
        let f = frame();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let h = 1e-6;
        for map in [
            FrameMap::ToLocal,
            FrameMap::ToWorld,
            FrameMap::DeltaToLocal,
            FrameMap::DeltaToWorld,
        ] {
            let inp = random(9, &mut rng, 3.0);
            let pose = Pose2 {
                x: 0.7,
                y: -1.3,
                theta: 0.9,
            };
            let d_inp = random(9, &mut rng, 1.0);
            let d_pose = Pose2 {
                x: 0.3,
                y: -0.8,
                theta: 0.5,
            };
            let shift = |t: f64| {
                let i: Vec<f64> = inp.iter().zip(&d_inp).map(|(a, b)| a + t * b).collect();
                let p = Pose2 {
                    x: pose.x + t * d_pose.x,
                    y: pose.y + t * d_pose.y,
                    theta: pose.theta + t * d_pose.theta,
                };
                let mut o = vec![0.0; 9];
                f.apply(map, p, &i, &mut o);
                o
            };
            let (op, om) = (shift(h), shift(-h));
            let mut jvp = vec![0.0; 9];
            f.apply_jvp(map, pose, &inp, &d_inp, d_pose, &mut jvp);
            for k in 0..9 {
                let fd = (op[k] - om[k]) / (2.0 * h);
                assert!(
                    (fd - jvp[k]).abs() < 1e-7,
                    "{map:?} jvp[{k}] {fd} vs {}",
                    jvp[k]
                );
            }
            // VJP is the adjoint of JVP: ⟨w, J v⟩ = ⟨Jᵀ w, v⟩.
            let w = random(9, &mut rng, 1.0);
            let mut inp_bar = vec![0.0; 9];
            let mut pose_bar = Pose2::default();
            f.apply_vjp(map, pose, &inp, &w, &mut inp_bar, &mut pose_bar);
            let lhs: f64 = w.iter().zip(&jvp).map(|(a, b)| a * b).sum();
            let rhs: f64 = inp_bar.iter().zip(&d_inp).map(|(a, b)| a * b).sum::<f64>()
                + pose_bar.x * d_pose.x
                + pose_bar.y * d_pose.y
                + pose_bar.theta * d_pose.theta;
            assert!((lhs - rhs).abs() < 1e-12, "{map:?}: {lhs} vs {rhs}");
        }
    }

    fn spatial() -> SpatialFrame {
        // pos 0..3, quaternion 3..7, vel 7..10, ω 10..13, a pass-through variable at 13, a
        // second point 14..17 and a second quaternion 17..21.
        let mut f = SpatialFrame::rigid_body(0, 3, 7, 10);
        f.points.push([14, 15, 16]);
        f.quaternions.push([17, 18, 19, 20]);
        f
    }

    fn frames() -> Vec<(LocalFrame, usize)> {
        let heading = SpatialFrame {
            attitude: Attitude::Heading,
            ..spatial()
        };
        vec![
            (frame().into(), 9),
            (spatial().into(), 21),
            (heading.into(), 21),
        ]
    }

    const MAPS: [FrameMap; 4] = [
        FrameMap::ToLocal,
        FrameMap::ToWorld,
        FrameMap::DeltaToLocal,
        FrameMap::DeltaToWorld,
    ];

    #[test]
    fn local_frames_invert_and_their_products_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let h = 1e-6;
        for (f, n) in frames() {
            assert!(f.validate(n).is_ok());
            assert!(f.validate(n - 1).is_err());
            for map in MAPS {
                // Pose source with a non-unit quaternion (the spatial frame divides by |q|²).
                let ps = random(n, &mut rng, 3.0);
                let inp = random(n, &mut rng, 30.0);
                let (mut out, mut back) = (vec![0.0; n], vec![0.0; n]);
                f.apply_at(map, &ps, &inp, &mut out);
                f.apply_at(map.inverse(), &ps, &out, &mut back);
                for k in 0..n {
                    assert!(
                        (back[k] - inp[k]).abs() < 1e-12 * (1.0 + inp[k].abs()),
                        "{map:?} {k}"
                    );
                }
                let inp = random(n, &mut rng, 3.0);
                let d_ps = random(n, &mut rng, 1.0);
                let d_inp = random(n, &mut rng, 1.0);
                let eval = |t: f64| {
                    let p: Vec<f64> = ps.iter().zip(&d_ps).map(|(a, b)| a + t * b).collect();
                    let i: Vec<f64> = inp.iter().zip(&d_inp).map(|(a, b)| a + t * b).collect();
                    let mut o = vec![0.0; n];
                    f.apply_at(map, &p, &i, &mut o);
                    o
                };
                let (op, om) = (eval(h), eval(-h));
                let mut jvp = vec![0.0; n];
                f.apply_jvp_at(map, &ps, &d_ps, &inp, &d_inp, &mut jvp);
                for k in 0..n {
                    let fd = (op[k] - om[k]) / (2.0 * h);
                    assert!(
                        (fd - jvp[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                        "{map:?} jvp[{k}] {fd} vs {}",
                        jvp[k]
                    );
                }
                let w = random(n, &mut rng, 1.0);
                let (mut inp_bar, mut ps_bar) = (vec![0.0; n], vec![0.0; n]);
                f.apply_vjp_at(map, &ps, &inp, &w, &mut inp_bar, &mut ps_bar);
                let lhs: f64 = w.iter().zip(&jvp).map(|(a, b)| a * b).sum();
                let rhs: f64 = inp_bar.iter().zip(&d_inp).map(|(a, b)| a * b).sum::<f64>()
                    + ps_bar.iter().zip(&d_ps).map(|(a, b)| a * b).sum::<f64>();
                assert!(
                    (lhs - rhs).abs() < 1e-10 * (1.0 + lhs.abs()),
                    "{map:?}: {lhs} vs {rhs}"
                );
                // Input = its own pose source.
                let mut s_bar = vec![0.0; n];
                f.apply_vjp_self(map, &inp, &w, &mut s_bar);
                let mut jvp_self = vec![0.0; n];
                f.apply_jvp_at(map, &inp, &d_inp, &inp, &d_inp, &mut jvp_self);
                let lhs: f64 = w.iter().zip(&jvp_self).map(|(a, b)| a * b).sum();
                let rhs: f64 = s_bar.iter().zip(&d_inp).map(|(a, b)| a * b).sum();
                assert!(
                    (lhs - rhs).abs() < 1e-10 * (1.0 + lhs.abs()),
                    "{map:?} self"
                );
            }
        }
    }

    #[test]
    fn spatial_frame_matches_nalgebra_rotation() {
        let f = spatial();
        let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(0.3, -1.0, 0.5));
        let rot = nalgebra::UnitQuaternion::from_axis_angle(&axis, 1.1);
        let mut s = vec![0.0; 21];
        s[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
        s[3..7].copy_from_slice(&[rot.w, rot.i, rot.j, rot.k]);
        s[7..10].copy_from_slice(&[0.5, -0.2, 0.9]);
        s[14..17].copy_from_slice(&[4.0, -1.0, 2.0]);
        s[17..21].copy_from_slice(&[rot.w, rot.i, rot.j, rot.k]);
        let mut l = vec![0.0; 21];
        f.apply(FrameMap::ToLocal, &f.pose(&s), &s, &mut l);
        let v = rot.inverse() * nalgebra::Vector3::new(0.5, -0.2, 0.9);
        let p = rot.inverse() * nalgebra::Vector3::new(3.0, -3.0, -1.0);
        for k in 0..3 {
            assert!(l[k].abs() < 1e-12);
            assert!((l[7 + k] - v[k]).abs() < 1e-12);
            assert!((l[14 + k] - p[k]).abs() < 1e-12);
        }
        // The body's own orientation becomes the identity quaternion.
        for (k, want) in [1.0, 0.0, 0.0, 0.0].iter().enumerate() {
            assert!((l[3 + k] - want).abs() < 1e-12);
            assert!((l[17 + k] - want).abs() < 1e-12);
        }
    }

    #[test]
    fn delta_inverts() {
        let s = [1.0, -2.0, 1e3];
        let d = [0.1, 0.2, -0.3];
        let mut n = [0.0; 3];
        let mut back = [0.0; 3];
        delta_forward(&s, &d, &mut n);
        delta_inverse(&s, &n, &mut back);
        for k in 0..3 {
            assert!((back[k] - d[k]).abs() < 1e-12);
        }
    }
}
