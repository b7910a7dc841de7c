//! # The planar local frame (NeuroAnimator §3.2; the truck)
//!
//! A planar model whose pose p₀ = (x₀, y₀), θ₀ is part of its state has dynamics invariant
//! under rotation and translation, so the network sees the state in the model's own frame:
//!
//! ```text
//! points  p ↦ Rᵀ(θ₀)(p − p₀),   vectors  v ↦ Rᵀ(θ₀) v,   angles  θ ↦ θ − θ₀,
//! ```
//!
//! with R(θ) the rotation by θ; state changes are only rotated. [`PlanarFrame::apply`] performs
//! any of the four [`FrameMap`]s, and its Jacobian–vector and vector–Jacobian products include
//! the derivative with respect to the pose, ∂/∂θ₀ R(±θ₀) v = ± perp(R(±θ₀) v), so that
//! gradients reach the state through the pose it defines.

use super::{check_indices, FrameMap};
use crate::emulator::EmulatorError;

/// A planar pose: origin (x, y) and heading θ (radians, counter-clockwise).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Pose2 {
    /// Origin x.
    pub x: f64,
    /// Origin y.
    pub y: f64,
    /// Heading θ in radians.
    pub theta: f64,
}

/// The local frame of a planar model whose pose (x, y, θ) is part of its state (§3.2: the
/// dynamics are invariant under rotation and translation). Used by the truck.
///
/// Variables not listed in `points`, `vectors` or `angles` pass through unchanged.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarFrame {
    /// State index of the frame origin's x.
    pub x: usize,
    /// State index of the frame origin's y.
    pub y: usize,
    /// State index of the frame heading θ.
    pub theta: usize,
    /// Index pairs of positions (translated and rotated); normally includes `(x, y)`.
    pub points: Vec<(usize, usize)>,
    /// Index pairs of free vectors such as velocities (rotated only).
    pub vectors: Vec<(usize, usize)>,
    /// Indices of headings (offset by θ₀); normally includes `theta`.
    pub angles: Vec<usize>,
}

impl PlanarFrame {
    /// A single rigid body with state indices for position (x, y), heading θ and linear
    /// velocity (vx, vy); any other state variable (e.g. angular velocity) passes through.
    pub fn rigid_body(x: usize, y: usize, theta: usize, vx: usize, vy: usize) -> Self {
        Self {
            x,
            y,
            theta,
            points: vec![(x, y)],
            vectors: vec![(vx, vy)],
            angles: vec![theta],
        }
    }

    /// Checks that every index is below `state_dim` and used at most once.
    pub fn validate(&self, state_dim: usize) -> Result<(), EmulatorError> {
        check_indices(
            state_dim,
            [self.x, self.y, self.theta].into_iter(),
            self.points
                .iter()
                .chain(&self.vectors)
                .flat_map(|&(a, b)| [a, b])
                .chain(self.angles.iter().copied()),
        )
    }

    /// The pose read from a world-frame state.
    pub fn pose(&self, s: &[f64]) -> Pose2 {
        Pose2 {
            x: s[self.x],
            y: s[self.y],
            theta: s[self.theta],
        }
    }

    /// Adds a pose cotangent to the state cotangent (the pose is read from the state).
    pub fn pose_vjp(&self, pose_bar: Pose2, s_bar: &mut [f64]) {
        s_bar[self.x] += pose_bar.x;
        s_bar[self.y] += pose_bar.y;
        s_bar[self.theta] += pose_bar.theta;
    }

    /// Applies `map` at `pose` to `inp`, writing `out` (same length).
    pub fn apply(&self, map: FrameMap, pose: Pose2, inp: &[f64], out: &mut [f64]) {
        out.copy_from_slice(inp);
        let phi = map.sign() * pose.theta;
        let (sn, c) = crate::portable::sin_cos(phi);
        let rot = |a: f64, b: f64| (c * a - sn * b, sn * a + c * b);
        for &(i, j) in &self.points {
            let (a, b) = match map {
                FrameMap::ToLocal => rot(inp[i] - pose.x, inp[j] - pose.y),
                FrameMap::ToWorld => {
                    let (a, b) = rot(inp[i], inp[j]);
                    (a + pose.x, b + pose.y)
                }
                _ => rot(inp[i], inp[j]),
            };
            out[i] = a;
            out[j] = b;
        }
        for &(i, j) in &self.vectors {
            let (a, b) = rot(inp[i], inp[j]);
            out[i] = a;
            out[j] = b;
        }
        self.shift_angles(map, inp, pose.theta, out);
    }

