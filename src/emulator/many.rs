//! Many rollouts of one net stepped at once ([`steps_many`], [`vjps_many`]): the network's
//! passes over all rows together, the transforms row by row, with their buffers.

use super::mlp::Mlp;
use super::step::avx_dispatched;
use super::{transform, Transforms};

/// The buffers of [`steps_many`] and [`vjps_many`] for a chunk of `rows` rollouts of one net
/// (each a row of the chunk; the network's values of each step are kept by the caller).
#[derive(Debug, Clone, Default)]
pub(crate) struct ManyScratch {
    /// The frame read from each row's state.
    ats: Vec<Option<transform::FrameAt>>,
    /// Output cotangents, hidden cotangents and input cotangents, a row each.
    y_bar: Vec<f64>,
    h_bar: Vec<f64>,
    z_bar: Vec<f64>,
    /// Temporaries of one row (n values each) and the control cotangent (m).
    t1: Vec<f64>,
    t2: Vec<f64>,
    u_bar: Vec<f64>,
}

impl ManyScratch {
    /// Sized for `rows` rows of transforms `t` and network `mlp` (grown, never shrunk).
    pub(crate) fn reset(&mut self, t: &Transforms, mlp: &Mlp, rows: usize) {
        let (n, m, q) = (t.state_dim, t.control_dim, mlp.n_hidden());
        if self.ats.len() < rows {
            self.ats.resize(rows, None);
        }
        for (v, len) in [
            (&mut self.y_bar, rows * n),
            (&mut self.h_bar, rows * q),
            (&mut self.z_bar, rows * (n + m)),
            (&mut self.t1, n),
            (&mut self.t2, n),
            (&mut self.u_bar, m),
        ] {
            if v.len() < len {
                v.resize(len, 0.0);
            }
        }
    }

    /// Row i's hidden cotangent h̄ (q values) after [`vjps_many`].
    pub(crate) fn hidden_bar(&self, i: usize, q: usize) -> &[f64] {
        &self.h_bar[i * q..(i + 1) * q]
    }

    /// Row i's output cotangent ȳ (n values) after [`vjps_many`].
    pub(crate) fn output_bar(&self, i: usize, n: usize) -> &[f64] {
        &self.y_bar[i * n..(i + 1) * n]
    }
}

/// One emulator step of many rollouts at once, the same bits as one [`predict_with`] per row:
/// row i of `s_next` (n values) from state row i of `s` and control row i of `u` (m), with the
/// network's input, hidden activations and output written to rows of `z`, `h` and `y`. The
/// network's passes take all rows together ([`Mlp::forward_many`]); the transforms go row by
/// row. Does not allocate once `scratch` has room ([`ManyScratch::reset`]).
///
/// [`predict_with`]: super::predict_with
pub(crate) fn steps_many(
    t: &Transforms,
    mlp: &Mlp,
    (s, u): (&[f64], &[f64]),
    (z, h, y): (&mut [f64], &mut [f64], &mut [f64]),
    scratch: &mut ManyScratch,
    s_next: &mut [f64],
) {
    let n = t.state_dim;
    let rows = s.len() / n.max(1);
    let ats = &mut scratch.ats[..rows];
    encode_rows(t, s, u, ats, z);
    mlp.forward_many(rows, z, h, y);
    decode_rows(t, ats, s, y, &mut scratch.t1[..n], s_next);
}

/// The vector–Jacobian products of many steps at once after [`steps_many`] (its states `s`,
/// hidden activations `h` and outputs `y`), the same bits as one [`step_vjp_after_forward`]
/// per row without a weight gradient: adds (∂s'/∂s)ᵀ s̄' of row i (s̄' row i of `s_next_bar`)
/// to row i of `s_bar`, and leaves the rows' ȳ and h̄ in `scratch` for the weight gradient
/// ([`Mlp::weight_grad_many`]); the control cotangents are dropped.
///
/// [`step_vjp_after_forward`]: super::step::step_vjp_after_forward
pub(crate) fn vjps_many(
    t: &Transforms,
    mlp: &Mlp,
    (s, h, y): (&[f64], &[f64], &[f64]),
    s_next_bar: &[f64],
    scratch: &mut ManyScratch,
    s_bar: &mut [f64],
) {
    let (n, m) = (t.state_dim, t.control_dim);
    let rows = s.len() / n.max(1);
    let ManyScratch {
        ats,
        y_bar,
        h_bar,
        z_bar,
        t1,
        t2,
        u_bar,
    } = scratch;
    // Every buffer cut to its length: the transforms read some lengths from their buffers,
    // and a thread's scratch may have served a larger net before.
    let (ats, t1, t2, u_bar) = (
        &mut ats[..rows],
        &mut t1[..n],
        &mut t2[..n],
        &mut u_bar[..m],
    );
    let (y_bar, h_bar) = (&mut y_bar[..rows * n], &mut h_bar[..rows * mlp.n_hidden()]);
    let z_bar = &mut z_bar[..rows * (n + m)];
    decode_vjp_rows(t, s, y, s_next_bar, t1, t2, ats, y_bar, s_bar);
    mlp.backward_many(rows, (h, y_bar), h_bar, z_bar);
    encode_vjp_rows(t, ats, s, z_bar, t1, s_bar, u_bar);
}

