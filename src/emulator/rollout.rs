//! # k-step rollout training
//!
//! A net trained for one super-step is used for 40 in a row by control learning (§4), and its
//! small one-step errors compound: the rollout leaves the states it was trained on. The k-step
//! rollout loss ("multi-step" training, Venkatraman, Hebert and Bagnell 2015; Abbeel et al.
//! 2005) trains the net on its own rollouts instead. From the first state s_0 of a simulated
//! window of k super-steps (the same episodes and control processes as the one-step data,
//! [`super::dataset::sample_windows`]) the emulator runs k steps under the window's controls,
//!
//! ```text
//! ŝ_0 = s_0,   ŝ_i = T(ŝ_{i−1}, u_{i−1}; w)      (T: transforms ∘ net ∘ transforms, Fig. 6c)
//! L_k(w) = 1/(R k n) Σ_windows Σ_{i=1..k} Σ_v ((ŝ_{i,v} − s_{i,v}) / σ_v)²
//! ```
//!
//! with the simulated states s_i as targets and σ_v the spread of variable v's one-step change
//! over the one-step training data (so L_1 is about the one-step error). The gradient is
//! backpropagation through the whole chain: the cotangent of ŝ_i flows through the output
//! transforms, the net (adding to ∂L/∂w) and the input transforms (local frame at ŝ_{i−1},
//! normalization) into ŝ_{i−1}, and on to the earlier steps; every transform's derivative is
//! exact ([`super::step_vjp`]), no approximation is made. Fine-tuning
//! ([`fine_tune`]) minimizes the one-step training loss plus `weight` · L_k by L-BFGS from the
//! one-step net, stopping early on the same sum over held-out data and windows.

use super::anchor::Anchor;
use super::dataset::Windows;
use super::mlp::Mlp;
use super::train::{
    minimize_early_stopping, mse, Dataset, Evaluated, FullBatchConfig, FullBatchMethod,
    TrainReport, TrainingProblem,
};
use super::{steps_many, vjps_many, Emulator, EmulatorError, ManyScratch, Transforms, Transitions};
use argmin::core::{CostFunction, Gradient};
use ndarray::Array1;
use rayon::prelude::*;

/// Windows per parallel chunk; fixed, and the chunks' sums are added in order, so the loss and
/// its gradient are bit-identical for any number of rayon threads.
const WINDOW_CHUNK: usize = 16;

/// Per-variable scale σ_v of the rollout loss: the spread of each state variable's one-step
/// change s' − s over `data` (floored at 1e-9 of the largest, so a constant variable counts
/// little but stays finite).
pub fn change_spread(data: &Transitions) -> Vec<f64> {
    let d = &data.next_states - &data.states;
    let rows = d.nrows().max(1) as f64;
    let sd: Vec<f64> = d
        .columns()
        .into_iter()
        .map(|c| {
            let mean = c.sum() / rows;
            (c.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / rows).sqrt()
        })
        .collect();
    let floor = 1e-9 * sd.iter().copied().fold(1e-300, f64::max);
    sd.into_iter().map(|s| s.max(floor)).collect()
}

/// The k-step rollout loss L_k of networks shaped like one net, on fixed windows.
#[derive(Debug, Clone)]
pub struct RolloutLoss<'a> {
    transforms: &'a Transforms,
    windows: &'a Windows,
    inv_var: Vec<f64>,
}

impl<'a> RolloutLoss<'a> {
    /// The loss on `windows` through `transforms`, with per-variable scales `sigma`
    /// ([`change_spread`]).
    pub fn new(
        transforms: &'a Transforms,
        windows: &'a Windows,
        sigma: &[f64],
    ) -> Result<Self, EmulatorError> {
        let (n, m) = (transforms.state_dim, transforms.control_dim);
        for (what, expected, got) in [
            ("rollout window states", n, windows.state_dim),
            ("rollout window controls", m, windows.control_dim),
            ("rollout scales", n, sigma.len()),
        ] {
            if expected != got {
                return Err(EmulatorError::Dimension {
                    what,
                    expected,
                    got,
                });
            }
        }
        if windows.is_empty() {
            return Err(EmulatorError::TooFewExamples(0));
        }
        Ok(Self {
            transforms,
            windows,
            inv_var: sigma.iter().map(|s| 1.0 / (s * s)).collect(),
        })
    }

