//! # The transform chain around the network (NeuroAnimator Fig. 6c, Fig. 9)
//!
//! [`Transforms`] composes the fixed operators of this module into the emulator's input and
//! output maps,
//!
//! ```text
//! z  = Tₓ^σ([Tₓ'(s), u])                       encode_input   (network input)
//! s' = T_y^Δ(s, T_y'(T_y^σ(y)))                decode_output  (next state from output y)
//! y  = (T_y^σ)⁻¹ (T_y')⁻¹ (T_y^Δ)⁻¹(s, s')     encode_target  (training target, Fig. 9)
//! ```
//!
//! each optional ([`TransformConfig`]): the frame maps read their pose from s, so the
//! vector–Jacobian products ([`Transforms::encode_input_vjp`], [`Transforms::decode_output_vjp`])
//! route the pose's dependence on the state back into s̄. [`Transforms::fit`] fits the
//! normalization statistics to simulated transitions as the network will see them.
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §3.2, Fig. 6, 9.

use super::{delta_inverse, FrameAt, FrameMap, LocalFrame, Normalizer};
use crate::emulator::train::Dataset;
use crate::emulator::{EmulatorError, Transitions};
use ndarray::Array2;

/// Which transforms of Fig. 6 to use; each is optional.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformConfig {
    /// Predict the state change Δs instead of the next state (T_y^Δ).
    pub delta: bool,
    /// Map inputs to the model's local frame and outputs back (T_x', T_y').
    pub frame: Option<LocalFrame>,
    /// Normalize inputs and outputs to zero mean, unit variance (T_x^σ, T_y^σ).
    pub normalize: bool,
    /// Group id per network input ([local state, control]); `None`: one group per variable.
    pub input_groups: Option<Vec<usize>>,
    /// Group id per network output (state); `None`: one group per variable.
    pub output_groups: Option<Vec<usize>>,
}

impl TransformConfig {
    /// No transforms: the bare network maps [s, u] to s'.
    pub fn none() -> Self {
        Self {
            delta: false,
            frame: None,
            normalize: false,
            input_groups: None,
            output_groups: None,
        }
    }

    /// State change and per-variable normalization, with an optional local frame.
    pub fn standard(frame: Option<LocalFrame>) -> Self {
        Self {
            delta: true,
            frame,
            normalize: true,
            input_groups: None,
            output_groups: None,
        }
    }

    /// Appendix A's grouping of the inputs: all state variables share one group, all controls
    /// another.
    pub fn state_control_groups(state_dim: usize, control_dim: usize) -> Vec<usize> {
        (0..state_dim + control_dim)
            .map(|k| usize::from(k >= state_dim))
            .collect()
    }
}

/// The fixed operators around the network (Fig. 6c), fitted to data.
#[derive(Debug, Clone, PartialEq)]
pub struct Transforms {
    pub(in crate::emulator) state_dim: usize,
    pub(in crate::emulator) control_dim: usize,
    /// Whether the network predicts the state change.
    pub delta: bool,
    /// The local frame, if any.
    pub frame: Option<LocalFrame>,
    /// Input normalization (identity when normalization is off).
    pub input_norm: Normalizer,
    /// Output normalization (identity when normalization is off).
    pub output_norm: Normalizer,
    /// The inputs' normalization groups when normalized by groups (Appendix A; `None`: per
    /// variable): the unit of [`Transforms::perturb`]'s noise.
    pub input_groups: Option<Vec<usize>>,
}

impl Transforms {
    /// Transforms without normalization (identity statistics).
    pub fn unfitted(
        config: &TransformConfig,
        state_dim: usize,
        control_dim: usize,
    ) -> Result<Self, EmulatorError> {
        if let Some(f) = &config.frame {
            f.validate(state_dim)?;
        }
        Ok(Self {
            state_dim,
            control_dim,
            delta: config.delta,
            frame: config.frame.clone(),
            input_norm: Normalizer::identity(state_dim + control_dim),
            output_norm: Normalizer::identity(state_dim),
            input_groups: config.input_groups.clone().filter(|_| config.normalize),
        })
    }

