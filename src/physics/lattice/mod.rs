//! # 3D mass-spring lattices on a floor (Christensen, Marks, Ngo 1995, §2.1)
//!
//! A lattice is a set of point masses joined by damped linear springs. With ℓ the current
//! length of a spring, ℓ̇ its rate and L its rest length, the spring pulls its two masses
//! together with the tension
//!
//! T = k (ℓ − L) + D ℓ̇,
//!
//! i.e. the force on mass a is −T·(p_a − p_b)/ℓ, equal and opposite on b. (The paper prints
//! the magnitude as f = −k(L − x) − D ẋ; read with one sign convention for both terms, that is
//! either anti-restoring or anti-damping, so we use the dissipative law above.) Gravity g acts
//! along −z and the floor is the plane z = 0:
//!
//! - **impact** (inelastic collision): a mass reaching the floor with v_z < 0 loses its normal
//!   velocity; its tangential velocity is reduced by at most μ·|v_z| (Coulomb's law for the
//!   impulse). Impacts are events handled by [`LatticeSim`], not by the force law.
//! - **resting contact**: a mass on the floor (z ≤ ε_z, |v_z| ≤ ε_v) receives the normal force
//!   N = max(0, −F_z) that cancels the downward part of the other forces F on it. Each
//!   contact involves one point mass and the mass matrix is diagonal, so this is the exact
//!   unilateral constraint force: no complementarity problem is needed.
//! - **friction** (regularized Coulomb): the friction force is the force that would stop the
//!   tangential motion within the time constant τ, f* = −F_t − m v_t/τ, clipped to the
//!   Coulomb limit μ_eff N. A mass at rest with |F_t| ≤ μN stays exactly at rest (static
//!   friction); a sliding mass feels |f| = μN opposing its motion (exactly opposite when F_t
//!   is parallel to v_t). The right-hand side stays bounded and Lipschitz (constant m/τ).
//! - **directional friction**: with preferred horizontal direction d, the coefficient is
//!   μ_eff = μ + (μ_d − μ)·max(0, ŝ·d) where ŝ is the direction of the (attempted) sliding,
//!   so sliding along +d is resisted by μ_d and sliding against it or across it by μ.
//!
//! The state is `[p_0, …, p_{n−1}, v_0, …, v_{n−1}]` (3 coordinates each, world frame, z up);
//! the controls are the springs' rest lengths ([`LatticeModel`] keeps the active ones when the
//! control slice is empty). The equations are integrated by adaptive Dormand–Prince RK45
//! (§2.1 of the paper) inside [`LatticeSim`], which ends a step at each impact.
//!
//! Three lattices ship as data: [`Lattice::cube`] (8 masses, 28 springs), [`Lattice::pyramid`]
//! (the "spider", 5 masses, 10 springs) and [`Lattice::chair`] (10 masses, 35 springs).
//! Actuation reflexes that produce rest lengths are in [`super::reflex`].
//!
//! Layout: this module holds the force law ([`LatticeModel`]); `shapes` the lattice data
//! ([`Lattice`], springs, the shipped shapes); `contact` the floor ([`Floor`]) and the
//! event-driven integration with impacts ([`LatticeSim`]).
//!
//! ## References
//! - J. Christensen, J. Marks, J. T. Ngo, *Automatic Motion Synthesis for 3D Mass-Spring
//!   Models*, The Visual Computer 13(1), 1997 (MERL TR95-01).

mod contact;
mod shapes;

pub use contact::{ContactStats, Floor, LatticeSim};
pub use shapes::{lengths, Lattice, PointMass, Spring, DEFAULT_DAMPING, DEFAULT_STIFFNESS};

use super::reflex::{self, ReflexGains};
use super::{Model, Ode, Parameter};
use serde::{Deserialize, Serialize};

/// Earth's gravitational acceleration (m/s²).
pub const EARTH_GRAVITY: f64 = 9.81;
/// The "low gravity" of the paper's somersault and pirouette examples: the Moon's (m/s²).
pub const LOW_GRAVITY: f64 = 1.62;

/// Errors of lattice construction and actuation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LatticeError {
    /// A lattice needs at least one mass.
    #[error("lattice has no masses")]
    Empty,
    /// A mass value that is not positive and finite (index, value in kg).
    #[error("mass {0} has invalid mass {1} kg (must be positive and finite)")]
    InvalidMass(usize, f64),
    /// A mass position that is not finite (index).
    #[error("mass {0} has a non-finite position")]
    InvalidPosition(usize),
    /// A spring whose end indices are out of range or equal (spring, a, b).
    #[error("spring {0} joins masses {1} and {2}: indices must differ and be in range")]
    InvalidEnds(usize, usize, usize),
    /// A spring whose ends coincide in the rest shape (spring index).
    #[error("spring {0} has zero rest length")]
    ZeroRestLength(usize),
    /// A negative or non-finite stiffness or damping (spring, value).
    #[error("spring {0} has invalid stiffness or damping {1} (must be finite and >= 0)")]
    InvalidSpring(usize, f64),
    /// A rest-length vector of the wrong length (got, expected).
    #[error("{0} rest lengths given, lattice has {1} springs")]
    RestLengthCount(usize, usize),
    /// A rest length that is not positive and finite (spring, value in m).
    #[error("spring {0}: invalid rest length {1} m")]
    InvalidRestLength(usize, f64),
    /// A reflex number outside 0–11.
    #[error("reflex number {0} is not in 0..=11")]
    InvalidReflex(usize),
    /// A floor parameter out of range (name, value).
    #[error("floor parameter `{0}` has invalid value {1}")]
    InvalidFloor(&'static str, f64),
    /// A reflex coefficient outside [−1, 1] or not finite.
    #[error("reflex coefficient {0} is not in [-1, 1]")]
    InvalidCoefficient(f64),
}

/// A lattice with gravity, a floor and active rest lengths: an [`Ode`].
///
/// Controls are the springs' rest lengths (m); an empty control slice means "use
/// [`LatticeModel::rest_lengths`]". The floor's impacts are not part of the right-hand side:
/// integrate with [`LatticeSim`], which handles them as events.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatticeModel {
    /// The lattice.
    pub lattice: Lattice,
    /// Gravitational acceleration along −z (m/s²); see [`EARTH_GRAVITY`], [`LOW_GRAVITY`].
    pub gravity: f64,
    /// The floor.
    pub floor: Floor,
    /// Gains of the actuation reflexes.
    pub reflex_gains: ReflexGains,
    /// Active rest lengths (m), one per spring.
    pub rest_lengths: Vec<f64>,
}

