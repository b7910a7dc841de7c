//! One emulator step through the transforms and the network ([`predict_with`]) and its
//! vector–Jacobian product ([`step_vjp`]), with their scratch and the AVX dispatch they share.

use super::mlp::{Mlp, MlpScratch};
use super::Transforms;

/// Scratch for one emulator step and its VJP, so the hot loop does not allocate.
#[derive(Debug, Clone)]
pub struct EmulatorScratch {
    pub(super) z: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) z_bar: Vec<f64>,
    pub(super) y_bar: Vec<f64>,
    pub(super) t1: Vec<f64>,
    pub(super) t2: Vec<f64>,
    pub(super) s_next: Vec<f64>,
    pub(super) mlp: MlpScratch,
}

/// One emulator step s' = T(s, u) through transforms `t` and network `mlp`. Does not allocate.
pub fn predict_with(
    t: &Transforms,
    mlp: &Mlp,
    s: &[f64],
    u: &[f64],
    scratch: &mut EmulatorScratch,
    s_next: &mut [f64],
) {
    let EmulatorScratch {
        z, y, t1, mlp: m, ..
    } = scratch;
    step_through(t, mlp, s, u, (z, y, &mut m.hidden), &mut [], t1, s_next);
}

/// Defines `fn $name` whose body is compiled twice, as written and with AVX enabled, and runs
/// the AVX copy on x86-64 processors that have it: the transforms around the network
/// (normalization, frame maps) are short loops of divisions, products and sums that then take
/// 4 lanes at a time, and the functions they call inline into one. The same IEEE operations on
/// the same values either way (Rust fuses no operation it is not asked to), so the same bits;
/// the network's own passes dispatch on their own.
macro_rules! avx_dispatched {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {
        $(#[$m])*
        #[allow(clippy::too_many_arguments)]
        $vis fn $name($($arg: $ty),*) {
            #[inline(always)]
            #[allow(clippy::too_many_arguments)]
            fn body($($arg: $ty),*) $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx")]
                #[allow(clippy::too_many_arguments)]
                fn avx($($arg: $ty),*) {
                    body($($arg),*)
                }
                if $crate::simd::avx() {
                    // SAFETY: the processor supports AVX (checked just above).
                    unsafe { avx($($arg),*) };
                    return;
                }
            }
            body($($arg),*)
        }
    };
}
pub(super) use avx_dispatched;

avx_dispatched! {
    /// One emulator step through transforms `t` and network `mlp`, writing the network's input
    /// z, output y and hidden activations h to the buffers given (a scratch, or a step of BPTT's
    /// tape), what the frame keeps of itself to `frame_tape` when it is not empty
    /// ([`Transforms::frame_tape_len`] values, for [`vjp_from_forward`]), and using `tmp`
    /// (length n). Does not allocate.
    pub(super) fn step_through(
        t: &Transforms,
        mlp: &Mlp,
        s: &[f64],
        u: &[f64],
        zyh: (&mut [f64], &mut [f64], &mut [f64]),
        frame_tape: &mut [f64],
        tmp: &mut [f64],
        s_next: &mut [f64],
    ) {
        let (z, y, h) = zyh;
        let at = t.frame_at(s, false);
        if let (Some(f), Some(at), false) = (&t.frame, &at, frame_tape.is_empty()) {
            f.write_tape(at, frame_tape);
        }
        t.encode_input_with(at.as_ref(), s, u, z);
        mlp.forward_into(z, h, y);
        t.decode_output_with(at.as_ref(), s, y, tmp, s_next);
    }
}

/// Vector–Jacobian product of one emulator step s' = T(s, u; w) through the transforms and the
/// network `mlp`: adds (∂s'/∂s)ᵀ s̄' to `s_bar`, writes (∂s'/∂u)ᵀ s̄' to `u_bar` and, when
/// given, adds (∂s'/∂w)ᵀ s̄' to `grad_w` (the weight gradient of a rollout loss, [`rollout`]).
/// Recomputes the forward pass at (s, u). Does not allocate.
///
/// [`rollout`]: super::rollout
#[allow(clippy::too_many_arguments)]
pub fn step_vjp(
    t: &Transforms,
    mlp: &Mlp,
    s: &[f64],
    u: &[f64],
    s_next_bar: &[f64],
    scratch: &mut EmulatorScratch,
    s_bar: &mut [f64],
    u_bar: &mut [f64],
    grad_w: Option<&mut [f64]>,
) {
    t.encode_input(s, u, &mut scratch.z);
    mlp.forward(&scratch.z, &mut scratch.mlp, &mut scratch.y);
    step_vjp_after_forward(t, mlp, s, s_next_bar, scratch, s_bar, u_bar, grad_w);
}

/// [`step_vjp`] when `scratch` already holds the forward pass at (s, u): the network input
/// `z`, output `y` and hidden activations (as [`predict_with`] leaves them).
#[allow(clippy::too_many_arguments)]
pub(super) fn step_vjp_after_forward(
    t: &Transforms,
    mlp: &Mlp,
    s: &[f64],
    s_next_bar: &[f64],
    scratch: &mut EmulatorScratch,
    s_bar: &mut [f64],
    u_bar: &mut [f64],
    grad_w: Option<&mut [f64]>,
) {
    let z = std::mem::take(&mut scratch.z);
    let y = std::mem::take(&mut scratch.y);
    let h = std::mem::take(&mut scratch.mlp.hidden);
    vjp_from_forward(
        t,
        mlp,
        s,
        (&z, &y, &h),
        None,
        s_next_bar,
        scratch,
        s_bar,
        u_bar,
        grad_w,
    );
    scratch.z = z;
    scratch.y = y;
    scratch.mlp.hidden = h;
}

avx_dispatched! {
    /// The backward half of [`step_vjp`] from the forward pass at (s, u) given as (network
    /// input z, output y, hidden activations h) and, when kept, the frame's tape
    /// ([`step_through`]); uses the rest of `scratch` as buffers.
    pub(super) fn vjp_from_forward(
        t: &Transforms,
        mlp: &Mlp,
        s: &[f64],
        zyh: (&[f64], &[f64], &[f64]),
        frame_tape: Option<&[f64]>,
        s_next_bar: &[f64],
        scratch: &mut EmulatorScratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
        grad_w: Option<&mut [f64]>,
    ) {
        let (z, y, h) = zyh;
        // The frame at s (with the rotation's derivatives) serves both transforms' products.
        let at = match frame_tape {
            Some(tape) => t.frame_at_taped(s, tape, true),
            None => t.frame_at(s, true),
        };
        t.decode_output_vjp_with(
            at.as_ref(),
            s,
            y,
            s_next_bar,
            (&mut scratch.t1, &mut scratch.t2),
            &mut scratch.y_bar,
            s_bar,
        );
        mlp.backward_from(
            z,
            h,
            &mut scratch.mlp.hidden_bar,
            &scratch.y_bar,
            grad_w,
            Some(&mut scratch.z_bar),
        );
        t.encode_input_vjp_with(
            at.as_ref(),
            s,
            &scratch.z_bar,
            &mut scratch.t1,
            s_bar,
            u_bar,
        );
    }
}
