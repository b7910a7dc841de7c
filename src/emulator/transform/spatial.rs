//! # The spatial local frame (NeuroAnimator §3.2; the lunar lander)
//!
//! A 3-D model whose pose (origin o, orientation quaternion q₀ = [w, x, y, z]) is part of its
//! state is seen by the network in its own frame:
//!
//! ```text
//! points  p ↦ Rᵀ(q₀)(p − o),   vectors  v ↦ Rᵀ(q₀) v,   quaternions  q ↦ q₀⁻¹ ⊗ q,
//! ```
//!
//! with R(q) = M(q)/|q|², M(q) = (w² − v·v) I + 2 v vᵀ + 2 w [v]×, which is orthogonal for
//! any q ≠ 0, so q₀ need not be exactly unit; state changes are only rotated. Products with
//! the Jacobians use ∂R/∂q_k in closed form and the bilinearity of the Hamilton product ⊗.
//!
//! The frame's orientation q₀ is either the body's whole attitude ([`Attitude::Full`], for a
//! body whose dynamics are invariant to any rotation, e.g. the swimming dolphin) or only its
//! heading ([`Attitude::Heading`]): the twist of the body quaternion about the world vertical
//! z, q₀ = (w, 0, 0, z)/√(w² + z²) (swing–twist decomposition). Under gravity the dynamics are
//! invariant only to translation and rotation about the vertical, so a frame that removed the
//! whole attitude would hide which way gravity points; the heading frame keeps the tilt in the
//! local quaternion.
//!
//! ## References
//! - K. Shoemake, *Animating rotation with quaternion curves*, SIGGRAPH 1985.

use super::{check_indices, FrameMap};
use crate::emulator::EmulatorError;

/// A 3D pose: origin and orientation quaternion `[w, x, y, z]`. The quaternion need not be
/// exactly unit: the rotation used is R(q) = M(q) / |q|², which is orthogonal for any q ≠ 0.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Pose3 {
    /// Origin (x, y, z).
    pub origin: [f64; 3],
    /// Orientation quaternion `[w, x, y, z]`.
    pub q: [f64; 4],
}

/// A [`SpatialFrame`] read from one state: the pose, the heading normalization it came from
/// and the rotation R(q₀) (with ∂R/∂q₀ₖ when asked for), computed once and shared by every map
/// at that state ([`SpatialFrame::at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialAt {
    /// The pose read from the state.
    pub pose: Pose3,
    /// The heading as a unit pair and its norm ([`Attitude::Heading`] only).
    heading: Option<([f64; 2], f64)>,
    /// R(q₀).
    r: M3,
    /// ∂R/∂q₀ₖ, when computed.
    dr: Option<[M3; 4]>,
}

/// Hamilton product a ⊗ b of quaternions `[w, x, y, z]`.
#[inline(always)]
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

#[inline(always)]
fn quat_conj(a: [f64; 4]) -> [f64; 4] {
    [a[0], -a[1], -a[2], -a[3]]
}

type M3 = [[f64; 3]; 3];

#[inline(always)]
fn mat_vec(m: &M3, v: [f64; 3]) -> [f64; 3] {
    let row = |i: usize| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2];
    [row(0), row(1), row(2)]
}

#[inline(always)]
fn mat_t_vec(m: &M3, v: [f64; 3]) -> [f64; 3] {
    let col = |j: usize| m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2];
    [col(0), col(1), col(2)]
}

#[inline(always)]
fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// R(q) = M(q)/|q|² alone, as [`rotation_and_derivatives`] computes it (the same operations,
/// without the derivatives the forward maps do not need).
fn rotation(q: [f64; 4]) -> M3 {
    let n = q.iter().map(|a| a * a).sum::<f64>();
    let (w, v) = (q[0], [q[1], q[2], q[3]]);
    let cv = [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]];
    let vv = dot3(v, v);
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let m = if i == j { w * w - vv } else { 0.0 } + 2.0 * v[i] * v[j] + 2.0 * w * cv[i][j];
            r[i][j] = m / n;
        }
    }
    r
}

/// All four quaternion components.
const ALL_Q: [usize; 4] = [0, 1, 2, 3];

/// R(q) = M(q)/|q|² with M(q) = (w² − v·v) I + 2 v vᵀ + 2 w [v]×, and ∂R/∂q_k.
#[inline]
fn rotation_and_derivatives(q: [f64; 4]) -> (M3, [M3; 4]) {
    rotation_and_derivatives_of(q, &ALL_Q)
}

/// [`rotation_and_derivatives`] with ∂R/∂q_k for the k in `live` only (the others are left
/// zero); each computed value is the same.
#[inline]
fn rotation_and_derivatives_of(q: [f64; 4], live: &[usize]) -> (M3, [M3; 4]) {
    let n = q.iter().map(|a| a * a).sum::<f64>();
    let (w, v) = (q[0], [q[1], q[2], q[3]]);
    let cross =
        |a: [f64; 3]| -> M3 { [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]] };
    let vv = dot3(v, v);
    let cv = cross(v);
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] =
                if i == j { w * w - vv } else { 0.0 } + 2.0 * v[i] * v[j] + 2.0 * w * cv[i][j];
        }
    }
    let mut dm = [[[0.0; 3]; 3]; 4];
    for i in 0..3 {
        for j in 0..3 {
            dm[0][i][j] = if i == j { 2.0 * w } else { 0.0 } + 2.0 * cv[i][j];
        }
    }
    for k in (0..3).filter(|k| live.contains(&(k + 1))) {
        let mut e = [0.0; 3];
        e[k] = 1.0;
        let ce = cross(e);
        for i in 0..3 {
            for j in 0..3 {
                dm[k + 1][i][j] = if i == j { -2.0 * v[k] } else { 0.0 }
                    + 2.0 * (e[i] * v[j] + v[i] * e[j])
                    + 2.0 * w * ce[i][j];
            }
        }
    }
    let r = m.map(|row| row.map(|a| a / n));
    let mut dr = [[[0.0; 3]; 3]; 4];
    for &k in live {
        for i in 0..3 {
            for j in 0..3 {
                dr[k][i][j] = (dm[k][i][j] - 2.0 * q[k] * r[i][j]) / n;
            }
        }
    }
    (r, dr)
}