impl LatticeModel {
    /// A validated model of `lattice` with Earth gravity, the default floor and the rest
    /// shape's rest lengths.
    pub fn new(lattice: Lattice) -> Result<Self, LatticeError> {
        lattice.validate()?;
        let rest_lengths = lattice.rest_lengths();
        Ok(Self {
            lattice,
            gravity: EARTH_GRAVITY,
            floor: Floor::default(),
            reflex_gains: ReflexGains::default(),
            rest_lengths,
        })
    }

    /// The same model with gravity `g` (m/s²).
    pub fn with_gravity(mut self, g: f64) -> Self {
        self.gravity = g;
        self
    }

    /// The same model with floor `floor`, validated.
    pub fn with_floor(mut self, floor: Floor) -> Result<Self, LatticeError> {
        floor.validate()?;
        self.floor = floor;
        Ok(self)
    }

    /// Sets the active rest lengths (m), validated.
    pub fn set_rest_lengths(&mut self, rest: &[f64]) -> Result<(), LatticeError> {
        let ns = self.lattice.springs.len();
        if rest.len() != ns {
            return Err(LatticeError::RestLengthCount(rest.len(), ns));
        }
        if let Some((j, &l)) = rest
            .iter()
            .enumerate()
            .find(|(_, l)| !(l.is_finite() && **l > 0.0))
        {
            return Err(LatticeError::InvalidRestLength(j, l));
        }
        self.rest_lengths.copy_from_slice(rest);
        Ok(())
    }

    /// Activates reflex `number` (0–11) with coefficient `alpha` ∈ [−1, 1]: the active rest
    /// lengths become those of the deformed rest shape (§2.2).
    pub fn apply_reflex(&mut self, number: usize, alpha: f64) -> Result<(), LatticeError> {
        let d = reflex::deform(&self.lattice, number, alpha, &self.reflex_gains)?;
        self.set_rest_lengths(&d.rest_lengths)
    }

    /// Positions (m) of the masses in state `x`.
    pub fn positions(&self, x: &[f64]) -> Vec<[f64; 3]> {
        let n = self.lattice.n_masses();
        (0..n)
            .map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
            .collect()
    }

    /// Centre of mass (m) of state `x`.
    pub fn center_of_mass(&self, x: &[f64]) -> [f64; 3] {
        self.lattice.center_of_mass(&self.positions(x))
    }

    /// Kinetic energy (J) of state `x`.
    pub fn kinetic_energy(&self, x: &[f64]) -> f64 {
        let n = self.lattice.n_masses();
        let v = &x[3 * n..];
        self.lattice
            .masses
            .iter()
            .enumerate()
            .map(|(i, m)| 0.5 * m.mass * (0..3).map(|k| v[3 * i + k].powi(2)).sum::<f64>())
            .sum()
    }

    /// Number of masses in contact with the floor in state `x`.
    pub fn contacts(&self, x: &[f64]) -> usize {
        let n = self.lattice.n_masses();
        (0..n)
            .filter(|&i| self.in_contact(x[3 * i + 2], x[3 * n + 3 * i + 2]))
            .count()
    }

    fn in_contact(&self, z: f64, vz: f64) -> bool {
        z <= self.floor.contact_tolerance && vz.abs() <= self.floor.velocity_tolerance
    }

    /// Adds gravity and, for a mass in contact, the floor's normal force and friction to the
    /// force `f` (N) on a mass of `mass` kg at position `p` with velocity `v`. `direction_norm`
    /// holds |d| of the preferred friction direction once a contact has needed it.
    fn add_floor_force(
        &self,
        f: &mut [f64; 3],
        mass: f64,
        p: &[f64; 3],
        v: &[f64; 3],
        direction_norm: &mut Option<f64>,
    ) {
        let fl = &self.floor;
        f[2] -= mass * self.gravity;
        if self.in_contact(p[2], v[2]) {
            let normal = (-f[2]).max(0.0);
            f[2] += normal;
            // Force that would stop the tangential motion within τ, clipped to Coulomb.
            let want = [
                -f[0] - mass * v[0] / fl.stick_time,
                -f[1] - mass * v[1] / fl.stick_time,
            ];
            let size = (want[0] * want[0] + want[1] * want[1]).sqrt();
            let dn = *direction_norm.get_or_insert_with(|| fl.direction_norm());
            let limit = fl.coefficient_with_norm([-want[0], -want[1]], dn) * normal;
            let scale = if size > limit { limit / size } else { 1.0 };
            f[0] += want[0] * scale;
            f[1] += want[1] * scale;
        }
    }

    /// Adds the spring forces (N) of state `x` with rest lengths `rest` to `f` (3 per mass).
    ///
    /// On x86-64, two springs at a time in the two lanes of SSE2 registers, or four at a time
    /// in AVX registers where the processor has AVX (runtime detection): each lane is the
    /// same IEEE operations as [`LatticeModel::add_spring_forces_portable`], one spring at a
    /// time, so the same bits (tested), but the square root and the four divisions of a
    /// spring take two (four) springs to an instruction. Four lanes pay where a 4-lane
    /// division costs what a 2-lane one does (AMD Zen 4: 4.7 cycles each); where it costs
    /// twice as much (Intel Sapphire Rapids) an earlier four-lane version, which built its
    /// lanes one value at a time, measured no faster. The AVX path reads and writes each
    /// end's three coordinates as vectors (the cube's right-hand side: 200 → 157 ns, AMD
    /// Zen 4).
    pub fn add_spring_forces(&self, x: &[f64], rest: &[f64], f: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::simd::avx() {
                // SAFETY: the processor has AVX (checked just above).
                unsafe { self.spring_forces_avx(x, rest, f) };
            } else {
                // SAFETY: every x86-64 processor has SSE2.
                unsafe { self.spring_forces_sse2(x, rest, f) };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.add_spring_forces_portable(x, rest, f);
    }

    /// [`LatticeModel::add_spring_forces`] one spring at a time.
    pub fn add_spring_forces_portable(&self, x: &[f64], rest: &[f64], f: &mut [f64]) {
        self.spring_forces_each(x, rest, f, 0);
    }

    /// The forces of springs `first..` one at a time.
    /// The positions and velocities of state `x` and the forces `f` as per-mass 3-vectors, for
    /// the spring-force paths: one bounds check per mass access instead of one per coordinate.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn per_mass<'x, 'f>(
        &self,
        x: &'x [f64],
        f: &'f mut [f64],
    ) -> (&'x [[f64; 3]], &'x [[f64; 3]], &'f mut [[f64; 3]]) {
        let n = self.lattice.n_masses();
        let (p, v) = x.split_at(3 * n);
        (
            p.as_chunks::<3>().0,
            v[..3 * n].as_chunks::<3>().0,
            f[..3 * n].as_chunks_mut::<3>().0,
        )
    }