avx_dispatched! {
    /// The transforms before the network ([`step_through`]) for each row of `s` and `u`: the
    /// frame read from the state to `ats`, the network input to a row of `z`.
    ///
    /// [`step_through`]: super::step::step_through
    fn encode_rows(
        t: &Transforms,
        s: &[f64],
        u: &[f64],
        ats: &mut [Option<transform::FrameAt>],
        z: &mut [f64],
    ) {
        let (n, m) = (t.state_dim, t.control_dim);
        for (i, at) in ats.iter_mut().enumerate() {
            let si = &s[i * n..(i + 1) * n];
            *at = t.frame_at(si, false);
            let zi = &mut z[i * (n + m)..(i + 1) * (n + m)];
            t.encode_input_with(at.as_ref(), si, &u[i * m..(i + 1) * m], zi);
        }
    }
}

avx_dispatched! {
    /// The transforms after the network ([`step_through`]) for each row: the next state from
    /// the network's output, at the frame read before.
    ///
    /// [`step_through`]: super::step::step_through
    fn decode_rows(
        t: &Transforms,
        ats: &[Option<transform::FrameAt>],
        s: &[f64],
        y: &[f64],
        tmp: &mut [f64],
        s_next: &mut [f64],
    ) {
        let n = t.state_dim;
        for (i, at) in ats.iter().enumerate() {
            let (si, yi) = (&s[i * n..(i + 1) * n], &y[i * n..(i + 1) * n]);
            t.decode_output_with(at.as_ref(), si, yi, tmp, &mut s_next[i * n..(i + 1) * n]);
        }
    }
}

avx_dispatched! {
    /// The output transforms' products of [`vjp_from_forward`] for each row: ȳ, the state's
    /// share of s̄ added, and the frame (with the rotation's derivatives) kept in `ats`.
    ///
    /// [`vjp_from_forward`]: super::step::vjp_from_forward
    fn decode_vjp_rows(
        t: &Transforms,
        s: &[f64],
        y: &[f64],
        s_next_bar: &[f64],
        t1: &mut [f64],
        t2: &mut [f64],
        ats: &mut [Option<transform::FrameAt>],
        y_bar: &mut [f64],
        s_bar: &mut [f64],
    ) {
        let n = t.state_dim;
        for (i, at) in ats.iter_mut().enumerate() {
            let row = i * n..(i + 1) * n;
            let si = &s[row.clone()];
            *at = t.frame_at(si, true);
            t.decode_output_vjp_with(
                at.as_ref(),
                si,
                &y[row.clone()],
                &s_next_bar[row.clone()],
                (&mut *t1, &mut *t2),
                &mut y_bar[row.clone()],
                &mut s_bar[row],
            );
        }
    }
}

avx_dispatched! {
    /// The input transforms' products of [`vjp_from_forward`] for each row: the state's share
    /// of z̄ added to its row of s̄ (the control's to `u_bar`, overwritten row after row).
    ///
    /// [`vjp_from_forward`]: super::step::vjp_from_forward
    fn encode_vjp_rows(
        t: &Transforms,
        ats: &[Option<transform::FrameAt>],
        s: &[f64],
        z_bar: &[f64],
        tmp: &mut [f64],
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        let (n, m) = (t.state_dim, t.control_dim);
        for (i, at) in ats.iter().enumerate() {
            t.encode_input_vjp_with(
                at.as_ref(),
                &s[i * n..(i + 1) * n],
                &z_bar[i * (n + m)..(i + 1) * (n + m)],
                tmp,
                &mut s_bar[i * n..(i + 1) * n],
                u_bar,
            );
        }
    }
}