/// [`rotation_and_derivatives_of`] for a heading quaternion q = (w, 0, 0, z) with ∂R/∂w and
/// ∂R/∂z (when `derivatives`; the others zero), bit for bit: the same operations on every
/// entry the generic code computes from a non-zero value, and the entries it computes from zeros
/// (exactly +0 for finite w and z) set to +0 without dividing, so 12 divisions instead of 27.
/// `None` when |q|² is zero or not finite (the generic code's NaNs are not reproduced).
#[inline(always)]
fn heading_rotation_and_derivatives(w: f64, z: f64, derivatives: bool) -> Option<(M3, [M3; 4])> {
    let n = w * w + z * z;
    if !(n.is_finite() && n > 0.0) {
        return None;
    }
    let tw = 2.0 * w;
    let a = w * w - z * z;
    let (m01, m10, m22) = (0.0 + tw * -z, 0.0 + tw * z, a + (2.0 * z) * z + tw * 0.0);
    let (r00, r01, r10, r22) = (a / n, m01 / n, m10 / n, m22 / n);
    let r = [[r00, r01, 0.0], [r10, r00, 0.0], [0.0, 0.0, r22]];
    let mut dr = [[[0.0; 3]; 3]; 4];
    if derivatives {
        // ∂M/∂w: 2w I + 2 [v]×; ∂M/∂z: −2z I + 2 (e_z vᵀ + v e_zᵀ) + 2w [e_z]×.
        let d00 = tw + 0.0;
        let (d01, d10, d22) = (0.0 + 2.0 * -z, 0.0 + 2.0 * z, tw + 2.0 * 0.0);
        let t = tw;
        let e00 = (d00 - t * r00) / n;
        dr[0] = [
            [e00, (d01 - t * r01) / n, 0.0],
            [(d10 - t * r10) / n, e00, 0.0],
            [0.0, 0.0, (d22 - t * r22) / n],
        ];
        let m2z = -2.0 * z;
        let c00 = (m2z + 2.0 * 0.0) + tw * 0.0;
        let (c01, c10, c22) = (0.0 + -tw, 0.0 + tw, (m2z + 2.0 * (z + z)) + tw * 0.0);
        let t = 2.0 * z;
        let f00 = (c00 - t * r00) / n;
        dr[3] = [
            [f00, (c01 - t * r01) / n, 0.0],
            [(c10 - t * r10) / n, f00, 0.0],
            [0.0, 0.0, (c22 - t * r22) / n],
        ];
    }
    Some((r, dr))
}

/// The local frame of a 3D model whose pose (origin, orientation quaternion) is part of its
/// state; e.g. the lunar lander (position, quaternion, velocity, angular velocity).
///
/// Local coordinates: points Rᵀ(p − o), vectors Rᵀ v, quaternions q₀⁻¹ ⊗ q; state changes are
/// only rotated (quaternion changes: q₀⁻¹ ⊗ Δq). Variables not listed pass through.
#[derive(Debug, Clone, PartialEq)]
pub struct SpatialFrame {
    /// Which part of the orientation quaternion defines the frame.
    pub attitude: Attitude,
    /// State indices of the frame origin.
    pub origin: [usize; 3],
    /// State indices of the frame orientation quaternion `[w, x, y, z]`.
    pub orientation: [usize; 4],
    /// Index triples of positions (translated and rotated); normally includes `origin`.
    pub points: Vec<[usize; 3]>,
    /// Index triples of free vectors such as velocities (rotated only).
    pub vectors: Vec<[usize; 3]>,
    /// Index quadruples of orientation quaternions; normally includes `orientation`.
    pub quaternions: Vec<[usize; 4]>,
}

/// Which rotation defines a [`SpatialFrame`] (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Attitude {
    /// The body's whole orientation: the body's own quaternion becomes the identity.
    Full,
    /// Only the heading, the rotation about the world vertical z: roll and pitch stay visible.
    Heading,
}

impl SpatialFrame {
    /// A rigid body whose state holds position at `pos..pos+3`, quaternion at `quat..quat+4`,
    /// linear velocity at `vel..vel+3` and angular velocity (world frame) at `omega..omega+3`.
    pub fn rigid_body(pos: usize, quat: usize, vel: usize, omega: usize) -> Self {
        let tri = |a: usize| [a, a + 1, a + 2];
        let quad = [quat, quat + 1, quat + 2, quat + 3];
        Self {
            attitude: Attitude::Full,
            origin: tri(pos),
            orientation: quad,
            points: vec![tri(pos)],
            vectors: vec![tri(vel), tri(omega)],
            quaternions: vec![quad],
        }
    }

    /// Checks that every index is below `state_dim` and listed at most once.
    pub fn validate(&self, state_dim: usize) -> Result<(), EmulatorError> {
        check_indices(
            state_dim,
            self.origin.iter().chain(&self.orientation).copied(),
            self.points
                .iter()
                .chain(&self.vectors)
                .flatten()
                .chain(self.quaternions.iter().flatten())
                .copied(),
        )
    }

    /// The frame's heading quaternion read from a state: (w, z)/√(w² + z²) of the orientation
    /// quaternion, as the unit pair and its norm.
    #[inline(always)]
    fn heading(&self, s: &[f64]) -> ([f64; 2], f64) {
        let (w, z) = (s[self.orientation[0]], s[self.orientation[3]]);
        // Borges's corrected hypot, as glibc's: the bits every cached lander and dolphin net
        // was trained through.
        let n = crate::portable::hypot_corrected(w, z);
        ([w / n, z / n], n)
    }

    /// The pose read from a world-frame state.
    pub fn pose(&self, s: &[f64]) -> Pose3 {
        let heading = match self.attitude {
            Attitude::Full => None,
            Attitude::Heading => Some(self.heading(s)),
        };
        self.pose_from(s, heading)
    }

    /// [`SpatialFrame::pose`] given the heading of `s` (for [`Attitude::Heading`]).
    #[inline(always)]
    fn pose_from(&self, s: &[f64], heading: Option<([f64; 2], f64)>) -> Pose3 {
        let q = match (self.attitude, heading) {
            (Attitude::Heading, Some(([w, z], _))) => [w, 0.0, 0.0, z],
            _ => self.orientation.map(|i| s[i]),
        };
        Pose3 {
            origin: self.origin.map(|i| s[i]),
            q,
        }
    }