    /// Builds the transforms of `config` and fits normalization statistics to `data` (after the
    /// frame and delta transforms, as the network will see them).
    pub fn fit(config: &TransformConfig, data: &Transitions) -> Result<Self, EmulatorError> {
        let (n, m) = (data.states.ncols(), data.controls.ncols());
        let mut t = Self::unfitted(config, n, m)?;
        if config.normalize {
            let raw = t.encode(data);
            let in_groups = config
                .input_groups
                .clone()
                .unwrap_or_else(|| (0..n + m).collect());
            let out_groups = config
                .output_groups
                .clone()
                .unwrap_or_else(|| (0..n).collect());
            t.input_norm = Normalizer::fit(raw.inputs.view(), &in_groups)?;
            t.output_norm = Normalizer::fit(raw.targets.view(), &out_groups)?;
        }
        Ok(t)
    }

    /// Number of state variables.
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// Number of control variables.
    pub fn control_dim(&self) -> usize {
        self.control_dim
    }

    /// The local frame read from state `s` (none without a frame), to share between the maps
    /// of one step ([`Transforms::encode_input_with`] and the other `_with` methods); with the
    /// derivatives the vector–Jacobian products need when `derivatives`.
    #[inline(always)]
    pub fn frame_at(&self, s: &[f64], derivatives: bool) -> Option<FrameAt> {
        self.frame.as_ref().map(|f| f.at(s, derivatives))
    }

    /// How many values of the frame read from a state a step keeps on a tape
    /// ([`LocalFrame::tape_len`]; none without a frame).
    pub fn frame_tape_len(&self) -> usize {
        self.frame.as_ref().map_or(0, LocalFrame::tape_len)
    }

    /// [`Transforms::frame_at`] of the state `s` whose frame was kept in `tape`
    /// ([`LocalFrame::write_tape`]): the same values.
    #[inline(always)]
    pub fn frame_at_taped(&self, s: &[f64], tape: &[f64], derivatives: bool) -> Option<FrameAt> {
        self.frame
            .as_ref()
            .map(|f| f.at_taped(s, tape, derivatives))
    }

    /// Network input z = T_x^σ(T_x'(s), u). Does not allocate.
    pub fn encode_input(&self, s: &[f64], u: &[f64], z: &mut [f64]) {
        self.encode_input_with(self.frame_at(s, false).as_ref(), s, u, z);
    }

    /// [`Transforms::encode_input`] with the frame read from `s` given
    /// ([`Transforms::frame_at`]).
    #[inline(always)]
    pub fn encode_input_with(&self, at: Option<&FrameAt>, s: &[f64], u: &[f64], z: &mut [f64]) {
        let n = self.state_dim;
        match (&self.frame, at) {
            (Some(f), Some(at)) => f.apply_with(FrameMap::ToLocal, at, s, &mut z[..n]),
            (Some(f), None) => f.apply_at(FrameMap::ToLocal, s, s, &mut z[..n]),
            (None, _) => z[..n].copy_from_slice(s),
        }
        z[n..].copy_from_slice(u);
        for ((z, m), sd) in z
            .iter_mut()
            .zip(&self.input_norm.mean)
            .zip(&self.input_norm.std)
        {
            *z = (*z - m) / sd;
        }
    }

    /// Inverse of [`Transforms::encode_input`] given a state `pose_source` with the pose the
    /// state was encoded at (the local frame forgets the pose itself).
    pub fn decode_input(&self, pose_source: &[f64], z: &[f64], s: &mut [f64], u: &mut [f64]) {
        let n = self.state_dim;
        let mut a = vec![0.0; z.len()];
        self.input_norm.denormalize(z, &mut a);
        match &self.frame {
            Some(f) => f.apply_at(FrameMap::ToWorld, pose_source, &a[..n], s),
            None => s.copy_from_slice(&a[..n]),
        }
        u.copy_from_slice(&a[n..]);
    }

    /// Network target for the transition s → s' (the inverse output transforms, Fig. 9).
    pub fn encode_target(&self, s: &[f64], s_next: &[f64], y: &mut [f64]) {
        let mut raw = vec![0.0; self.state_dim];
        if self.delta {
            delta_inverse(s, s_next, &mut raw);
        } else {
            raw.copy_from_slice(s_next);
        }
        let mut local = raw.clone();
        if let Some(f) = &self.frame {
            let map = if self.delta {
                FrameMap::DeltaToLocal
            } else {
                FrameMap::ToLocal
            };
            f.apply_at(map, s, &raw, &mut local);
        }
        self.output_norm.normalize(&local, y);
    }

    /// Next state s' from the network output y at state s (the output transforms). `tmp` is
    /// scratch of length state_dim. Does not allocate.
    pub fn decode_output(&self, s: &[f64], y: &[f64], tmp: &mut [f64], s_next: &mut [f64]) {
        self.decode_output_with(self.frame_at(s, false).as_ref(), s, y, tmp, s_next);
    }