    /// L_k(w) of `mlp`.
    pub fn value(&self, mlp: &Mlp) -> f64 {
        self.eval(mlp, None)
    }

    /// L_k(w) of `mlp`; adds ∂L_k/∂w to `grad`.
    pub fn value_grad(&self, mlp: &Mlp, grad: &mut [f64]) -> f64 {
        self.eval(mlp, Some(grad))
    }

    fn eval(&self, mlp: &Mlp, grad: Option<&mut [f64]>) -> f64 {
        let w = self.windows;
        let chunks = w.len().div_ceil(WINDOW_CHUNK);
        let want_grad = grad.is_some();
        let parts: Vec<(f64, Vec<f64>)> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let rows = c * WINDOW_CHUNK..w.len().min((c + 1) * WINDOW_CHUNK);
                self.chunk(mlp, rows, want_grad)
            })
            .collect();
        let scale = 1.0 / (w.len() * w.k * w.state_dim) as f64;
        let mut total = 0.0;
        let mut grad = grad;
        for (loss, g) in parts {
            total += loss;
            if let Some(out) = grad.as_deref_mut() {
                for (o, v) in out.iter_mut().zip(&g) {
                    *o += scale * v;
                }
            }
        }
        scale * total
    }

    /// Unscaled loss and gradient sums over windows `rows`.
    ///
    /// The windows of the chunk go through each step together ([`steps_many`], [`vjps_many`]:
    /// the network's passes take them all at once, the transforms one by one), and every sum
    /// is kept in the order of one window after the other (the loss's terms window by window,
    /// step by step; the weight-gradient terms window by window, last step first), so the
    /// results are the same bits as running the windows one at a time.
    fn chunk(&self, mlp: &Mlp, rows: std::ops::Range<usize>, want_grad: bool) -> (f64, Vec<f64>) {
        let (t, w) = (self.transforms, self.windows);
        let (n, m, k, q) = (w.state_dim, w.control_dim, w.k, mlp.n_hidden());
        let (b, p) = (rows.len(), n + m);
        let mut grad = vec![0.0; if want_grad { mlp.n_weights() } else { 0 }];
        let mut bufs = BUFFERS.with_borrow_mut(std::mem::take);
        bufs.reset(t, mlp, (b, k));
        let ChunkBuffers {
            traj,
            zs,
            hs,
            ys,
            us,
            next_bar,
            prev_bar,
            many,
        } = &mut bufs;
        for (wi, r) in rows.clone().enumerate() {
            traj[wi * n..(wi + 1) * n].copy_from_slice(w.state(r, 0));
        }
        for i in 0..k {
            for (wi, r) in rows.clone().enumerate() {
                us[wi * m..(wi + 1) * m].copy_from_slice(w.control(r, i));
            }
            let (done, rest) = traj.split_at_mut((i + 1) * b * n);
            let at = |width: usize| i * b * width..(i + 1) * b * width;
            steps_many(
                t,
                mlp,
                (&done[i * b * n..], &us[..b * m]),
                (&mut zs[at(p)], &mut hs[at(q)], &mut ys[at(n)]),
                many,
                &mut rest[..b * n],
            );
        }
        // The loss's terms window by window, step by step, in one chain (held in a register:
        // as a `+=` into a local it was kept on the stack, each addition waiting on a store).
        let mut loss = 0.0;
        for (wi, r) in rows.clone().enumerate() {
            for i in 0..k {
                let (s_next, truth) = (&traj[((i + 1) * b + wi) * n..][..n], w.state(r, i + 1));
                loss = s_next
                    .iter()
                    .zip(truth)
                    .zip(&self.inv_var)
                    .fold(loss, |l, ((s, t), iv)| l + (s - t).powi(2) * iv);
            }
        }
        if want_grad {
            // The cotangents of each window's state at the step being undone (`next_bar`) and
            // at the step before. The backward passes' weight-gradient terms go on the tape in
            // the order of one window after the other, each from its last step back
            // ([`Mlp::weight_grad_many`]: the same sums, bit for bit, as adding each at once).
            next_bar[..b * n].fill(0.0);
            let r_out = mlp.n_out();
            let mut tape = TAPE.with_borrow_mut(std::mem::take);
            tape.reset(b * k, (p, q, r_out));
            for i in (1..=k).rev() {
                for (wi, r) in rows.clone().enumerate() {
                    let (s_hat, truth) = (&traj[(i * b + wi) * n..][..n], w.state(r, i));
                    let bar = &mut next_bar[wi * n..(wi + 1) * n];
                    for v in 0..n {
                        bar[v] += 2.0 * (s_hat[v] - truth[v]) * self.inv_var[v];
                    }
                }
                let j = i - 1;
                let (sj, hj, yj) = (
                    &traj[j * b * n..i * b * n],
                    &hs[j * b * q..i * b * q],
                    &ys[j * b * n..i * b * n],
                );
                prev_bar[..b * n].fill(0.0);
                vjps_many(
                    t,
                    mlp,
                    (sj, hj, yj),
                    &next_bar[..b * n],
                    many,
                    &mut prev_bar[..b * n],
                );
                for wi in 0..b {
                    let e = wi * k + (k - i);
                    let row = j * b + wi;
                    tape.x[e * p..(e + 1) * p].copy_from_slice(&zs[row * p..(row + 1) * p]);
                    tape.h[e * q..(e + 1) * q].copy_from_slice(&hs[row * q..(row + 1) * q]);
                    tape.hb[e * q..(e + 1) * q].copy_from_slice(many.hidden_bar(wi, q));
                    tape.yb[e * r_out..(e + 1) * r_out].copy_from_slice(many.output_bar(wi, r_out));
                }
                std::mem::swap(next_bar, prev_bar);
            }
            tape.len = b * k;
            mlp.weight_grad_many(tape.len, (&tape.x, &tape.h, &tape.hb, &tape.yb), &mut grad);
            TAPE.with_borrow_mut(|t| *t = tape);
        }
        BUFFERS.with_borrow_mut(|t| *t = bufs);
        (loss, grad)
    }
}