    /// The components of the frame's quaternion that depend on the state, the only ones whose
    /// cotangents [`SpatialFrame::pose_vjp`] reads: all four, or w and z of a heading.
    fn live_q(&self) -> &'static [usize] {
        match self.attitude {
            Attitude::Full => &ALL_Q,
            Attitude::Heading => &[0, 3],
        }
    }

    /// The frame read from state `s`: its pose and rotation, with the rotation's derivatives
    /// when `derivatives` (the vector–Jacobian products need them; the maps do not).
    #[inline(always)]
    pub fn at(&self, s: &[f64], derivatives: bool) -> SpatialAt {
        let heading = match self.attitude {
            Attitude::Full => None,
            Attitude::Heading => Some(self.heading(s)),
        };
        self.at_heading(s, heading, derivatives)
    }

    /// How many values [`SpatialFrame::write_tape`] keeps of a frame read from a state: the
    /// heading's unit pair and norm for [`Attitude::Heading`], none for [`Attitude::Full`].
    pub fn tape_len(&self) -> usize {
        match self.attitude {
            Attitude::Full => 0,
            Attitude::Heading => 3,
        }
    }

    /// Keeps what [`SpatialFrame::at_taped`] needs to read the frame `at` again without its
    /// square root (`tape`: [`SpatialFrame::tape_len`] values).
    #[inline(always)]
    pub fn write_tape(&self, at: &SpatialAt, tape: &mut [f64]) {
        if let Some(([w, z], n)) = at.heading {
            tape[..3].copy_from_slice(&[w, z, n]);
        }
    }

    /// [`SpatialFrame::at`] of the state `s` whose frame [`SpatialFrame::write_tape`] kept in
    /// `tape`: the same values, the heading read from the tape instead of computed again.
    #[inline(always)]
    pub fn at_taped(&self, s: &[f64], tape: &[f64], derivatives: bool) -> SpatialAt {
        let heading = match self.attitude {
            Attitude::Full => None,
            Attitude::Heading => Some(([tape[0], tape[1]], tape[2])),
        };
        self.at_heading(s, heading, derivatives)
    }

    /// [`SpatialFrame::at`] given the heading of `s` (for [`Attitude::Heading`]).
    #[inline(always)]
    fn at_heading(
        &self,
        s: &[f64],
        heading: Option<([f64; 2], f64)>,
        derivatives: bool,
    ) -> SpatialAt {
        let pose = self.pose_from(s, heading);
        if let Some(([w, z], _)) = heading {
            if let Some((r, dr)) = heading_rotation_and_derivatives(w, z, derivatives) {
                return SpatialAt {
                    pose,
                    heading,
                    r,
                    dr: derivatives.then_some(dr),
                };
            }
        }
        let (r, dr) = if derivatives {
            let (r, dr) = rotation_and_derivatives_of(pose.q, self.live_q());
            (r, Some(dr))
        } else {
            (rotation(pose.q), None)
        };
        SpatialAt {
            pose,
            heading,
            r,
            dr,
        }
    }

    /// The pose tangent for a state tangent `ds` at state `s`.
    pub fn pose_jvp(&self, s: &[f64], ds: &[f64]) -> Pose3 {
        let q = match self.attitude {
            Attitude::Full => self.orientation.map(|i| ds[i]),
            Attitude::Heading => {
                // d(t/|t|) = (I − t̂ t̂ᵀ) dt / |t| for t = (w, z).
                let (h, n) = self.heading(s);
                let dt = [ds[self.orientation[0]], ds[self.orientation[3]]];
                let along = h[0] * dt[0] + h[1] * dt[1];
                [
                    (dt[0] - h[0] * along) / n,
                    0.0,
                    0.0,
                    (dt[1] - h[1] * along) / n,
                ]
            }
        };
        Pose3 {
            origin: self.origin.map(|i| ds[i]),
            q,
        }
    }

    /// Adds a pose cotangent to the cotangent `s_bar` of the state `s` the pose is read from.
    pub fn pose_vjp(&self, s: &[f64], pose_bar: &Pose3, s_bar: &mut [f64]) {
        let heading = match self.attitude {
            Attitude::Full => None,
            Attitude::Heading => Some(self.heading(s)),
        };
        self.pose_vjp_from(heading, pose_bar, s_bar);
    }

    /// [`SpatialFrame::pose_vjp`] given the heading of the state (for [`Attitude::Heading`]).
    pub fn pose_vjp_at(&self, at: &SpatialAt, pose_bar: &Pose3, s_bar: &mut [f64]) {
        self.pose_vjp_from(at.heading, pose_bar, s_bar);
    }

    fn pose_vjp_from(&self, heading: Option<([f64; 2], f64)>, pose_bar: &Pose3, s_bar: &mut [f64]) {
        for (i, v) in self.origin.iter().zip(pose_bar.origin) {
            s_bar[*i] += v;
        }
        match self.attitude {
            Attitude::Full => {
                for (i, v) in self.orientation.iter().zip(pose_bar.q) {
                    s_bar[*i] += v;
                }
            }
            Attitude::Heading => {
                // The normalization's Jacobian is symmetric; x and y of the pose are constant.
                let (h, n) = heading.expect("a heading frame reads its heading");
                let g = [pose_bar.q[0], pose_bar.q[3]];
                let along = h[0] * g[0] + h[1] * g[1];
                s_bar[self.orientation[0]] += (g[0] - h[0] * along) / n;
                s_bar[self.orientation[3]] += (g[1] - h[1] * along) / n;
            }
        }
    }

    fn triples(&self) -> impl Iterator<Item = (&[usize; 3], bool)> {
        self.points
            .iter()
            .map(|p| (p, true))
            .chain(self.vectors.iter().map(|p| (p, false)))
    }

    /// Applies `map` at `pose` to `inp`, writing `out` (same length).
    pub fn apply(&self, map: FrameMap, pose: &Pose3, inp: &[f64], out: &mut [f64]) {
        self.apply_rotated(map, pose, &rotation(pose.q), inp, out);
    }

    /// [`SpatialFrame::apply`] at the frame read from a state ([`SpatialFrame::at`]).
    pub fn apply_at(&self, map: FrameMap, at: &SpatialAt, inp: &[f64], out: &mut [f64]) {
        self.apply_rotated(map, &at.pose, &at.r, inp, out);
    }

    /// [`SpatialFrame::apply`] with R(q₀) given: one body ([`SpatialFrame::apply_body`]) with
    /// the map as a constant, compiled with AVX where the processor has it (the same IEEE
    /// operations either way, as in [`SpatialFrame::apply_vjp_rotated`]).
    fn apply_rotated(&self, map: FrameMap, pose: &Pose3, r: &M3, inp: &[f64], out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx")]
            fn avx(
                f: &SpatialFrame,
                map: FrameMap,
                pose: &Pose3,
                r: &M3,
                inp: &[f64],
                out: &mut [f64],
            ) {
                f.apply_dispatch(map, pose, r, inp, out);
            }
            if crate::simd::avx() {
                // SAFETY: the processor supports AVX (checked just above).
                unsafe { avx(self, map, pose, r, inp, out) };
                return;
            }
        }
        self.apply_dispatch(map, pose, r, inp, out);
    }

    /// [`SpatialFrame::apply_body`] for `map` as constants.
    #[inline(always)]
    fn apply_dispatch(&self, map: FrameMap, pose: &Pose3, r: &M3, inp: &[f64], out: &mut [f64]) {
        use FrameMap::*;
        match map {
            ToLocal => self.apply_body::<true, SHIFT_TO_LOCAL>(pose, r, inp, out),
            ToWorld => self.apply_body::<false, SHIFT_TO_WORLD>(pose, r, inp, out),
            DeltaToLocal => self.apply_body::<true, SHIFT_NONE>(pose, r, inp, out),
            DeltaToWorld => self.apply_body::<false, SHIFT_NONE>(pose, r, inp, out),
        }
    }

    /// The body of [`SpatialFrame::apply_rotated`] (`LOCAL` and `SHIFT` as in
    /// [`SpatialFrame::vjp_body`]).
    #[inline(always)]
    fn apply_body<const LOCAL: bool, const SHIFT: u8>(
        &self,
        pose: &Pose3,
        r: &M3,
        inp: &[f64],
        out: &mut [f64],
    ) {
        out.copy_from_slice(inp);
        for t in &self.points {
            apply_triple::<LOCAL, SHIFT, true>(t, pose, r, inp, out);
        }
        for t in &self.vectors {
            apply_triple::<LOCAL, SHIFT, false>(t, pose, r, inp, out);
        }
        let n = pose.q.iter().map(|a| a * a).sum::<f64>();
        for qi in &self.quaternions {
            let a = qi.map(|i| inp[i]);
            let o = if LOCAL {
                quat_mul(quat_conj(pose.q), a).map(|x| x / n)
            } else {
                quat_mul(pose.q, a)
            };
            for k in 0..4 {
                out[qi[k]] = o[k];
            }
        }
    }

    /// Jacobian–vector product of [`SpatialFrame::apply`] with respect to the input (tangent
    /// `d_inp`) and the pose (tangent `d_pose`), written to `d_out`.
    pub fn apply_jvp(
        &self,
        map: FrameMap,
        pose: &Pose3,
        inp: &[f64],
        d_inp: &[f64],
        d_pose: &Pose3,
        d_out: &mut [f64],
    ) {
        d_out.copy_from_slice(d_inp);
        let (r, dr) = rotation_and_derivatives(pose.q);
        let local = map.sign() < 0.0;
        for (t, is_point) in self.triples() {
            let mut v = t.map(|i| inp[i]);
            let mut dv = t.map(|i| d_inp[i]);
            if is_point && map == FrameMap::ToLocal {
                v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
                dv = [0, 1, 2].map(|k| dv[k] - d_pose.origin[k]);
            }
            let mut o = if local {
                mat_t_vec(&r, dv)
            } else {
                mat_vec(&r, dv)
            };
            for (k, drk) in dr.iter().enumerate() {
                let term = if local {
                    mat_t_vec(drk, v)
                } else {
                    mat_vec(drk, v)
                };
                for c in 0..3 {
                    o[c] += term[c] * d_pose.q[k];
                }
            }
            if is_point && map == FrameMap::ToWorld {
                o = [0, 1, 2].map(|k| o[k] + d_pose.origin[k]);
            }
            for k in 0..3 {
                d_out[t[k]] = o[k];
            }
        }
        for qi in &self.quaternions {
            let a = qi.map(|i| inp[i]);
            let da = qi.map(|i| d_inp[i]);
            let mut o = [0.0; 4];
            let partials = quat_partials(map, pose.q, a, &ALL_Q);
            for (k, dq) in partials.iter().enumerate() {
                for c in 0..4 {
                    o[c] += dq[c] * d_pose.q[k];
                }
            }
            let lin = quat_linear(map, pose.q, da);
            for k in 0..4 {
                d_out[qi[k]] = o[k] + lin[k];
            }
        }
    }

    /// Vector–Jacobian product of [`SpatialFrame::apply`]: adds (∂out/∂inp)ᵀ `out_bar` to
    /// `inp_bar` and (∂out/∂pose)ᵀ `out_bar` to `pose_bar`.
    pub fn apply_vjp(
        &self,
        map: FrameMap,
        pose: &Pose3,
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        let (r, dr) = rotation_and_derivatives(pose.q);
        let rot = (&r, &dr, &ALL_Q[..]);
        self.apply_vjp_rotated(map, pose, rot, inp, out_bar, inp_bar, pose_bar);
    }

    /// [`SpatialFrame::apply_vjp`] at the frame read from a state ([`SpatialFrame::at`]; the
    /// rotation's derivatives are computed here if `at` lacks them), for
    /// [`SpatialFrame::pose_vjp_at`]: of `pose_bar`'s quaternion only the components that
    /// depend on the state are computed (w and z of a heading frame).
    pub(super) fn apply_vjp_at(
        &self,
        map: FrameMap,
        at: &SpatialAt,
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        let computed;
        let dr = match &at.dr {
            Some(dr) => dr,
            None => {
                computed = rotation_and_derivatives_of(at.pose.q, self.live_q()).1;
                &computed
            }
        };
        let rot = (&at.r, dr, self.live_q());
        self.apply_vjp_rotated(map, &at.pose, rot, inp, out_bar, inp_bar, pose_bar);
    }

    /// [`SpatialFrame::apply_vjp`] with R(q₀) and ∂R/∂q₀ₖ given, computing the quaternion
    /// cotangent for the components k in `live` only (all four, or w and z of a heading).
    ///
    /// One body ([`SpatialFrame::vjp_body`]) with the map and the live set as constants, so
    /// that each case is straight-line code; on x86-64 processors with AVX it is compiled with
    /// AVX enabled, which puts independent divisions in one 4-lane division. Every operation is
    /// the same IEEE operation either way (none is fused), so the bits do not depend on the
    /// path.
    #[allow(clippy::too_many_arguments)]
    fn apply_vjp_rotated(
        &self,
        map: FrameMap,
        pose: &Pose3,
        (r, dr, live): (&M3, &[M3; 4], &[usize]),
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        let args = VjpArgs {
            pose,
            r,
            dr,
            inp,
            out_bar,
        };
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx")]
            fn avx(
                f: &SpatialFrame,
                map: FrameMap,
                live: &[usize],
                a: &VjpArgs<'_>,
                inp_bar: &mut [f64],
                pose_bar: &mut Pose3,
            ) {
                f.vjp_dispatch(map, live, a, inp_bar, pose_bar);
            }
            if crate::simd::avx() {
                // SAFETY: the processor supports AVX (checked just above).
                unsafe { avx(self, map, live, &args, inp_bar, pose_bar) };
                return;
            }
        }
        self.vjp_dispatch(map, live, &args, inp_bar, pose_bar);
    }

    /// [`SpatialFrame::vjp_body`] for `map` and `live` as constants.
    #[inline(always)]
    fn vjp_dispatch(
        &self,
        map: FrameMap,
        live: &[usize],
        a: &VjpArgs<'_>,
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        use FrameMap::*;
        let heading = live == [0, 3];
        debug_assert!(heading || live == ALL_Q);
        macro_rules! body {
            ($local:expr, $shift:expr) => {
                if heading {
                    self.vjp_body::<$local, $shift, 2>([0, 3], a, inp_bar, pose_bar)
                } else {
                    self.vjp_body::<$local, $shift, 4>(ALL_Q, a, inp_bar, pose_bar)
                }
            };
        }
        match map {
            ToLocal => body!(true, SHIFT_TO_LOCAL),
            ToWorld => body!(false, SHIFT_TO_WORLD),
            DeltaToLocal => body!(true, SHIFT_NONE),
            DeltaToWorld => body!(false, SHIFT_NONE),
        }
    }

    /// The body of [`SpatialFrame::apply_vjp_rotated`]: `LOCAL` for the maps that rotate by
    /// Rᵀ (to local), `SHIFT` for how points move with the origin (none for state changes),
    /// `live` the quaternion components whose cotangents are computed.
    #[inline(always)]
    fn vjp_body<const LOCAL: bool, const SHIFT: u8, const K: usize>(
        &self,
        live: [usize; K],
        &VjpArgs {
            pose,
            r,
            dr,
            inp,
            out_bar,
        }: &VjpArgs<'_>,
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        // Variables the map does not touch pass their cotangent through. Indices are listed at
        // most once (`validate`), so when the map's count equals the length it touches all.
        let touched = 3 * (self.points.len() + self.vectors.len()) + 4 * self.quaternions.len();
        if touched < inp_bar.len() {
            pass_untouched(self, inp_bar, out_bar);
        }
        // The pose cotangent is summed in a local copy (registers), in the same order, and
        // stored once: read back from memory after each triple, its components waited on the
        // stores just made.
        let mut pb = *pose_bar;
        let rot = (r, dr, live);
        for t in &self.points {
            vjp_triple::<LOCAL, SHIFT, K, true>(t, pose, rot, inp, out_bar, inp_bar, &mut pb);
        }
        for t in &self.vectors {
            vjp_triple::<LOCAL, SHIFT, K, false>(t, pose, rot, inp, out_bar, inp_bar, &mut pb);
        }
        let n = pose.q.iter().map(|a| a * a).sum::<f64>();
        for qi in &self.quaternions {
            let a = qi.map(|i| inp[i]);
            let g = qi.map(|i| out_bar[i]);
            // Transposes of left multiplication: L(q)ᵀ = L(q*).
            let ib = if LOCAL {
                quat_mul(pose.q, g).map(|x| x / n)
            } else {
                quat_mul(quat_conj(pose.q), g)
            };
            for k in 0..4 {
                inp_bar[qi[k]] += ib[k];
            }
            let map = if LOCAL {
                FrameMap::ToLocal
            } else {
                FrameMap::ToWorld
            };
            let partials = quat_partials_body(map, pose.q, a, &live);
            for k in live {
                let dq = partials[k];
                pb.q[k] += (0..4).map(|c| dq[c] * g[c]).sum::<f64>();
            }
        }
        *pose_bar = pb;
    }
}