    /// [`Transforms::decode_output`] with the frame read from `s` given
    /// ([`Transforms::frame_at`]).
    #[inline(always)]
    pub fn decode_output_with(
        &self,
        at: Option<&FrameAt>,
        s: &[f64],
        y: &[f64],
        tmp: &mut [f64],
        s_next: &mut [f64],
    ) {
        if let Some(f) = &self.frame {
            let map = if self.delta {
                FrameMap::DeltaToWorld
            } else {
                FrameMap::ToWorld
            };
            self.output_norm.denormalize(y, tmp);
            match at {
                Some(at) => f.apply_with(map, at, tmp, s_next),
                None => f.apply_at(map, s, tmp, s_next),
            }
        } else {
            self.output_norm.denormalize(y, s_next);
        }
        if self.delta {
            for (o, a) in s_next.iter_mut().zip(s) {
                *o += a;
            }
        }
    }

    /// VJP of [`Transforms::encode_input`]: adds (∂z/∂s)ᵀ z̄ to `s_bar` and writes (∂z/∂u)ᵀ z̄
    /// to `u_bar`. `tmp` is scratch of length state_dim. Does not allocate.
    pub fn encode_input_vjp(
        &self,
        s: &[f64],
        z_bar: &[f64],
        tmp: &mut [f64],
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        self.encode_input_vjp_with(None, s, z_bar, tmp, s_bar, u_bar);
    }

    /// [`Transforms::encode_input_vjp`] with the frame read from `s` given
    /// ([`Transforms::frame_at`], best with derivatives).
    #[inline(always)]
    pub fn encode_input_vjp_with(
        &self,
        at: Option<&FrameAt>,
        s: &[f64],
        z_bar: &[f64],
        tmp: &mut [f64],
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        let n = self.state_dim;
        for (k, o) in tmp.iter_mut().enumerate() {
            *o = z_bar[k] / self.input_norm.std[k];
        }
        for (k, o) in u_bar.iter_mut().enumerate() {
            *o = z_bar[n + k] / self.input_norm.std[n + k];
        }
        match &self.frame {
            Some(f) => match at {
                Some(at) => f.apply_vjp_self_with(FrameMap::ToLocal, at, s, tmp, s_bar),
                None => f.apply_vjp_self(FrameMap::ToLocal, s, tmp, s_bar),
            },
            None => {
                for (o, a) in s_bar.iter_mut().zip(tmp.iter()) {
                    *o += a;
                }
            }
        }
    }

    /// VJP of [`Transforms::decode_output`]: writes (∂s'/∂y)ᵀ s̄' to `y_bar` and adds
    /// (∂s'/∂s)ᵀ s̄' to `s_bar`. `tmp1`, `tmp2` are scratch of length state_dim.
    #[allow(clippy::too_many_arguments)]
    pub fn decode_output_vjp(
        &self,
        s: &[f64],
        y: &[f64],
        s_next_bar: &[f64],
        tmp1: &mut [f64],
        tmp2: &mut [f64],
        y_bar: &mut [f64],
        s_bar: &mut [f64],
    ) {
        self.decode_output_vjp_with(None, s, y, s_next_bar, (tmp1, tmp2), y_bar, s_bar);
    }

