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

use super::EmulatorError;
use ndarray::ArrayView2;

/// Normalization to zero mean, unit variance per group of variables (Appendix A).
#[derive(Debug, Clone, PartialEq)]
pub struct Normalizer {
    /// Mean per variable (shared within a group).
    pub mean: Vec<f64>,
    /// Standard deviation per variable (shared within a group; never zero).
    pub std: Vec<f64>,
}

impl Normalizer {
    /// The identity map on `n` variables (mean 0, std 1).
    pub fn identity(n: usize) -> Self {
        Self {
            mean: vec![0.0; n],
            std: vec![1.0; n],
        }
    }

    /// Fits statistics to the rows of `data` (N × K). `groups[k]` is the group id of column `k`;
    /// columns with the same id share a mean and a standard deviation (eqs. 17–18).
    pub fn fit(data: ArrayView2<'_, f64>, groups: &[usize]) -> Result<Self, EmulatorError> {
        let k = data.ncols();
        if groups.len() != k {
            return Err(EmulatorError::Dimension {
                what: "normalization groups",
                expected: k,
                got: groups.len(),
            });
        }
        if data.nrows() < 2 {
            return Err(EmulatorError::TooFewExamples(data.nrows()));
        }
        let n_groups = groups.iter().copied().max().map_or(0, |g| g + 1);
        let mut sum = vec![0.0; n_groups];
        let mut count = vec![0usize; n_groups];
        for row in data.rows() {
            for (c, v) in row.iter().enumerate() {
                sum[groups[c]] += v;
                count[groups[c]] += 1;
            }
        }
        let mu: Vec<f64> = sum
            .iter()
            .zip(&count)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
            .collect();
        let mut ss = vec![0.0; n_groups];
        for row in data.rows() {
            for (c, v) in row.iter().enumerate() {
                let g = groups[c];
                ss[g] += (v - mu[g]) * (v - mu[g]);
            }
        }
        let sd: Vec<f64> = (0..n_groups)
            .map(|g| {
                let var = if count[g] > 1 {
                    ss[g] / (count[g] - 1) as f64
                } else {
                    0.0
                };
                let s = var.sqrt();
                if s > 1e-12 * (1.0 + mu[g].abs()) {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        Ok(Self {
            mean: groups.iter().map(|&g| mu[g]).collect(),
            std: groups.iter().map(|&g| sd[g]).collect(),
        })
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.mean.len()
    }

    /// Whether there are no variables.
    pub fn is_empty(&self) -> bool {
        self.mean.is_empty()
    }

    /// Forward: z = (x − μ) / σ.
    pub fn normalize(&self, x: &[f64], z: &mut [f64]) {
        for (((z, x), m), s) in z.iter_mut().zip(x).zip(&self.mean).zip(&self.std) {
            *z = (x - m) / s;
        }
    }

    /// Inverse: x = μ + σ z.
    pub fn denormalize(&self, z: &[f64], x: &mut [f64]) {
        for (((x, z), m), s) in x.iter_mut().zip(z).zip(&self.mean).zip(&self.std) {
            *x = m + s * z;
        }
    }

    /// JVP and VJP of [`Normalizer::normalize`] (a diagonal map): `out = v / σ`.
    pub fn normalize_tangent(&self, v: &[f64], out: &mut [f64]) {
        for ((o, v), s) in out.iter_mut().zip(v).zip(&self.std) {
            *o = v / s;
        }
    }

    /// JVP and VJP of [`Normalizer::denormalize`] (a diagonal map): `out = σ v`.
    pub fn denormalize_tangent(&self, v: &[f64], out: &mut [f64]) {
        for ((o, v), s) in out.iter_mut().zip(v).zip(&self.std) {
            *o = v * s;
        }
    }
}

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
    /// +1 for maps that rotate by +θ₀ (to world), −1 for maps that rotate by −θ₀.
    fn sign(self) -> f64 {
        match self {
            Self::ToLocal | Self::DeltaToLocal => -1.0,
            Self::ToWorld | Self::DeltaToWorld => 1.0,
        }
    }
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
        let (sn, c) = phi.sin_cos();
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
        for &k in &self.angles {
            out[k] = match map {
                FrameMap::ToLocal => inp[k] - pose.theta,
                FrameMap::ToWorld => inp[k] + pose.theta,
                _ => inp[k],
            };
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
        let (sn, c) = (sign * pose.theta).sin_cos();
        let rot = |a: f64, b: f64| (c * a - sn * b, sn * a + c * b);
        let pairs = self
            .points
            .iter()
            .map(|p| (p, true))
            .chain(self.vectors.iter().map(|p| (p, false)));
        for (&(i, j), is_point) in pairs {
            // v' is what gets rotated; out = R(φ) v' (+ p₀ for ToWorld points).
            let (va, vb) = if is_point && map == FrameMap::ToLocal {
                (inp[i] - pose.x, inp[j] - pose.y)
            } else {
                (inp[i], inp[j])
            };
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
        for &k in &self.angles {
            d_out[k] = match map {
                FrameMap::ToLocal => d_inp[k] - d_pose.theta,
                FrameMap::ToWorld => d_inp[k] + d_pose.theta,
                _ => d_inp[k],
            };
        }
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
        let (sn, c) = (sign * pose.theta).sin_cos();
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
        let pairs = self
            .points
            .iter()
            .map(|p| (p, true))
            .chain(self.vectors.iter().map(|p| (p, false)));
        for (&(i, j), is_point) in pairs {
            let (va, vb) = if is_point && map == FrameMap::ToLocal {
                (inp[i] - pose.x, inp[j] - pose.y)
            } else {
                (inp[i], inp[j])
            };
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

/// A 3D pose: origin and orientation quaternion `[w, x, y, z]`. The quaternion need not be
/// exactly unit: the rotation used is R(q) = M(q) / |q|², which is orthogonal for any q ≠ 0.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Pose3 {
    /// Origin (x, y, z).
    pub origin: [f64; 3],
    /// Orientation quaternion `[w, x, y, z]`.
    pub q: [f64; 4],
}

/// Hamilton product a ⊗ b of quaternions `[w, x, y, z]`.
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn quat_conj(a: [f64; 4]) -> [f64; 4] {
    [a[0], -a[1], -a[2], -a[3]]
}

type M3 = [[f64; 3]; 3];

fn mat_vec(m: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn mat_t_vec(m: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|j| m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2])
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// R(q) = M(q)/|q|² with M(q) = (w² − v·v) I + 2 v vᵀ + 2 w [v]×, and ∂R/∂q_k.
fn rotation_and_derivatives(q: [f64; 4]) -> (M3, [M3; 4]) {
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
    for k in 0..3 {
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
    for k in 0..4 {
        for i in 0..3 {
            for j in 0..3 {
                dr[k][i][j] = (dm[k][i][j] - 2.0 * q[k] * r[i][j]) / n;
            }
        }
    }
    (r, dr)
}

/// The local frame of a 3D model whose pose (origin, orientation quaternion) is part of its
/// state; e.g. the lunar lander (position, quaternion, velocity, angular velocity).
///
/// Local coordinates: points Rᵀ(p − o), vectors Rᵀ v, quaternions q₀⁻¹ ⊗ q; state changes are
/// only rotated (quaternion changes: q₀⁻¹ ⊗ Δq). Variables not listed pass through.
#[derive(Debug, Clone, PartialEq)]
pub struct SpatialFrame {
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

impl SpatialFrame {
    /// A rigid body whose state holds position at `pos..pos+3`, quaternion at `quat..quat+4`,
    /// linear velocity at `vel..vel+3` and angular velocity (world frame) at `omega..omega+3`.
    pub fn rigid_body(pos: usize, quat: usize, vel: usize, omega: usize) -> Self {
        let tri = |a: usize| [a, a + 1, a + 2];
        let quad = [quat, quat + 1, quat + 2, quat + 3];
        Self {
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

    /// The pose read from a world-frame state.
    pub fn pose(&self, s: &[f64]) -> Pose3 {
        Pose3 {
            origin: self.origin.map(|i| s[i]),
            q: self.orientation.map(|i| s[i]),
        }
    }

    /// Adds a pose cotangent to the state cotangent (the pose is read from the state).
    pub fn pose_vjp(&self, pose_bar: &Pose3, s_bar: &mut [f64]) {
        for (i, v) in self.origin.iter().zip(pose_bar.origin) {
            s_bar[*i] += v;
        }
        for (i, v) in self.orientation.iter().zip(pose_bar.q) {
            s_bar[*i] += v;
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
        out.copy_from_slice(inp);
        let (r, _) = rotation_and_derivatives(pose.q);
        let local = map.sign() < 0.0;
        for (t, is_point) in self.triples() {
            let mut v = t.map(|i| inp[i]);
            if is_point && map == FrameMap::ToLocal {
                v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
            }
            let mut o = if local {
                mat_t_vec(&r, v)
            } else {
                mat_vec(&r, v)
            };
            if is_point && map == FrameMap::ToWorld {
                o = [0, 1, 2].map(|k| o[k] + pose.origin[k]);
            }
            for k in 0..3 {
                out[t[k]] = o[k];
            }
        }
        let n = pose.q.iter().map(|a| a * a).sum::<f64>();
        for qi in &self.quaternions {
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
            for k in 0..4 {
                let dq = quat_partial(map, pose.q, a, k);
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
        let mapped = |i: usize| {
            self.triples().any(|(t, _)| t.contains(&i))
                || self.quaternions.iter().any(|q| q.contains(&i))
        };
        for (i, b) in inp_bar.iter_mut().enumerate() {
            if !mapped(i) {
                *b += out_bar[i];
            }
        }
        let (r, dr) = rotation_and_derivatives(pose.q);
        let local = map.sign() < 0.0;
        for (t, is_point) in self.triples() {
            let mut v = t.map(|i| inp[i]);
            if is_point && map == FrameMap::ToLocal {
                v = [0, 1, 2].map(|k| v[k] - pose.origin[k]);
            }
            let g = t.map(|i| out_bar[i]);
            let ib = if local {
                mat_vec(&r, g)
            } else {
                mat_t_vec(&r, g)
            };
            for k in 0..3 {
                inp_bar[t[k]] += ib[k];
            }
            for (k, drk) in dr.iter().enumerate() {
                let term = if local {
                    mat_t_vec(drk, v)
                } else {
                    mat_vec(drk, v)
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
        for qi in &self.quaternions {
            let a = qi.map(|i| inp[i]);
            let g = qi.map(|i| out_bar[i]);
            // Transposes of left multiplication: L(q)ᵀ = L(q*).
            let ib = if local {
                quat_mul(pose.q, g).map(|x| x / n)
            } else {
                quat_mul(quat_conj(pose.q), g)
            };
            for k in 0..4 {
                inp_bar[qi[k]] += ib[k];
            }
            for k in 0..4 {
                let dq = quat_partial(map, pose.q, a, k);
                pose_bar.q[k] += (0..4).map(|c| dq[c] * g[c]).sum::<f64>();
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

/// ∂/∂q₀ₖ of [`quat_linear`].
fn quat_partial(map: FrameMap, q0: [f64; 4], a: [f64; 4], k: usize) -> [f64; 4] {
    let mut e = [0.0; 4];
    e[k] = 1.0;
    if map.sign() < 0.0 {
        let n = q0.iter().map(|x| x * x).sum::<f64>();
        let f = quat_mul(quat_conj(q0), a).map(|x| x / n);
        let d = quat_mul(quat_conj(e), a);
        [0, 1, 2, 3].map(|c| d[c] / n - 2.0 * q0[k] * f[c] / n)
    } else {
        quat_mul(e, a)
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

impl LocalFrame {
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
            Self::Spatial(f) => f.apply_jvp(map, &f.pose(ps), inp, d_inp, &f.pose(d_ps), d_out),
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
                f.pose_vjp(&pb, s_bar);
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
                f.pose_vjp(&pb, ps_bar);
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
    use ndarray::Array2;
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
        vec![(frame().into(), 9), (spatial().into(), 21)]
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
    fn normalizer_fits_groups_and_inverts() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let data = Array2::from_shape_fn((500, 4), |(_, c)| {
            [10.0, 20.0, -3.0, 0.0][c] + [1.0, 3.0, 0.5, 0.0][c] * rng.random_range(-1.0..1.0)
        });
        // Columns 0 and 1 share a group; 2 alone; 3 is constant.
        let n = Normalizer::fit(data.view(), &[0, 0, 1, 2]).unwrap();
        assert_eq!(n.mean[0], n.mean[1]);
        assert_eq!(n.std[0], n.std[1]);
        assert!((n.mean[0] - 15.0).abs() < 0.5);
        assert!((n.mean[2] + 3.0).abs() < 0.1);
        assert_eq!(n.std[3], 1.0);
        // Per-variable groups give zero mean, unit variance columns.
        let n = Normalizer::fit(data.view(), &[0, 1, 2, 3]).unwrap();
        let mut z = Array2::zeros((500, 4));
        for (r, mut zr) in data.rows().into_iter().zip(z.rows_mut()) {
            n.normalize(r.as_slice().unwrap(), zr.as_slice_mut().unwrap());
        }
        for c in 0..3 {
            let col = z.column(c);
            assert!(col.mean().unwrap().abs() < 1e-12);
            assert!((col.var(1.0) - 1.0).abs() < 1e-12);
        }
        let x = [1.0, -2.0, 3.5, 0.25];
        let mut zz = [0.0; 4];
        let mut back = [0.0; 4];
        n.normalize(&x, &mut zz);
        n.denormalize(&zz, &mut back);
        for k in 0..4 {
            assert!((back[k] - x[k]).abs() < 1e-12);
        }
        // Tangent maps: (f(x + h v) − f(x − h v)) / 2h.
        let v = [0.3, -0.1, 2.0, 1.0];
        let mut t = [0.0; 4];
        n.normalize_tangent(&v, &mut t);
        let h = 1e-5;
        let xp: Vec<f64> = x.iter().zip(&v).map(|(a, b)| a + h * b).collect();
        let xm: Vec<f64> = x.iter().zip(&v).map(|(a, b)| a - h * b).collect();
        let (mut zp, mut zm) = ([0.0; 4], [0.0; 4]);
        n.normalize(&xp, &mut zp);
        n.normalize(&xm, &mut zm);
        for k in 0..4 {
            assert!(((zp[k] - zm[k]) / (2.0 * h) - t[k]).abs() < 1e-8);
        }
        n.denormalize_tangent(&t, &mut back);
        for k in 0..4 {
            assert!((back[k] - v[k]).abs() < 1e-12);
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