/// What [`SpatialFrame::vjp_body`] reads: the pose, R(q₀), ∂R/∂q₀ₖ, the map's input and the
/// cotangent of its output.
struct VjpArgs<'a> {
    pose: &'a Pose3,
    r: &'a M3,
    dr: &'a [M3; 4],
    inp: &'a [f64],
    out_bar: &'a [f64],
}

/// [`SpatialFrame::vjp_body`]'s `SHIFT`: points are state changes (not shifted), mapped to
/// local (p − o), or mapped to world (+ o).
const SHIFT_NONE: u8 = 0;
const SHIFT_TO_LOCAL: u8 = 1;
const SHIFT_TO_WORLD: u8 = 2;

/// One point (`POINT`) or vector triple `t` of [`SpatialFrame::apply_body`].
#[inline(always)]
fn apply_triple<const LOCAL: bool, const SHIFT: u8, const POINT: bool>(
    t: &[usize; 3],
    pose: &Pose3,
    r: &M3,
    inp: &[f64],
    out: &mut [f64],
) {
    let mut v = t.map(|i| inp[i]);
    if POINT && SHIFT == SHIFT_TO_LOCAL {
        v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
    }
    let mut o = if LOCAL {
        mat_t_vec(r, v)
    } else {
        mat_vec(r, v)
    };
    if POINT && SHIFT == SHIFT_TO_WORLD {
        o = [0, 1, 2].map(|k| o[k] + pose.origin[k]);
    }
    for k in 0..3 {
        out[t[k]] = o[k];
    }
}