/// A chunk's rollouts, step-major (the b windows' values at step i are rows i·b … (i + 1)·b − 1):
/// the states (k + 1 steps), each step's network input, hidden activations and output (kept
/// for the backward pass), one step's controls, the state cotangents of two steps, and the
/// buffers of [`steps_many`] and [`vjps_many`].
#[derive(Debug, Default)]
struct ChunkBuffers {
    traj: Vec<f64>,
    zs: Vec<f64>,
    hs: Vec<f64>,
    ys: Vec<f64>,
    us: Vec<f64>,
    next_bar: Vec<f64>,
    prev_bar: Vec<f64>,
    many: ManyScratch,
}

impl ChunkBuffers {
    /// Room for `b` windows of `k` steps of transforms `t` and net `mlp` (grown, never shrunk:
    /// a worker thread's buffers serve every chunk it takes; every value a chunk reads it
    /// writes first).
    fn reset(&mut self, t: &Transforms, mlp: &Mlp, (b, k): (usize, usize)) {
        let (n, m, q) = (t.state_dim, t.control_dim, mlp.n_hidden());
        for (v, len) in [
            (&mut self.traj, (k + 1) * b * n),
            (&mut self.zs, k * b * (n + m)),
            (&mut self.hs, k * b * q),
            (&mut self.ys, k * b * n),
            (&mut self.us, b * m),
            (&mut self.next_bar, b * n),
            (&mut self.prev_bar, b * n),
        ] {
            if v.len() < len {
                v.resize(len, 0.0);
            }
        }
        self.many.reset(t, mlp, b);
    }
}