    fn spring_forces_each(&self, x: &[f64], rest: &[f64], f: &mut [f64], first: usize) {
        let (p, v, f) = self.per_mass(x, f);
        let springs = self.lattice.springs.iter().zip(rest).skip(first);
        for (s, &l0) in springs {
            let (pa, pb, va, vb) = (p[s.a], p[s.b], v[s.a], v[s.b]);
            let d = [pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]];
            let dv = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let rate = (d[0] * dv[0] + d[1] * dv[1] + d[2] * dv[2]) / len;
            let tension = s.stiffness * (len - l0) + s.damping * rate;
            add_spring_force(f, s, len, d.map(|dk| tension * dk / len));
        }
    }

    /// [`LatticeModel::add_spring_forces`] two springs at a time in SSE2 lanes (lane 0 the
    /// first spring of a pair); an odd last spring one at a time.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "sse2")]
    fn spring_forces_sse2(&self, x: &[f64], rest: &[f64], f: &mut [f64]) {
        use std::arch::x86_64::*;
        let ns = self.lattice.springs.len().min(rest.len());
        let (p, v, ff) = self.per_mass(x, f);
        let (pairs, _) = self.lattice.springs[..ns].as_chunks::<2>();
        let pair = |a: f64, b: f64| _mm_set_pd(b, a);
        let (low, high) = (
            |v| _mm_cvtsd_f64(v),
            |v| _mm_cvtsd_f64(_mm_unpackhi_pd(v, v)),
        );
        for ([s, t], r) in pairs.iter().zip(rest.as_chunks::<2>().0) {
            let (ps, pt, vs, vt) = (
                (p[s.a], p[s.b]),
                (p[t.a], p[t.b]),
                (v[s.a], v[s.b]),
                (v[t.a], v[t.b]),
            );
            let d = [0, 1, 2].map(|c| pair(ps.0[c] - ps.1[c], pt.0[c] - pt.1[c]));
            let dv = [0, 1, 2].map(|c| pair(vs.0[c] - vs.1[c], vt.0[c] - vt.1[c]));
            let len = _mm_sqrt_pd(_mm_add_pd(
                _mm_add_pd(_mm_mul_pd(d[0], d[0]), _mm_mul_pd(d[1], d[1])),
                _mm_mul_pd(d[2], d[2]),
            ));
            let rate = _mm_div_pd(
                _mm_add_pd(
                    _mm_add_pd(_mm_mul_pd(d[0], dv[0]), _mm_mul_pd(d[1], dv[1])),
                    _mm_mul_pd(d[2], dv[2]),
                ),
                len,
            );
            let tension = _mm_add_pd(
                _mm_mul_pd(
                    pair(s.stiffness, t.stiffness),
                    _mm_sub_pd(len, pair(r[0], r[1])),
                ),
                _mm_mul_pd(pair(s.damping, t.damping), rate),
            );
            let fk = d.map(|dk| _mm_div_pd(_mm_mul_pd(tension, dk), len));
            add_spring_force(ff, s, low(len), fk.map(low));
            add_spring_force(ff, t, high(len), fk.map(high));
        }
        self.spring_forces_each(x, rest, f, 2 * pairs.len());
    }

    /// [`LatticeModel::add_spring_forces`] four springs at a time in AVX lanes (lane i the
    /// i-th spring of a quad); the last springs, fewer than four, one at a time.
    ///
    /// Each end's 3-vector is read with one masked load and the four springs' differences
    /// taken as vectors, then turned into one register per coordinate by a 4 × 4 transpose;
    /// the forces go back the same way, each end updated by a 2-lane and a 1-lane
    /// read–modify–write. Every value is the same IEEE operation on the same operands as one
    /// spring at a time, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn spring_forces_avx(&self, x: &[f64], rest: &[f64], f: &mut [f64]) {
        use std::arch::x86_64::*;
        let ns = self.lattice.springs.len().min(rest.len());
        let (p, v, ff) = self.per_mass(x, f);
        let (quads, _) = self.lattice.springs[..ns].as_chunks::<4>();
        // Lanes 0–2 of a 3-vector, lane 3 zero; the masked lane is not read, so the last
        // mass's velocity is read without reading past the state.
        let three = _mm256_set_epi64x(0, -1, -1, -1);
        // SAFETY (every load below): a `&[f64; 3]` holds the three values read.
        let load = |e: &[f64; 3]| unsafe { _mm256_maskload_pd(e.as_ptr(), three) };
        // The 4 × 4 transpose: lane j of register i becomes lane i of register j. It turns
        // four springs' 3-vectors (lane 3 ignored) into one register per coordinate, and back.
        let transpose = |r: [__m256d; 4]| {
            let (even01, odd01) = (
                _mm256_unpacklo_pd(r[0], r[1]),
                _mm256_unpackhi_pd(r[0], r[1]),
            );
            let (even23, odd23) = (
                _mm256_unpacklo_pd(r[2], r[3]),
                _mm256_unpackhi_pd(r[2], r[3]),
            );
            [
                _mm256_permute2f128_pd(even01, even23, 0x20),
                _mm256_permute2f128_pd(odd01, odd23, 0x20),
                _mm256_permute2f128_pd(even01, even23, 0x31),
                _mm256_permute2f128_pd(odd01, odd23, 0x31),
            ]
        };
        for (q, r) in quads.iter().zip(rest.as_chunks::<4>().0) {
            let [s0, s1, s2, s3] = q;
            let [d0, d1, d2, _] = transpose([
                _mm256_sub_pd(load(&p[s0.a]), load(&p[s0.b])),
                _mm256_sub_pd(load(&p[s1.a]), load(&p[s1.b])),
                _mm256_sub_pd(load(&p[s2.a]), load(&p[s2.b])),
                _mm256_sub_pd(load(&p[s3.a]), load(&p[s3.b])),
            ]);
            let [dv0, dv1, dv2, _] = transpose([
                _mm256_sub_pd(load(&v[s0.a]), load(&v[s0.b])),
                _mm256_sub_pd(load(&v[s1.a]), load(&v[s1.b])),
                _mm256_sub_pd(load(&v[s2.a]), load(&v[s2.b])),
                _mm256_sub_pd(load(&v[s3.a]), load(&v[s3.b])),
            ]);
            let (d, dv) = ([d0, d1, d2], [dv0, dv1, dv2]);
            let len = _mm256_sqrt_pd(_mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(d[0], d[0]), _mm256_mul_pd(d[1], d[1])),
                _mm256_mul_pd(d[2], d[2]),
            ));
            let rate = _mm256_div_pd(
                _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(d[0], dv[0]), _mm256_mul_pd(d[1], dv[1])),
                    _mm256_mul_pd(d[2], dv[2]),
                ),
                len,
            );
            let stiffness = _mm256_set_pd(s3.stiffness, s2.stiffness, s1.stiffness, s0.stiffness);
            let damping = _mm256_set_pd(s3.damping, s2.damping, s1.damping, s0.damping);
            // SAFETY: four f64 values are read from a 4-value array.
            let r = unsafe { _mm256_loadu_pd(r.as_ptr()) };
            let tension = _mm256_add_pd(
                _mm256_mul_pd(stiffness, _mm256_sub_pd(len, r)),
                _mm256_mul_pd(damping, rate),
            );
            let fk = d.map(|dk| _mm256_div_pd(_mm256_mul_pd(tension, dk), len));
            // Back to one register per spring: (f_x, f_y, f_z, f_z).
            let each = transpose([fk[0], fk[1], fk[2], fk[2]]);
            // Springs of zero length add nothing.
            let zero = _mm256_movemask_pd(_mm256_cmp_pd(len, _mm256_setzero_pd(), _CMP_EQ_OQ));
            for (i, (s, fk)) in q.iter().zip(each).enumerate() {
                if zero & (1 << i) != 0 {
                    continue;
                }
                let (xy, z) = (_mm256_castpd256_pd128(fk), _mm256_extractf128_pd(fk, 1));
                // Each end as in `add_spring_force`: −fk on the first, then +fk on the second.
                let fa = &mut ff[s.a];
                // SAFETY: two f64 values are read and written in a 3-value array.
                unsafe {
                    _mm_storeu_pd(fa.as_mut_ptr(), _mm_sub_pd(_mm_loadu_pd(fa.as_ptr()), xy))
                };
                fa[2] -= _mm_cvtsd_f64(z);
                let fb = &mut ff[s.b];
                // SAFETY: as above.
                unsafe {
                    _mm_storeu_pd(fb.as_mut_ptr(), _mm_add_pd(_mm_loadu_pd(fb.as_ptr()), xy))
                };
                fb[2] += _mm_cvtsd_f64(z);
            }
        }
        self.spring_forces_each(x, rest, f, 4 * quads.len());
    }
}