/// One point (`POINT`) or vector triple `t` of [`SpatialFrame::vjp_body`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn vjp_triple<const LOCAL: bool, const SHIFT: u8, const K: usize, const POINT: bool>(
    t: &[usize; 3],
    pose: &Pose3,
    (r, dr, live): (&M3, &[M3; 4], [usize; K]),
    inp: &[f64],
    out_bar: &[f64],
    inp_bar: &mut [f64],
    pose_bar: &mut Pose3,
) {
    let mut v = t.map(|i| inp[i]);
    if POINT && SHIFT == SHIFT_TO_LOCAL {
        v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
    }
    let g = t.map(|i| out_bar[i]);
    let ib = if LOCAL {
        mat_vec(r, g)
    } else {
        mat_t_vec(r, g)
    };
    for k in 0..3 {
        inp_bar[t[k]] += ib[k];
    }
    for k in live {
        let term = if LOCAL {
            mat_t_vec(&dr[k], v)
        } else {
            mat_vec(&dr[k], v)
        };
        pose_bar.q[k] += dot3(g, term);
    }
    if POINT {
        match SHIFT {
            SHIFT_TO_LOCAL => (0..3).for_each(|k| pose_bar.origin[k] -= ib[k]),
            SHIFT_TO_WORLD => (0..3).for_each(|k| pose_bar.origin[k] += g[k]),
            _ => {}
        }
    }
}