/// The backward passes' inputs to the weight gradient, one row per pass, in order.
#[derive(Debug, Default)]
struct GradTape {
    x: Vec<f64>,
    h: Vec<f64>,
    hb: Vec<f64>,
    yb: Vec<f64>,
    len: usize,
}

impl GradTape {
    /// Empty, with room for `rows` passes of a (p, q, r) net (grown, never shrunk: a worker
    /// thread's tape serves every chunk it takes).
    fn reset(&mut self, rows: usize, (p, q, r): (usize, usize, usize)) {
        for (v, width) in [
            (&mut self.x, p),
            (&mut self.h, q),
            (&mut self.hb, q),
            (&mut self.yb, r),
        ] {
            if v.len() < rows * width {
                v.resize(rows * width, 0.0);
            }
        }
        self.len = 0;
    }
}

std::thread_local! {
    /// Each thread's [`GradTape`], kept between chunks so that the rollout loss does not
    /// allocate (and fault in) a fresh one per chunk.
    static TAPE: std::cell::RefCell<GradTape> = std::cell::RefCell::new(GradTape::default());
    /// Each thread's [`ChunkBuffers`], for the same reason.
    static BUFFERS: std::cell::RefCell<ChunkBuffers> =
        std::cell::RefCell::new(ChunkBuffers::default());
}

/// The fine-tuning objective over flat weights: the one-step loss (eq. 5, as
/// [`TrainingProblem`]) plus `weight` · L_k. The line search asks for the cost and then the
/// gradient at the same weights (and L-BFGS the gradient again at the accepted point), so one
/// evaluation computes both and keeps them for the next request at the same weights.
#[derive(Debug)]
pub struct FineTuneProblem<'a> {
    one_step: TrainingProblem<'a>,
    rollout: RolloutLoss<'a>,
    weight: f64,
    shape: (usize, usize, usize),
    anchor: Option<&'a Anchor>,
    last: std::sync::Mutex<Option<Evaluated>>,
}

impl<'a> FineTuneProblem<'a> {
    /// The objective for nets shaped like `mlp`.
    pub fn new(mlp: &Mlp, one_step: &'a Dataset, rollout: RolloutLoss<'a>, weight: f64) -> Self {
        Self {
            one_step: TrainingProblem::new(mlp, one_step),
            rollout,
            weight,
            shape: (mlp.n_in(), mlp.n_hidden(), mlp.n_out()),
            anchor: None,
            last: std::sync::Mutex::new(None),
        }
    }

    /// The same objective over nets that reproduce `anchor` exactly ([`Anchor`]).
    pub fn anchored(self, anchor: Option<&'a Anchor>) -> Self {
        Self { anchor, ..self }
    }

    /// Cost and gradient at `w` (from the last evaluation when `w` is the same).
    fn eval(&self, w: &Array1<f64>) -> Result<(f64, Array1<f64>), argmin::core::Error> {
        let mut last = self.last.lock().expect("no panics while held");
        if let Some((lw, c, g)) = last.as_ref() {
            if lw == w {
                return Ok((*c, g.clone()));
            }
        }
        // Both losses at the projected weights; the sum of their gradients is pulled back once.
        let mut net = net_of(self.shape, w.as_slice().expect("contiguous weights"));
        if let Some(a) = self.anchor {
            a.project(&mut net);
        }
        let wp = Array1::from(net.weights().to_vec());
        let mut g = vec![0.0; net.n_weights()];
        let roll = self.rollout.value_grad(&net, &mut g);
        let (one_cost, one) = self.one_step.cost_and_gradient(&wp);
        let cost = one_cost + self.weight * roll;
        let mut grad = Array1::from_iter(one.iter().zip(&g).map(|(a, b)| a + self.weight * b));
        if let Some(a) = self.anchor {
            a.pull_back(&net, grad.as_slice_mut().expect("contiguous gradient"));
        }
        *last = Some((w.clone(), cost, grad.clone()));
        Ok((cost, grad))
    }
}