    /// [`Transforms::decode_output_vjp`] with the frame read from `s` given
    /// ([`Transforms::frame_at`], best with derivatives).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn decode_output_vjp_with(
        &self,
        at: Option<&FrameAt>,
        s: &[f64],
        y: &[f64],
        s_next_bar: &[f64],
        (tmp1, tmp2): (&mut [f64], &mut [f64]),
        y_bar: &mut [f64],
        s_bar: &mut [f64],
    ) {
        if self.delta {
            for (o, a) in s_bar.iter_mut().zip(s_next_bar) {
                *o += a;
            }
        }
        match &self.frame {
            Some(f) => {
                let map = if self.delta {
                    FrameMap::DeltaToWorld
                } else {
                    FrameMap::ToWorld
                };
                self.output_norm.denormalize(y, tmp1);
                tmp2.fill(0.0);
                match at {
                    Some(at) => f.apply_vjp_with(map, at, tmp1, s_next_bar, tmp2, s_bar),
                    None => f.apply_vjp_at(map, s, tmp1, s_next_bar, tmp2, s_bar),
                }
                self.output_norm.denormalize_tangent(tmp2, y_bar);
            }
            None => self.output_norm.denormalize_tangent(s_next_bar, y_bar),
        }
    }

    /// Training noise on the state inputs with corrected targets (Sanchez-Gonzalez et al.
    /// 2020, "Learning to simulate complex physics with graph networks", §4: noise on the
    /// inputs so that the net learns to correct the errors its own rollouts make).
    ///
    /// Each local state input l_k of each example moves by δ_k ~ N(0, (`scale` · sd_k)²). The
    /// spread sd_k is in the net's own normalization units: that input's spread over `ds` when
    /// the inputs are normalized one by one, and its group's pooled spread when they are
    /// normalized by groups ([`Transforms::input_groups`]), so that an input the data hold
    /// (nearly) constant, such as an out-of-plane coordinate of a planar swimmer, still learns to
    /// pull back errors of the size its group's errors have. The frame's own pose inputs, which
    /// the local frame makes constant (a spatial frame's own origin and full attitude), get
    /// none, nor does any constant input normalized alone. With the state change predicted
    /// (T_y^Δ), the target is the change from the *perturbed* state to the true next state,
    /// Δl_k − δ_k: in the local frame a state input and its change are the same coordinates
    /// (points Rᵀ(p − o) and Rᵀ(p′ − p), vectors, angles, quaternions q₀⁻¹ ⊗ q and q₀⁻¹ ⊗ Δq),
    /// so the correction is exact. Without T_y^Δ the target stays the true next state. Controls
    /// are not perturbed. Works on the encoded (normalized) set; draws every δ from `rng`.
    pub fn perturb(&self, ds: &Dataset, scale: f64, rng: &mut rand_chacha::ChaCha8Rng) -> Dataset {
        let n = self.state_dim;
        let mut out = ds.clone();
        let rows = ds.len().max(1) as f64;
        let stats = |k: usize| {
            let col = ds.inputs.column(k);
            let mean = col.sum() / rows;
            let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / rows;
            (mean, var.sqrt())
        };
        let st: Vec<(f64, f64)> = (0..n).map(stats).collect();
        let mut sd: Vec<f64> = st.iter().map(|&(_, s)| s).collect();
        if let Some(groups) = &self.input_groups {
            let pose = self
                .frame
                .as_ref()
                .map(LocalFrame::pose_indices)
                .unwrap_or_default();
            let pooled = |g: usize| {
                let members: Vec<usize> = (0..n).filter(|&k| groups[k] == g).collect();
                let mean = members.iter().map(|&k| st[k].0).sum::<f64>() / members.len() as f64;
                let var = members
                    .iter()
                    .map(|&k| {
                        ds.inputs
                            .column(k)
                            .iter()
                            .map(|v| (v - mean).powi(2))
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    / (rows * members.len() as f64);
                var.sqrt()
            };
            let ids: std::collections::BTreeSet<usize> = groups[..n].iter().copied().collect();
            let group_sd: std::collections::BTreeMap<usize, f64> =
                ids.into_iter().map(|g| (g, pooled(g))).collect();
            for (k, s) in sd.iter_mut().enumerate() {
                let constant_pose = *s <= 1e-9 && pose.contains(&k);
                *s = if constant_pose {
                    0.0
                } else {
                    group_sd[&groups[k]]
                };
            }
        }
        // A normalized input step δz is the local step δz σ_in, which is δz σ_in / σ_out of
        // normalized output.
        let gain: Vec<f64> = (0..n)
            .map(|k| {
                if self.delta {
                    self.input_norm.std[k] / self.output_norm.std[k]
                } else {
                    0.0
                }
            })
            .collect();
        for (mut z, mut y) in out
            .inputs
            .rows_mut()
            .into_iter()
            .zip(out.targets.rows_mut())
        {
            for k in 0..n {
                if sd[k] > 1e-9 {
                    let d = scale * sd[k] * crate::portable::standard_normal(rng);
                    z[k] += d;
                    y[k] -= gain[k] * d;
                }
            }
        }
        out
    }

    /// Maps transitions to (network input, network target) pairs (Fig. 9).
    pub fn encode(&self, data: &Transitions) -> Dataset {
        let (n, m) = (self.state_dim, self.control_dim);
        let rows = data.len();
        let mut inputs = Array2::zeros((rows, n + m));
        let mut targets = Array2::zeros((rows, n));
        for r in 0..rows {
            let s = data.states.row(r).to_vec();
            let u = data.controls.row(r).to_vec();
            let s1 = data.next_states.row(r).to_vec();
            let mut z = vec![0.0; n + m];
            let mut y = vec![0.0; n];
            self.encode_input(&s, &u, &mut z);
            self.encode_target(&s, &s1, &mut y);
            inputs.row_mut(r).assign(&ndarray::ArrayView1::from(&z));
            targets.row_mut(r).assign(&ndarray::ArrayView1::from(&y));
        }
        Dataset::new(inputs, targets).expect("rows agree by construction")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::transform::SpatialFrame;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A rigid body's 13 states (position, quaternion, velocity, angular velocity) and one
    /// control, normalized by quantity groups, as an encoded set whose frame pose is constant
    /// (its own origin and attitude) and whose lateral velocity (column 8) is constant too, as
    /// a planar motion's out-of-plane coordinate is.
    fn grouped(groups: bool) -> (Transforms, Dataset) {
        let config = TransformConfig {
            input_groups: groups.then(|| vec![0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4]),
            ..TransformConfig::standard(Some(SpatialFrame::rigid_body(0, 3, 7, 10).into()))
        };
        let t = Transforms::unfitted(&config, 13, 1).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let rows = 20_000;
        let mut inputs = Array2::zeros((rows, 14));
        for mut z in inputs.rows_mut() {
            z[3] = 1.0;
            for k in [7, 9, 10, 11, 12, 13] {
                z[k] = rng.random_range(-1.0..1.0) * if k == 9 { 3.0 } else { 1.0 };
            }
        }
        let targets = Array2::from_shape_fn((rows, 13), |_| rng.random_range(-1.0..1.0));
        (t, Dataset::new(inputs, targets).unwrap())
    }

    /// With group normalization every state input, a constant out-of-plane one included, moves
    /// by the requested fraction of its group's pooled spread, except the frame's own constant
    /// pose; each target moves back by its input's move; controls stay. Normalized one by one,
    /// the constant input gets none (the per-variable rule, unchanged).
    #[test]
    fn grouped_noise_is_scaled_by_the_groups_spread() {
        let (t, clean) = grouped(true);
        let scale = 0.1;
        let noisy = t.perturb(&clean, scale, &mut ChaCha8Rng::seed_from_u64(4));
        let rows = clean.len() as f64;
        let moved = |k: usize| -> Vec<f64> {
            (0..clean.len())
                .map(|r| noisy.inputs[[r, k]] - clean.inputs[[r, k]])
                .collect()
        };
        let rms = |v: &[f64]| (v.iter().map(|d| d * d).sum::<f64>() / rows).sqrt();
        for k in 0..7 {
            assert!(moved(k).iter().all(|&d| d == 0.0), "pose input {k} moved");
        }
        // Group 2 (velocity): columns 7, 8, 9 with spreads 1/√3, 0 and √3 around mean 0; the
        // pooled spread is √((1/3 + 0 + 3) / 3).
        let pooled = ((1.0 / 3.0 + 3.0) / 3.0f64).sqrt();
        for k in [7, 8, 9] {
            let got = rms(&moved(k));
            assert!(
                (got / (scale * pooled) - 1.0).abs() < 0.03,
                "input {k}: moved {got}, want {}",
                scale * pooled
            );
        }
        for r in 0..clean.len() {
            for k in 0..13 {
                let dz = noisy.inputs[[r, k]] - clean.inputs[[r, k]];
                let dy = noisy.targets[[r, k]] - clean.targets[[r, k]];
                assert!((dy + dz).abs() < 1e-12, "row {r} target {k}");
            }
            assert_eq!(
                noisy.inputs[[r, 13]],
                clean.inputs[[r, 13]],
                "control moved"
            );
        }
        let (t, clean) = grouped(false);
        let noisy = t.perturb(&clean, scale, &mut ChaCha8Rng::seed_from_u64(4));
        assert_eq!(noisy.inputs.column(8), clean.inputs.column(8));
        assert!(noisy.inputs.column(9) != clean.inputs.column(9));
        // The dolphin's global net is normalized by groups, so its noise is the groups'.
        use crate::emulator::hierarchy::{global_transforms, GLOBAL_DIM};
        const N_SEGMENTS: usize = 6;
        let g = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS).unwrap();
        assert_eq!(
            g.input_groups.map(|v| v.len()),
            Some(GLOBAL_DIM + N_SEGMENTS)
        );
    }
}