/// Adds `out_bar` to `inp_bar` at the variables `frame` does not map (they pass through).
#[inline(always)]
fn pass_untouched(frame: &SpatialFrame, inp_bar: &mut [f64], out_bar: &[f64]) {
    if inp_bar.is_empty() {
    } else if inp_bar.len() <= 64 {
        // One bit per variable: building and reading it costs less than the state is long.
        let mut mapped = 0u64;
        for (t, _) in frame.triples() {
            t.iter().for_each(|&i| mapped |= 1 << i);
        }
        for q in &frame.quaternions {
            q.iter().for_each(|&i| mapped |= 1 << i);
        }
        let mut free = !mapped & (u64::MAX >> (64 - inp_bar.len()));
        while free != 0 {
            let i = free.trailing_zeros() as usize;
            inp_bar[i] += out_bar[i];
            free &= free - 1;
        }
    } else {
        let mapped = |i: usize| {
            frame.triples().any(|(t, _)| t.contains(&i))
                || frame.quaternions.iter().any(|q| q.contains(&i))
        };
        for (i, b) in inp_bar.iter_mut().enumerate() {
            if !mapped(i) {
                *b += out_bar[i];
            }
        }
    }
}

/// The quaternion part of a spatial map, linear in its argument: q₀⁻¹ ⊗ a or q₀ ⊗ a.
fn quat_linear(map: FrameMap, q0: [f64; 4], a: [f64; 4]) -> [f64; 4] {
    if map.sign() < 0.0 {
        let n = q0.iter().map(|x| x * x).sum::<f64>();
        quat_mul(quat_conj(q0), a).map(|x| x / n)
    } else {
        quat_mul(q0, a)
    }
}

/// ∂/∂q₀ₖ of [`quat_linear`] for the k in `live` (the others left zero; the norm and the
/// product shared by the four computed once).
fn quat_partials(map: FrameMap, q0: [f64; 4], a: [f64; 4], live: &[usize]) -> [[f64; 4]; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        /// The same body compiled with AVX: its four divisions per row go in one 4-lane
        /// division (IEEE division lane by lane, and no operation is fused, so the same bits).
        #[target_feature(enable = "avx")]
        fn avx(map: FrameMap, q0: [f64; 4], a: [f64; 4], live: &[usize]) -> [[f64; 4]; 4] {
            quat_partials_body(map, q0, a, live)
        }
        if crate::simd::avx() {
            // SAFETY: the processor supports AVX (checked just above).
            return unsafe { avx(map, q0, a, live) };
        }
    }
    quat_partials_body(map, q0, a, live)
}