    /// Each point and vector pair (i, j), whether it is a point, and v′, what the rotation
    /// acts on: p − p₀ for points mapped to local, the input pair otherwise; out = R(±θ₀) v′
    /// (+ p₀ for points mapped to world).
    fn rotated_inputs<'a>(
        &'a self,
        map: FrameMap,
        pose: Pose2,
        inp: &'a [f64],
    ) -> impl Iterator<Item = (usize, usize, bool, (f64, f64))> + 'a {
        let points = self.points.iter().map(|p| (p, true));
        let vectors = self.vectors.iter().map(|p| (p, false));
        points.chain(vectors).map(move |(&(i, j), is_point)| {
            let v = if is_point && map == FrameMap::ToLocal {
                (inp[i] - pose.x, inp[j] - pose.y)
            } else {
                (inp[i], inp[j])
            };
            (i, j, is_point, v)
        })
    }

    /// The angles under `map` (θ ∓ θ₀, or unchanged for state changes); linear, so the same
    /// for tangents.
    fn shift_angles(&self, map: FrameMap, inp: &[f64], theta: f64, out: &mut [f64]) {
        for &k in &self.angles {
            out[k] = map.shift_angle(inp[k], theta);
        }
    }

    /// Jacobian–vector product of [`PlanarFrame::apply`] with respect to both the input (tangent
    /// `d_inp`) and the pose (tangent `d_pose`), written to `d_out`.
    pub fn apply_jvp(
        &self,
        map: FrameMap,
        pose: Pose2,
        inp: &[f64],
        d_inp: &[f64],
        d_pose: Pose2,
        d_out: &mut [f64],
    ) {
        d_out.copy_from_slice(d_inp);
        let sign = map.sign();
        let (sn, c) = crate::portable::sin_cos(sign * pose.theta);
        let rot = |a: f64, b: f64| (c * a - sn * b, sn * a + c * b);
        for (i, j, is_point, (va, vb)) in self.rotated_inputs(map, pose, inp) {
            let (ra, rb) = rot(va, vb);
            let (mut da, mut db) = rot(d_inp[i], d_inp[j]);
            // ∂/∂θ₀ of R(±θ₀) v' = ± perp(R v').
            da += sign * -rb * d_pose.theta;
            db += sign * ra * d_pose.theta;
            if is_point {
                match map {
                    FrameMap::ToLocal => {
                        let (pa, pb) = rot(d_pose.x, d_pose.y);
                        da -= pa;
                        db -= pb;
                    }
                    FrameMap::ToWorld => {
                        da += d_pose.x;
                        db += d_pose.y;
                    }
                    _ => {}
                }
            }
            d_out[i] = da;
            d_out[j] = db;
        }
        self.shift_angles(map, d_inp, d_pose.theta, d_out);
    }

    /// Vector–Jacobian product of [`PlanarFrame::apply`]: adds (∂out/∂inp)ᵀ `out_bar` to
    /// `inp_bar` and (∂out/∂pose)ᵀ `out_bar` to `pose_bar`.
    pub fn apply_vjp(
        &self,
        map: FrameMap,
        pose: Pose2,
        inp: &[f64],
        out_bar: &[f64],
        inp_bar: &mut [f64],
        pose_bar: &mut Pose2,
    ) {
        let n = inp.len();
        let mut touched_theta = 0.0;
        let sign = map.sign();
        let (sn, c) = crate::portable::sin_cos(sign * pose.theta);
        let rot = |a: f64, b: f64| (c * a - sn * b, sn * a + c * b);
        let rot_t = |a: f64, b: f64| (c * a + sn * b, -sn * a + c * b);
        // Pass-through variables (angles included) first: identity.
        let is_mapped = |i: usize| {
            self.points
                .iter()
                .chain(&self.vectors)
                .any(|&(a, b)| a == i || b == i)
        };
        for i in 0..n {
            if !is_mapped(i) {
                inp_bar[i] += out_bar[i];
            }
        }
        for (i, j, is_point, (va, vb)) in self.rotated_inputs(map, pose, inp) {
            let (ra, rb) = rot(va, vb);
            let (ga, gb) = (out_bar[i], out_bar[j]);
            let (ia, ib) = rot_t(ga, gb);
            inp_bar[i] += ia;
            inp_bar[j] += ib;
            touched_theta += sign * (-rb * ga + ra * gb);
            if is_point {
                match map {
                    FrameMap::ToLocal => {
                        pose_bar.x -= ia;
                        pose_bar.y -= ib;
                    }
                    FrameMap::ToWorld => {
                        pose_bar.x += ga;
                        pose_bar.y += gb;
                    }
                    _ => {}
                }
            }
        }
        for &k in &self.angles {
            // Angles were counted as pass-through above (derivative 1 to the input).
            match map {
                FrameMap::ToLocal => touched_theta -= out_bar[k],
                FrameMap::ToWorld => touched_theta += out_bar[k],
                _ => {}
            }
        }
        pose_bar.theta += touched_theta;
    }
}