/// Adds the force `fk` (N) of spring `s`, of length `len`, to its ends in `f`: −fk on the
/// first, +fk on the second; nothing for a spring of zero length.
#[inline(always)]
fn add_spring_force(f: &mut [[f64; 3]], s: &Spring, len: f64, fk: [f64; 3]) {
    if len == 0.0 {
        return;
    }
    // Each coordinate is updated once on each end, so grouping the updates by end (rather
    // than by coordinate) gives the same sums, also when a == b.
    let fa = &mut f[s.a];
    for c in 0..3 {
        fa[c] -= fk[c];
    }
    let fb = &mut f[s.b];
    for c in 0..3 {
        fb[c] += fk[c];
    }
}

impl Model for LatticeModel {
    fn name(&self) -> &str {
        &self.lattice.name
    }
    fn state_names(&self) -> Vec<String> {
        let n = self.lattice.n_masses();
        let mut names = Vec::with_capacity(6 * n);
        for prefix in ["", "v"] {
            for i in 0..n {
                for c in ["x", "y", "z"] {
                    names.push(format!("mass{i}.{prefix}{c}"));
                }
            }
        }
        names
    }
    fn control_names(&self) -> Vec<String> {
        (0..self.lattice.springs.len())
            .map(|j| format!("spring{j}.rest_length"))
            .collect()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let f = &self.floor;
        let mut p = vec![
            Parameter::new("gravity", self.gravity, "m/s^2", "gravity along -z"),
            Parameter::new("floor.friction", f.friction, "1", "Coulomb coefficient"),
            Parameter::new(
                "floor.preferred_friction",
                f.preferred_friction,
                "1",
                "Coulomb coefficient sliding along the preferred direction",
            ),
            Parameter::new(
                "floor.preferred_direction.x",
                f.preferred_direction[0],
                "1",
                "preferred sliding direction, x component (world)",
            ),
            Parameter::new(
                "floor.preferred_direction.y",
                f.preferred_direction[1],
                "1",
                "preferred sliding direction, y component (world)",
            ),
            Parameter::new(
                "floor.stick_time",
                f.stick_time,
                "s",
                "time constant of regularized static friction",
            ),
            Parameter::new(
                "floor.contact_tolerance",
                f.contact_tolerance,
                "m",
                "contact height and tolerated penetration",
            ),
            Parameter::new(
                "floor.velocity_tolerance",
                f.velocity_tolerance,
                "m/s",
                "normal speed of resting contact",
            ),
        ];
        for (name, value, unit, description) in [
            (
                "reflex.scale",
                self.reflex_gains.scale,
                "1",
                "relative stretch at alpha = 1",
            ),
            (
                "reflex.shear",
                self.reflex_gains.shear,
                "1",
                "shear strain at alpha = 1",
            ),
            (
                "reflex.splay",
                self.reflex_gains.splay,
                "1",
                "relative widening at the extremes",
            ),
            (
                "reflex.twist",
                self.reflex_gains.twist,
                "rad",
                "twist angle at the extremes",
            ),
        ] {
            p.push(Parameter::new(name, value, unit, description));
        }
        for (i, m) in self.lattice.masses.iter().enumerate() {
            p.push(Parameter::new(
                format!("mass{i}.mass"),
                m.mass,
                "kg",
                "point mass",
            ));
        }
        for (j, s) in self.lattice.springs.iter().enumerate() {
            p.push(Parameter::new(
                format!("spring{j}.stiffness"),
                s.stiffness,
                "N/m",
                "spring constant k",
            ));
            p.push(Parameter::new(
                format!("spring{j}.damping"),
                s.damping,
                "N*s/m",
                "damping constant D",
            ));
            p.push(Parameter::new(
                format!("spring{j}.rest_length"),
                self.rest_lengths[j],
                "m",
                "active rest length L",
            ));
        }
        p
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for LatticeModel {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let n = self.lattice.n_masses();
        let rest = if u.len() == self.lattice.springs.len() {
            u
        } else {
            &self.rest_lengths[..]
        };
        let (dp, dv) = dx.split_at_mut(3 * n);
        dp.copy_from_slice(&x[3 * n..]);
        dv.fill(0.0);
        self.add_spring_forces(x, rest, dv);
        let (p, v) = x.split_at(3 * n);
        let (p, v) = (p.as_chunks::<3>().0, v[..3 * n].as_chunks::<3>().0);
        let masses = self.lattice.masses.iter();
        // |d| of the friction's preferred direction, once per call where a mass is in contact.
        let mut direction_norm = None;
        for (((m, f), p), v) in masses.zip(dv.as_chunks_mut::<3>().0).zip(p).zip(v) {
            self.add_floor_force(f, m.mass, p, v, &mut direction_norm);
        }
        // Accelerations: each force divided by its mass, two masses (six values) at a time so
        // that the divisions go two to an instruction.
        let (pairs, last) = dv.as_chunks_mut::<6>();
        let (mass_pairs, last_mass) = self.lattice.masses.as_chunks::<2>();
        for (f, [m0, m1]) in pairs.iter_mut().zip(mass_pairs) {
            let m = [m0.mass, m0.mass, m0.mass, m1.mass, m1.mass, m1.mass];
            for (f, m) in f.iter_mut().zip(m) {
                *f /= m;
            }
        }
        if let Some(m) = last_mass.first() {
            for f in last.iter_mut() {
                *f /= m.mass;
            }
        }
    }

    fn position_dim(&self) -> Option<usize> {
        Some(3 * self.lattice.n_masses())
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let n = self.lattice.n_masses();
        let p = self.positions(x);
        let gravity: f64 = (0..n)
            .map(|i| self.lattice.masses[i].mass * self.gravity * x[3 * i + 2])
            .sum();
        let elastic: f64 = lengths(&p, &self.lattice.springs)
            .iter()
            .zip(&self.lattice.springs)
            .zip(&self.rest_lengths)
            .map(|((l, s), l0)| 0.5 * s.stiffness * (l - l0).powi(2))
            .sum();
        Some(self.kinetic_energy(x) + gravity + elastic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Dynamics;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn free_cube(damping: bool) -> LatticeModel {
        let mut lattice = Lattice::cube();
        if !damping {
            for s in &mut lattice.springs {
                s.damping = 0.0;
            }
        }
        LatticeModel::new(lattice).unwrap().with_gravity(0.0)
    }

    /// A perturbed cube far above the floor with random velocities.
    fn tumbling_state(model: &LatticeModel, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = model.lattice.placed_state([0.3, -0.2, 0.5], 5.0, [0.0; 3]);
        for v in x.iter_mut() {
            *v += rng.random_range(-0.1..0.1);
        }
        x
    }

    fn max_speed(model: &LatticeModel, x: &[f64]) -> f64 {
        let n = model.lattice.n_masses();
        x[3 * n..]
            .chunks(3)
            .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
            .fold(0.0, f64::max)
    }

    /// The three shipped lattices (28, 10 and 35 springs: pairs, and an odd last spring).
    fn shipped() -> [LatticeModel; 3] {
        [Lattice::cube(), Lattice::pyramid(), Lattice::chair()]
            .map(|l| LatticeModel::new(l).unwrap().with_gravity(LOW_GRAVITY))
    }

    /// A random state of `model`: masses scattered about the rest shape, random velocities;
    /// with `floor`, about half the masses resting on the floor (z = 0, v_z = 0).
    fn random_state(model: &LatticeModel, rng: &mut ChaCha8Rng, floor: bool) -> Vec<f64> {
        let n = model.lattice.n_masses();
        let mut x = model.lattice.resting_state();
        for v in x.iter_mut() {
            *v += rng.random_range(-0.2..0.2);
        }
        if floor {
            for i in (0..n).filter(|_| rng.random_bool(0.5)) {
                (x[3 * i + 2], x[3 * n + 3 * i + 2]) = (0.0, 0.0);
            }
        }
        x
    }

    #[test]
    fn spring_forces_in_lanes_are_the_one_at_a_time_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(41);
        for model in shipped() {
            let (n, ns) = (model.lattice.n_masses(), model.lattice.springs.len());
            for trial in 0..300 {
                let mut x = random_state(&model, &mut rng, false);
                if trial % 3 == 0 {
                    // Two masses at one point: the spring joining them has zero length.
                    let (a, b) = (
                        model.lattice.springs[trial % ns].a,
                        model.lattice.springs[trial % ns].b,
                    );
                    for c in 0..3 {
                        x[3 * b + c] = x[3 * a + c];
                    }
                }
                // Rest lengths for every spring, or for all but the last (the rest unforced).
                let count = if trial % 5 == 0 { ns - 1 } else { ns };
                let rest: Vec<f64> = (0..count).map(|_| rng.random_range(0.2..1.5)).collect();
                let start: Vec<f64> = (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
                let (mut lanes, mut each) = (start.clone(), start.clone());
                model.add_spring_forces(&x, &rest, &mut lanes);
                model.add_spring_forces_portable(&x, &rest, &mut each);
                let bits = |f: &[f64]| f.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&lanes),
                    bits(&each),
                    "{} trial {trial}",
                    model.lattice.name
                );
                assert!(lanes.iter().all(|v| v.is_finite()));
                // Each lane path on its own, whichever the dispatch chose.
                #[cfg(target_arch = "x86_64")]
                {
                    let mut pairs = start.clone();
                    // SAFETY: every x86-64 processor has SSE2.
                    unsafe { model.spring_forces_sse2(&x, &rest, &mut pairs) };
                    assert_eq!(bits(&pairs), bits(&each), "SSE2, trial {trial}");
                    if std::arch::is_x86_feature_detected!("avx") {
                        let mut quads = start.clone();
                        // SAFETY: the processor has AVX (checked just above).
                        unsafe { model.spring_forces_avx(&x, &rest, &mut quads) };
                        assert_eq!(bits(&quads), bits(&each), "AVX, trial {trial}");
                    }
                }
            }
        }
    }

    /// The right-hand side as it was written before the divisions went in pairs: each mass's
    /// gravity, contact and friction (|d| of the friction direction computed for each mass),
    /// then its three divisions by its mass, one mass at a time.
    fn derivative_one_mass_at_a_time(model: &LatticeModel, x: &[f64], dx: &mut [f64]) {
        let n = model.lattice.n_masses();
        let (dp, dv) = dx.split_at_mut(3 * n);
        dp.copy_from_slice(&x[3 * n..]);
        dv.fill(0.0);
        model.add_spring_forces_portable(x, &model.rest_lengths, dv);
        let (p, v) = x.split_at(3 * n);
        let (p, v) = (p.as_chunks::<3>().0, v.as_chunks::<3>().0);
        let f = dv.as_chunks_mut::<3>().0;
        for (i, m) in model.lattice.masses.iter().enumerate() {
            model.add_floor_force(&mut f[i], m.mass, &p[i], &v[i], &mut None);
            for fk in f[i].iter_mut() {
                *fk /= m.mass;
            }
        }
    }

    #[test]
    fn derivative_is_the_one_mass_at_a_time_form_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(43);
        for model in shipped() {
            let directional = model.clone().with_floor(Floor {
                preferred_friction: 2.5,
                preferred_direction: [0.6, -1.3],
                ..Floor::default()
            });
            for mut model in [model, directional.unwrap()] {
                // Masses other than 1 kg, so that the divisions by mass are not exact.
                for m in &mut model.lattice.masses {
                    m.mass *= rng.random_range(0.3..3.0);
                }
                let n = model.lattice.n_masses();
                let mut contacts = 0;
                for trial in 0..300 {
                    let x = random_state(&model, &mut rng, true);
                    contacts += model.contacts(&x);
                    let (mut got, mut want) = (vec![0.0; 6 * n], vec![0.0; 6 * n]);
                    model.derivative(&x, &[], &mut got);
                    derivative_one_mass_at_a_time(&model, &x, &mut want);
                    let bits = |f: &[f64]| f.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&got),
                        bits(&want),
                        "{} trial {trial}",
                        model.lattice.name
                    );
                }
                assert!(
                    contacts > 300,
                    "the states must exercise the floor: {contacts}"
                );
            }
        }
    }

    #[test]
    fn shipped_lattices_are_valid_and_round_trip() {
        for (lattice, n, ns) in [
            (Lattice::cube(), 8, 28),
            (Lattice::pyramid(), 5, 10),
            (Lattice::chair(), 10, 35),
        ] {
            lattice.validate().unwrap();
            assert_eq!((lattice.n_masses(), lattice.springs.len()), (n, ns));
            let json = serde_json::to_string(&lattice).unwrap();
            let back: Lattice = serde_json::from_str(&json).unwrap();
            assert_eq!(back, lattice);
            let model = LatticeModel::new(lattice).unwrap();
            assert_eq!(model.state_dim(), 6 * n);
            assert_eq!(model.control_dim(), ns);
            assert!(model.parameters().iter().all(|p| !p.unit.is_empty()));
        }
        // The cube: 12 edges, 12 face diagonals, 4 body diagonals.
        let rest = Lattice::cube().rest_lengths();
        for (len, count) in [(1.0, 12), (2f64.sqrt(), 12), (3f64.sqrt(), 4)] {
            let c = rest.iter().filter(|l| (*l - len).abs() < 1e-12).count();
            assert_eq!(c, count, "springs of length {len}");
        }
        let mut bad = Lattice::cube();
        bad.springs[3].b = 8;
        assert_eq!(bad.validate(), Err(LatticeError::InvalidEnds(3, 0, 8)));
        let mut model = LatticeModel::new(Lattice::pyramid()).unwrap();
        assert_eq!(
            model.set_rest_lengths(&[1.0; 3]),
            Err(LatticeError::RestLengthCount(3, 10))
        );
    }

    #[test]
    fn spring_forces_conserve_momentum() {
        // Damped springs, no gravity, no floor contact: Σ m a = 0 and Σ r × m a = 0.
        let model = free_cube(true);
        let n = model.lattice.n_masses();
        for seed in 0..5 {
            let x = tumbling_state(&model, seed);
            let u: Vec<f64> = model.rest_lengths.iter().map(|l| 0.9 * l).collect();
            let mut dx = vec![0.0; 6 * n];
            model.derivative(&x, &u, &mut dx);
            let (mut p, mut l) = (Vector3::zeros(), Vector3::zeros());
            let mut scale: f64 = 0.0;
            for (i, m) in model.lattice.masses.iter().enumerate() {
                let f = m.mass * Vector3::from_column_slice(&dx[3 * n + 3 * i..3 * n + 3 * i + 3]);
                let r = Vector3::from_column_slice(&x[3 * i..3 * i + 3]);
                p += f;
                l += r.cross(&f);
                scale = scale.max(f.norm());
            }
            assert!(scale > 1.0, "forces should be non-trivial: {scale}");
            assert!(p.norm() < 1e-12 * scale, "net force {p}");
            assert!(l.norm() < 1e-11 * scale, "net torque {l}");
        }
    }

    #[test]
    fn power_balance_of_damped_springs_and_gravity() {
        // Away from the floor, dE/dt = −Σ D ℓ̇² (springs' damping only), checked by central
        // differences along the flow.
        let model = LatticeModel::new(Lattice::chair()).unwrap();
        let x = tumbling_state(&model, 3);
        let mut dx = vec![0.0; x.len()];
        model.derivative(&x, &[], &mut dx);
        let h = 1e-6;
        let energy_at = |s: f64| {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + s * b).collect();
            model.energy(&y).unwrap()
        };
        let de = (energy_at(h) - energy_at(-h)) / (2.0 * h);
        let n = model.lattice.n_masses();
        let power: f64 = model
            .lattice
            .springs
            .iter()
            .map(|s| {
                let d = Vector3::from_column_slice(&x[3 * s.a..3 * s.a + 3])
                    - Vector3::from_column_slice(&x[3 * s.b..3 * s.b + 3]);
                let dv = Vector3::from_column_slice(&x[3 * n + 3 * s.a..3 * n + 3 * s.a + 3])
                    - Vector3::from_column_slice(&x[3 * n + 3 * s.b..3 * n + 3 * s.b + 3]);
                let rate = d.dot(&dv) / d.norm();
                -s.damping * rate * rate
            })
            .sum();
        assert!(power < -1e-3, "{power}");
        assert!(
            (de - power).abs() < 1e-6 * power.abs().max(1.0),
            "{de} vs {power}"
        );
    }

    #[test]
    fn undamped_free_lattice_conserves_energy() {
        let model = free_cube(false);
        let x0 = tumbling_state(&model, 7);
        let e0 = model.energy(&x0).unwrap();
        let mut sim = LatticeSim::new(model.clone()).with_tolerances(1e-10, 1e-12);
        let mut x = x0.clone();
        let mut worst: f64 = 0.0;
        for _ in 0..100 {
            sim.step(&mut x, &[], 0.02);
            worst = worst.max((model.energy(&x).unwrap() - e0).abs());
        }
        assert!(e0 > 0.01, "{e0}");
        assert!(worst < 1e-7 * e0, "energy drift {worst} of {e0}");
        // And damping dissipates it.
        let damped = free_cube(true);
        let mut sim = LatticeSim::new(damped.clone());
        let mut y = x0.clone();
        for _ in 0..100 {
            sim.step(&mut y, &[], 0.02);
        }
        assert!(damped.energy(&y).unwrap() < 0.5 * damped.energy(&x0).unwrap());
    }

    /// Settles `lattice` from its rest shape standing on the floor for `settle` seconds, then
    /// returns the largest displacement and speed seen over the next `watch` seconds.
    fn rest_drift(lattice: Lattice, settle: f64, watch: f64) -> (f64, f64, LatticeSim) {
        let model = LatticeModel::new(lattice).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        let dt = 0.01;
        for _ in 0..(settle / dt) as usize {
            sim.step(&mut x, &[], dt);
        }
        let x1 = x.clone();
        let n = model.lattice.n_masses();
        let (mut drift, mut speed): (f64, f64) = (0.0, 0.0);
        for _ in 0..(watch / dt) as usize {
            sim.step(&mut x, &[], dt);
            for k in 0..3 * n {
                drift = drift.max((x[k] - x1[k]).abs());
            }
            speed = speed.max(max_speed(&model, &x));
            let low = (0..n).map(|i| x[3 * i + 2]).fold(f64::INFINITY, f64::min);
            assert!(low >= -model.floor.contact_tolerance, "penetration {low}");
        }
        (drift, speed, sim)
    }

    #[test]
    fn lattices_at_rest_on_the_floor_stay_at_rest() {
        for lattice in [Lattice::cube(), Lattice::pyramid(), Lattice::chair()] {
            let name = lattice.name.clone();
            // Standing up from the undeformed rest shape, the lattice sags under gravity and
            // its slowest modes take a few seconds to die out; then it must stay put.
            let (drift, speed, sim) = rest_drift(lattice, 10.0, 5.0);
            eprintln!(
                "{name}: drift {drift:.3e} m, speed {speed:.3e} m/s, {:?}, {:?}",
                sim.integrator_stats(),
                sim.contact_stats()
            );
            assert!(drift < 1e-6, "{name}: drift {drift} m");
            assert!(speed < 1e-5, "{name}: speed {speed} m/s");
        }
    }

    #[test]
    fn dropped_cube_comes_to_rest_on_the_floor() {
        let model = LatticeModel::new(Lattice::cube()).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        // Tilted, 0.5 m up, moving sideways: corners land one after another.
        let mut x = model
            .lattice
            .placed_state([0.3, 0.2, 0.1], 0.5, [0.5, 0.0, 0.0]);
        let n = model.lattice.n_masses();
        let mut lowest = f64::INFINITY;
        for _ in 0..600 {
            sim.step(&mut x, &[], 0.01);
            lowest = (0..n).map(|i| x[3 * i + 2]).fold(lowest, f64::min);
            check_all_finite(&x);
        }
        let stats = sim.integrator_stats();
        let contact = sim.contact_stats();
        eprintln!("dropped cube: {stats:?}, {contact:?}, lowest {lowest:e}");
        assert!(
            lowest >= -model.floor.contact_tolerance,
            "penetration {lowest}"
        );
        assert!(
            contact.deepest <= model.floor.contact_tolerance,
            "{contact:?}"
        );
        assert!(contact.impacts >= 4, "{contact:?}");
        assert!(model.contacts(&x) >= 4, "ends standing on a face");
        assert!(
            max_speed(&model, &x) < 1e-4,
            "speed {}",
            max_speed(&model, &x)
        );
        // No stall: a bounded number of RK45 steps for 6 s.
        assert!(stats.accepted + stats.rejected < 20_000, "{stats:?}");
    }

    #[test]
    fn hopping_cube_in_low_gravity_does_not_stall() {
        // Alternating squash and stretch along z every 0.4 s: repeated take-offs and landings.
        let model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_gravity(LOW_GRAVITY);
        let squash = reflex::deform(&model.lattice, 2, -0.3, &model.reflex_gains).unwrap();
        let stretch = reflex::deform(&model.lattice, 2, 0.3, &model.reflex_gains).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        let (mut top, mut airborne) = (0.0f64, 0);
        for k in 0..800 {
            let u = if (k / 40) % 2 == 0 {
                &squash.rest_lengths
            } else {
                &stretch.rest_lengths
            };
            sim.step(&mut x, u, 0.01);
            check_all_finite(&x);
            top = top.max(model.center_of_mass(&x)[2]);
            if model.contacts(&x) == 0 {
                airborne += 1;
            }
        }
        let (stats, contact) = (sim.integrator_stats(), sim.contact_stats());
        eprintln!("hopping cube: {stats:?}, {contact:?}, top {top:.3} m, airborne {airborne}");
        assert!(airborne > 20, "it should leave the floor: {airborne}");
        assert!(contact.impacts >= 8, "{contact:?}");
        assert!(
            contact.deepest <= model.floor.contact_tolerance,
            "{contact:?}"
        );
        assert!(stats.accepted + stats.rejected < 50_000, "{stats:?}");
    }

    fn check_all_finite(x: &[f64]) {
        assert!(x.iter().all(|v| v.is_finite()));
    }

    /// Distance the cube's centre of mass slides along `dir` (±x) from rest on the floor when
    /// launched with 1 m/s along it, with preferred direction +x.
    fn slide(dir: f64) -> f64 {
        let floor = Floor {
            friction: 0.2,
            preferred_friction: 0.6,
            preferred_direction: [1.0, 0.0],
            ..Floor::default()
        };
        let model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_floor(floor)
            .unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        for _ in 0..100 {
            sim.step(&mut x, &[], 0.01);
        }
        let n = model.lattice.n_masses();
        for i in 0..n {
            x[3 * n + 3 * i] += dir;
        }
        let c0 = model.center_of_mass(&x);
        for _ in 0..300 {
            sim.step(&mut x, &[], 0.01);
        }
        assert!(max_speed(&model, &x) < 1e-3, "still moving");
        (model.center_of_mass(&x)[0] - c0[0]) * dir
    }

    #[test]
    fn directional_friction_resists_the_preferred_direction() {
        let along = slide(1.0);
        let against = slide(-1.0);
        eprintln!("slide along {along:.4} m, against {against:.4} m");
        // Coulomb: d = v²/(2 μ g) = 0.255 m for μ = 0.2 and 0.085 m for μ = 0.6 when all the
        // kinetic energy goes into sliding friction; rocking and spring damping take a bit more.
        assert!(along > 0.0 && against > 0.0);
        assert!(along < 0.5 * against, "along {along}, against {against}");
        assert!(
            against < 0.255 * 1.02 && against > 0.255 * 0.85,
            "against {against}"
        );
        assert!(along < 0.085 * 1.02 && along > 0.085 * 0.5, "along {along}");
    }

    #[test]
    fn reflex_rest_lengths_are_reached_in_free_space() {
        // Zero gravity, no floor contact: the lattice relaxes to the deformed rest shape.
        let mut model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_gravity(0.0);
        model.apply_reflex(11, 0.8).unwrap(); // twist_z
        let target = model.rest_lengths.clone();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.placed_state([0.0; 3], 3.0, [0.0; 3]);
        for _ in 0..300 {
            sim.step(&mut x, &[], 0.01);
        }
        let now = lengths(&model.positions(&x), &model.lattice.springs);
        for (a, b) in now.iter().zip(&target) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Explicit controls override the active rest lengths.
        let mut dx = vec![0.0; x.len()];
        let mut dy = vec![0.0; x.len()];
        model.derivative(&x, &[], &mut dx);
        model.derivative(&x, &Lattice::cube().rest_lengths(), &mut dy);
        assert!(dx.iter().zip(&dy).any(|(a, b)| (a - b).abs() > 1e-3));
    }

    #[test]
    fn resting_contact_cancels_gravity_and_friction_holds() {
        // A single mass on the floor: the normal force cancels gravity exactly; a sliding
        // mass decelerates by μ g.
        let lattice = Lattice {
            name: "one".into(),
            masses: vec![PointMass {
                position: [0.0; 3],
                mass: 2.0,
            }],
            springs: vec![],
        };
        let model = LatticeModel::new(lattice).unwrap();
        let mut dx = [0.0; 6];
        model.derivative(&[0.0; 6], &[], &mut dx);
        assert_eq!(dx, [0.0; 6]);
        model.derivative(&[0.0, 0.0, 0.0, 3.0, 0.0, 0.0], &[], &mut dx);
        assert!((dx[3] + model.floor.friction * EARTH_GRAVITY).abs() < 1e-12);
        // Sliding along / against the preferred direction stops after v²/(2 μ g).
        let floor = Floor {
            friction: 0.2,
            preferred_friction: 0.6,
            preferred_direction: [0.0, 1.0],
            ..Floor::default()
        };
        let model = model.with_floor(floor).unwrap();
        let bad = Floor {
            stick_time: 0.0,
            ..floor
        };
        assert_eq!(
            bad.validate(),
            Err(LatticeError::InvalidFloor("stick_time", 0.0))
        );
        for (dir, mu) in [(1.0, 0.6), (-1.0, 0.2)] {
            let mut sim = LatticeSim::new(model.clone());
            let mut x = [0.0, 0.0, 0.0, 0.0, 2.0 * dir, 0.0];
            for _ in 0..300 {
                sim.step(&mut x, &[], 0.01);
            }
            let want = 4.0 / (2.0 * mu * EARTH_GRAVITY);
            assert!(x[4].abs() < 1e-9, "still sliding at {}", x[4]);
            assert!(
                (x[1] * dir - want).abs() < 1e-3 * want,
                "{} vs {want}",
                x[1]
            );
            assert_eq!((x[0], x[2]), (0.0, 0.0));
        }
        // In flight, gravity only.
        model.derivative(&[0.0, 0.0, 1.0, 3.0, 0.0, 0.0], &[], &mut dx);
        assert_eq!(&dx[3..], &[0.0, 0.0, -EARTH_GRAVITY]);
    }
}