#[inline(always)]
fn quat_partials_body(map: FrameMap, q0: [f64; 4], a: [f64; 4], live: &[usize]) -> [[f64; 4]; 4] {
    let unit = |k: usize| {
        let mut e = [0.0; 4];
        e[k] = 1.0;
        e
    };
    let mut out = [[0.0; 4]; 4];
    if map.sign() < 0.0 {
        let n = q0.iter().map(|x| x * x).sum::<f64>();
        let p = quat_mul(quat_conj(q0), a);
        let f = [p[0] / n, p[1] / n, p[2] / n, p[3] / n];
        let heading = live == [0, 3] && q0[1].to_bits() == 0 && q0[2].to_bits() == 0;
        if heading && a.iter().all(|&x| x != 0.0 && x.is_finite()) {
            // q₀ = (w, 0, 0, z), k = w and z: conj(e_w) ⊗ a is exactly a and conj(e_z) ⊗ a is
            // exactly (a₃, a₂, −a₁, −a₀) when no component of a is zero (each adds only
            // signed zeros to one ±a_c), so both share the four divisions a_c / n.
            let g = [a[0] / n, a[1] / n, a[2] / n, a[3] / n];
            let d3 = [g[3], g[2], -g[1], -g[0]];
            for c in 0..4 {
                out[0][c] = g[c] - 2.0 * q0[0] * f[c] / n;
                out[3][c] = d3[c] - 2.0 * q0[3] * f[c] / n;
            }
            return out;
        }
        for &k in live {
            let o = &mut out[k];
            let d = quat_mul(quat_conj(unit(k)), a);
            for c in 0..4 {
                o[c] = d[c] / n - 2.0 * q0[k] * f[c] / n;
            }
        }
    } else {
        for &k in live {
            out[k] = quat_mul(unit(k), a);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits<const N: usize>(m: &[[f64; N]]) -> Vec<u64> {
        m.iter().flatten().map(|x| x.to_bits()).collect()
    }

    fn vbits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The quaternion partials' AVX copy (runtime dispatch) gives every bit of the plain
    /// body, for general and heading quaternions, both maps, every live set the frames use,
    /// and components that are zero of either sign.
    #[test]
    fn dispatched_quaternion_partials_match_the_plain_body_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(37);
        for i in 0..20_000 {
            let mut q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
            let mut a: [f64; 4] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
            match i % 5 {
                0 => (q[1], q[2]) = (0.0, 0.0),
                1 => a[i % 4] = -0.0,
                2 => q[3] = 0.0,
                _ => {}
            }
            for map in [FrameMap::ToLocal, FrameMap::ToWorld] {
                for live in [&ALL_Q[..], &[0, 3][..]] {
                    assert_eq!(
                        bits(&quat_partials(map, q, a, live)),
                        bits(&quat_partials_body(map, q, a, live)),
                        "{q:?} {a:?} {map:?} {live:?}"
                    );
                }
            }
        }
    }

    /// [`SpatialFrame::apply_rotated`] written out as generic loops over the frame's triples,
    /// the map matched inside them: the oracle of the operations and their order.
    fn reference_apply(
        f: &SpatialFrame,
        map: FrameMap,
        pose: &Pose3,
        r: &M3,
        inp: &[f64],
    ) -> Vec<f64> {
        let mut out = inp.to_vec();
        let local = map.sign() < 0.0;
        for (t, is_point) in f.triples() {
            let mut v = t.map(|i| inp[i]);
            if is_point && map == FrameMap::ToLocal {
                v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
            }
            let mut o = if local {
                mat_t_vec(r, v)
            } else {
                mat_vec(r, v)
            };
            if is_point && map == FrameMap::ToWorld {
                o = [0, 1, 2].map(|k| o[k] + pose.origin[k]);
            }
            for k in 0..3 {
                out[t[k]] = o[k];
            }
        }
        let n = pose.q.iter().map(|a| a * a).sum::<f64>();
        for qi in &f.quaternions {
            let a = qi.map(|i| inp[i]);
            let o = if local {
                quat_mul(quat_conj(pose.q), a).map(|x| x / n)
            } else {
                quat_mul(pose.q, a)
            };
            for k in 0..4 {
                out[qi[k]] = o[k];
            }
        }
        out
    }

    /// [`SpatialFrame::apply_vjp_rotated`] written out the same way: adds to `inp_bar` and
    /// `pose_bar`.
    #[allow(clippy::too_many_arguments)]
    fn reference_vjp(
        f: &SpatialFrame,
        map: FrameMap,
        pose: &Pose3,
        (r, dr, live): (&M3, &[M3; 4], &[usize]),
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        pose_bar: &mut Pose3,
    ) {
        pass_untouched(f, inp_bar, out_bar);
        let local = map.sign() < 0.0;
        for (t, is_point) in f.triples() {
            let mut v = t.map(|i| inp[i]);
            if is_point && map == FrameMap::ToLocal {
                v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
            }
            let g = t.map(|i| out_bar[i]);
            let ib = if local {
                mat_vec(r, g)
            } else {
                mat_t_vec(r, g)
            };
            for k in 0..3 {
                inp_bar[t[k]] += ib[k];
            }
            for &k in live {
                let term = if local {
                    mat_t_vec(&dr[k], v)
                } else {
                    mat_vec(&dr[k], v)
                };
                pose_bar.q[k] += dot3(g, term);
            }
            if is_point {
                match map {
                    FrameMap::ToLocal => (0..3).for_each(|k| pose_bar.origin[k] -= ib[k]),
                    FrameMap::ToWorld => (0..3).for_each(|k| pose_bar.origin[k] += g[k]),
                    _ => {}
                }
            }
        }
        let n = pose.q.iter().map(|a| a * a).sum::<f64>();
        for qi in &f.quaternions {
            let a = qi.map(|i| inp[i]);
            let g = qi.map(|i| out_bar[i]);
            let ib = if local {
                quat_mul(pose.q, g).map(|x| x / n)
            } else {
                quat_mul(quat_conj(pose.q), g)
            };
            for k in 0..4 {
                inp_bar[qi[k]] += ib[k];
            }
            let partials = quat_partials_body(map, pose.q, a, live);
            for &k in live {
                let dq = partials[k];
                pose_bar.q[k] += (0..4).map(|c| dq[c] * g[c]).sum::<f64>();
            }
        }
    }

    /// The frame maps and their vector–Jacobian products compiled with AVX (runtime dispatch)
    /// give every bit of the plain bodies, and both give every bit of the written-out
    /// reference loops (the same operations in the same order): every map, both live sets,
    /// rigid bodies with one or two vectors, general and heading quaternions, and inputs with
    /// zeros of either sign.
    #[test]
    fn dispatched_frame_maps_match_the_plain_bodies_bit_for_bit() {
        use FrameMap::*;
        let mut rng = ChaCha8Rng::seed_from_u64(41);
        let mut lander = SpatialFrame::rigid_body(0, 3, 7, 10);
        lander.vectors.truncate(1);
        let frames = [SpatialFrame::rigid_body(0, 3, 7, 10), lander];
        for i in 0..4000 {
            let f = &frames[i % 2];
            let mut draw = |scale: f64| -> f64 {
                match rng.random_range(0..12) {
                    0 => 0.0,
                    1 => -0.0,
                    _ => rng.random_range(-scale..scale),
                }
            };
            let s: Vec<f64> = (0..13).map(|_| draw(3.0)).collect();
            let inp: Vec<f64> = (0..13).map(|_| draw(2.0)).collect();
            let out_bar: Vec<f64> = (0..13).map(|_| draw(1.0)).collect();
            let mut q: [f64; 4] = std::array::from_fn(|_| draw(1.0));
            if i % 3 == 0 {
                (q[1], q[2]) = (0.0, 0.0);
            }
            if q.iter().all(|&x| x == 0.0) {
                q[0] = 1.0;
            }
            let pose = Pose3 {
                origin: [s[0], s[1], s[2]],
                q,
            };
            let (r, dr) = rotation_and_derivatives(q);
            for map in [ToLocal, ToWorld, DeltaToLocal, DeltaToWorld] {
                let (mut a, mut b) = (vec![0.0; 13], vec![0.0; 13]);
                f.apply_rotated(map, &pose, &r, &inp, &mut a);
                f.apply_dispatch(map, &pose, &r, &inp, &mut b);
                assert_eq!(vbits(&a), vbits(&b), "apply {map:?} {q:?}");
                let reference = reference_apply(f, map, &pose, &r, &inp);
                assert_eq!(
                    vbits(&a),
                    vbits(&reference),
                    "apply {map:?} {q:?} reference"
                );
                for live in [&ALL_Q[..], &[0, 3][..]] {
                    let (mut ia, mut ib) = (out_bar.clone(), out_bar.clone());
                    let (mut pa, mut pb) = (Pose3::default(), Pose3::default());
                    f.apply_vjp_rotated(
                        map,
                        &pose,
                        (&r, &dr, live),
                        &inp,
                        &out_bar,
                        &mut ia,
                        &mut pa,
                    );
                    let args = VjpArgs {
                        pose: &pose,
                        r: &r,
                        dr: &dr,
                        inp: &inp,
                        out_bar: &out_bar,
                    };
                    f.vjp_dispatch(map, live, &args, &mut ib, &mut pb);
                    assert_eq!(vbits(&ia), vbits(&ib), "vjp {map:?} {q:?} {live:?}");
                    let pose_bits = |p: &Pose3| [bits(&[p.origin]), bits(&[p.q])];
                    assert_eq!(
                        pose_bits(&pa),
                        pose_bits(&pb),
                        "pose {map:?} {q:?} {live:?}"
                    );
                    let (mut ic, mut pc) = (out_bar.clone(), Pose3::default());
                    let rot = (&r, &dr, live);
                    reference_vjp(f, map, &pose, rot, &inp, &out_bar, &mut ic, &mut pc);
                    assert_eq!(
                        vbits(&ia),
                        vbits(&ic),
                        "vjp {map:?} {q:?} {live:?} reference"
                    );
                    assert_eq!(
                        pose_bits(&pa),
                        pose_bits(&pc),
                        "pose {map:?} {q:?} {live:?} reference"
                    );
                }
            }
        }
    }

    /// Heading quaternions as [`SpatialFrame::at`] reads them, (w, z)/√(w² + z²), with the
    /// special values a state can hold: exact zeros of either sign, negative w, the identity.
    fn headings(rng: &mut ChaCha8Rng) -> Vec<(f64, f64)> {
        let mut out = vec![
            (1.0, 0.0),
            (1.0, -0.0),
            (0.0, 1.0),
            (-0.0, 1.0),
            (-1.0, 0.0),
        ];
        for i in 0..4000 {
            let (mut w, mut z): (f64, f64) =
                (rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0));
            match i % 6 {
                0 => z = 0.0,
                1 => w = -0.0,
                2 => z = -z.abs(),
                3 => w = -w.abs(),
                _ => {}
            }
            let n = w.hypot(z);
            out.push((w / n, z / n));
        }
        out
    }

    /// A frame read again from its tape is the frame read from the state, every bit (with and
    /// without the rotation's derivatives), for heading and full attitudes; the full attitude
    /// keeps nothing.
    #[test]
    fn frame_read_from_its_tape_is_the_frame_read_from_the_state() {
        let mut rng = ChaCha8Rng::seed_from_u64(33);
        for attitude in [Attitude::Heading, Attitude::Full] {
            let frame = SpatialFrame {
                attitude,
                ..SpatialFrame::rigid_body(0, 3, 7, 10)
            };
            assert_eq!(
                frame.tape_len(),
                if attitude == Attitude::Heading { 3 } else { 0 }
            );
            for (i, (w, z)) in headings(&mut rng).into_iter().enumerate().take(1500) {
                let mut s: Vec<f64> = (0..13).map(|_| rng.random_range(-3.0..3.0)).collect();
                // A tilted attitude whose twist is (w, z), not always unit.
                let scale = if i % 3 == 0 {
                    1.0
                } else {
                    rng.random_range(0.5..2.0)
                };
                (s[3], s[6]) = (w * scale, z * scale);
                let mut tape = vec![f64::NAN; frame.tape_len()];
                for derivatives in [false, true] {
                    let at = frame.at(&s, derivatives);
                    frame.write_tape(&at, &mut tape);
                    assert_eq!(
                        frame.at_taped(&s, &tape, derivatives),
                        at,
                        "{attitude:?} {s:?}"
                    );
                    let local = crate::emulator::transform::LocalFrame::Spatial(frame.clone());
                    let at = local.at(&s, derivatives);
                    let mut tape = vec![f64::NAN; local.tape_len()];
                    local.write_tape(&at, &mut tape);
                    assert_eq!(local.at_taped(&s, &tape, derivatives), at);
                }
            }
        }
    }

    /// The heading fast path gives every bit the generic rotation and derivatives give.
    #[test]
    fn heading_rotation_matches_the_generic_code_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        for (w, z) in headings(&mut rng) {
            let q = [w, 0.0, 0.0, z];
            let (r, dr) = rotation_and_derivatives_of(q, &[0, 3]);
            let (fr, fdr) = heading_rotation_and_derivatives(w, z, true).expect("a unit heading");
            assert_eq!(bits(&fr), bits(&r), "R at ({w:e}, {z:e})");
            assert_eq!(bits(&fr), bits(&rotation(q)), "R alone at ({w:e}, {z:e})");
            for k in 0..4 {
                assert_eq!(bits(&fdr[k]), bits(&dr[k]), "dR/dq{k} at ({w:e}, {z:e})");
            }
            let (r2, _) = heading_rotation_and_derivatives(w, z, false).expect("a unit heading");
            assert_eq!(bits(&r2), bits(&r));
        }
        assert!(heading_rotation_and_derivatives(0.0, 0.0, true).is_none());
        assert!(heading_rotation_and_derivatives(f64::NAN, 1.0, false).is_none());
    }

    /// The heading fast path of [`quat_partials`] gives every bit the generic loop gives (which
    /// it takes for any `live` other than w and z), for quaternions with and without zeros.
    #[test]
    fn heading_quaternion_partials_match_the_generic_code_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(32);
        for (i, (w, z)) in headings(&mut rng).into_iter().enumerate() {
            let q0 = [w, 0.0, 0.0, z];
            let mut a: [f64; 4] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
            if i % 7 == 0 {
                a[i % 4] = 0.0;
            }
            for map in [FrameMap::ToLocal, FrameMap::DeltaToLocal, FrameMap::ToWorld] {
                let fast = quat_partials(map, q0, a, &[0, 3]);
                let generic = quat_partials(map, q0, a, &ALL_Q);
                for k in [0, 3] {
                    assert_eq!(
                        bits(&[fast[k]]),
                        bits(&[generic[k]]),
                        "{map:?} k = {k} at q0 = {q0:?}, a = {a:?}"
                    );
                }
            }
        }
    }
}