fn net_of((p, q, r): (usize, usize, usize), w: &[f64]) -> Mlp {
    Mlp::from_weights(p, q, r, w.to_vec())
}

impl CostFunction for FineTuneProblem<'_> {
    type Param = Array1<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.eval(w)?.0)
    }
}

impl Gradient for FineTuneProblem<'_> {
    type Param = Array1<f64>;
    type Gradient = Array1<f64>;
    fn gradient(&self, w: &Self::Param) -> Result<Self::Gradient, argmin::core::Error> {
        Ok(self.eval(w)?.1)
    }
}

/// Rollout fine-tuning data and settings for [`fine_tune`].
#[derive(Debug, Clone, Copy)]
pub struct FineTune<'a> {
    /// One-step training examples (network space, as trained on).
    pub train: &'a Dataset,
    /// One-step held-out examples.
    pub held: &'a Dataset,
    /// Training windows.
    pub train_windows: &'a Windows,
    /// Held-out windows.
    pub held_windows: &'a Windows,
    /// Per-variable scales σ_v ([`change_spread`]).
    pub sigma: &'a [f64],
    /// Weight of L_k against the one-step loss.
    pub weight: f64,
    /// L-BFGS iteration limit.
    pub max_iters: u64,
    /// Early-stopping patience (iterations).
    pub patience: usize,
    /// Relative held-out improvement that counts.
    pub min_improvement: f64,
    /// An example the net keeps reproducing exactly ([`Anchor`]), if any.
    pub anchor: Option<&'a Anchor>,
}

/// Fine-tunes `emulator`'s net on the one-step loss + `weight` · L_k by L-BFGS, early-stopped on
/// the same sum over the held-out examples and windows; leaves it at the best held-out weights.
/// The report's errors are those sums.
pub fn fine_tune(emulator: &mut Emulator, ft: &FineTune<'_>) -> Result<TrainReport, EmulatorError> {
    if !(ft.weight > 0.0 && ft.weight.is_finite()) {
        return Err(EmulatorError::Setting {
            name: "rollout_weight",
            value: ft.weight,
        });
    }
    let transforms = emulator.transforms.clone();
    let train_loss = RolloutLoss::new(&transforms, ft.train_windows, ft.sigma)?;
    let held_loss = RolloutLoss::new(&transforms, ft.held_windows, ft.sigma)?;
    let mlp = emulator.mlp_mut();
    let problem = FineTuneProblem::new(mlp, ft.train, train_loss, ft.weight).anchored(ft.anchor);
    let shape = (mlp.n_in(), mlp.n_hidden(), mlp.n_out());
    let held = |w: &[f64]| {
        let mut net = net_of(shape, w);
        if let Some(a) = ft.anchor {
            a.project(&mut net);
        }
        mse(&net, ft.held) + ft.weight * held_loss.value(&net)
    };
    let config = FullBatchConfig {
        method: FullBatchMethod::Lbfgs { memory: 20 },
        max_iters: ft.max_iters,
        patience: ft.patience,
        min_improvement: ft.min_improvement,
    };
    let report = minimize_early_stopping(problem, mlp.weights_mut(), &held, &config)?;
    if let Some(a) = ft.anchor {
        a.project(mlp);
    }
    Ok(report)
}

/// L_k of `emulator` on `windows` with scales `sigma`.
pub fn rollout_loss(
    emulator: &Emulator,
    windows: &Windows,
    sigma: &[f64],
) -> Result<f64, EmulatorError> {
    Ok(RolloutLoss::new(&emulator.transforms, windows, sigma)?.value(&emulator.mlp))
}
