//! The controller's parameterization: piecewise-constant knots ([`Knots`]) and the actuators'
//! boxes with the normalized-knot map ([`Bounds`]).

/// Piecewise-constant controls: `per_actuator` knots per actuator over `steps` steps; knot k
/// (of actuator j, stored at `k * m + j`) holds on the steps i with ⌊i K / M⌋ = k.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Knots {
    /// Steps M.
    pub steps: usize,
    /// Knots per actuator K (1 ≤ K ≤ M).
    pub per_actuator: usize,
    /// Actuators m.
    pub m: usize,
}

impl Knots {
    /// Total number of knot values K m.
    pub fn len(&self) -> usize {
        self.per_actuator * self.m
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The knot that step `i` uses.
    pub fn knot_of(&self, i: usize) -> usize {
        i * self.per_actuator / self.steps
    }
    /// Per-step controls (M m) from knot values (K m).
    pub fn expand(&self, knots: &[f64], controls: &mut [f64]) {
        let m = self.m;
        for i in 0..self.steps {
            let k = self.knot_of(i);
            controls[i * m..(i + 1) * m].copy_from_slice(&knots[k * m..(k + 1) * m]);
        }
    }
    /// Knot gradients: sums the per-step gradients over the steps each knot holds.
    pub fn reduce(&self, u_bar: &[f64], knot_bar: &mut [f64]) {
        let m = self.m;
        knot_bar.fill(0.0);
        for i in 0..self.steps {
            let k = self.knot_of(i);
            for j in 0..m {
                knot_bar[k * m + j] += u_bar[i * m + j];
            }
        }
    }
}

/// Box bounds on each actuator, and the optimizer's unit of each: the normalized knot value v
/// of actuator j stands for the control u = c_j + h_j g_j v, with c_j and h_j the centre and
/// half-width of its box and g_j its gain (1 unless [`Bounds::with_gain`] says otherwise), so
/// the box is |v| ≤ 1/g_j. A gain rescales an actuator's variables against the others' (how
/// far one unit of descent moves it), never its box.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds (may be −∞).
    pub low: Vec<f64>,
    /// Upper bounds (may be +∞).
    pub high: Vec<f64>,
    /// Gain g_j per actuator (empty: all 1).
    gain: Vec<f64>,
    /// Whether [`Bounds::project`] clips to the boxes (true unless
    /// [`Bounds::without_clipping`]).
    clip: bool,
}

impl Bounds {
    /// Boxes [low_j, high_j] (either side may be infinite), unit gains.
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> Self {
        Self {
            low,
            high,
            gain: Vec::new(),
            clip: true,
        }
    }
    /// The same map from normalized values to controls, with the boxes no longer enforced:
    /// [`Bounds::project`] is the identity (the controls may leave their boxes). For studying
    /// descent without the clipping that hides its divergence (Fig. 14).
    pub fn without_clipping(mut self) -> Self {
        self.clip = false;
        self
    }
    /// Whether [`Bounds::project`] clips to the boxes.
    pub fn clips(&self) -> bool {
        self.clip
    }
    /// No bounds on `m` actuators.
    pub fn unbounded(m: usize) -> Self {
        Self::new(vec![f64::NEG_INFINITY; m], vec![f64::INFINITY; m])
    }
    /// The same boxes with gain `gain[j]` (positive and finite) on actuator j.
    ///
    /// # Panics
    /// When `gain` does not have one positive finite value per actuator.
    pub fn with_gain(mut self, gain: Vec<f64>) -> Self {
        assert_eq!(gain.len(), self.low.len(), "one gain per actuator");
        assert!(
            gain.iter().all(|g| g.is_finite() && *g > 0.0),
            "gains must be positive and finite: {gain:?}"
        );
        // Unit gains are stored as none, so a box with unit gains equals the plain box.
        self.gain = if gain.iter().all(|&g| g == 1.0) {
            Vec::new()
        } else {
            gain
        };
        self
    }
    /// Gain g_j of actuator j.
    pub fn gain(&self, j: usize) -> f64 {
        self.gain.get(j).copied().unwrap_or(1.0)
    }
    /// Centre c_j and scale h_j g_j of actuator j: u = c_j + h_j g_j v (h_j the box's
    /// half-width; (0, g_j) when the box is unbounded on a side).
    pub fn affine(&self, j: usize) -> (f64, f64) {
        let (lo, hi) = (self.low[j], self.high[j]);
        let g = self.gain(j);
        if lo.is_finite() && hi.is_finite() {
            (0.5 * (lo + hi), 0.5 * (hi - lo) * g)
        } else {
            (0.0, g)
        }
    }
    /// Control values from normalized values `v` of consecutive actuators (value i belongs to
    /// actuator i mod m): u_i = c_j + h_j g_j v_i with [`Bounds::affine`] of j.
    pub fn denormalize(&self, v: &[f64], u: &mut [f64]) {
        // Actuator by actuator down the knots: the same c_j + h_j v_i as value by value, without
        // an integer division and the bounds' tests per value.
        let m = self.low.len();
        let n = u.len().min(v.len());
        for j in 0..m {
            let (c, h) = self.affine(j);
            for i in (j..n).step_by(m) {
                u[i] = c + h * v[i];
            }
        }
    }
    /// Projects a normalized value of actuator j onto its box.
    pub fn project(&self, j: usize, v: f64) -> f64 {
        if !self.clip {
            return v;
        }
        let (lo, hi) = (self.low[j], self.high[j]);
        let g = self.gain(j);
        if lo.is_finite() && hi.is_finite() {
            if g == 1.0 {
                v.clamp(-1.0, 1.0)
            } else {
                v.clamp(-1.0 / g, 1.0 / g)
            }
        } else if g == 1.0 {
            v.clamp(lo, hi)
        } else {
            v.clamp(lo / g, hi / g)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::bptt::dot;

    /// [`Bounds::denormalize`] (actuator by actuator) is c_j + h_j v_i value by value, every
    /// bit, for bounded and unbounded actuators and a length that is not a whole number of
    /// knots.
    #[test]
    fn denormalize_is_the_affine_map_value_by_value() {
        let bounds = Bounds::new(vec![-2.0, f64::NEG_INFINITY, 0.3], vec![5.0, 1.0, 0.7]);
        let v: Vec<f64> = (0..17).map(|i| (i as f64 * 0.37).sin() * 1.3).collect();
        let mut u = vec![f64::NAN; v.len()];
        bounds.denormalize(&v, &mut u);
        for (i, (u, v)) in u.iter().zip(&v).enumerate() {
            let (c, h) = bounds.affine(i % 3);
            assert_eq!(u.to_bits(), (c + h * v).to_bits(), "value {i}");
        }
    }

    /// A gain g_j rescales actuator j's variable and nothing else: the control of v is
    /// c + h g v, the box in v is |v| <= 1/g (u stays within its box), and v = (u - c)/(h g)
    /// round-trips; unit gains are the plain box map, bit for bit.
    #[test]
    fn a_gain_rescales_the_variable_not_the_box() {
        let plain = Bounds::new(vec![-3.0, -0.5, f64::NEG_INFINITY], vec![3.0, 0.5, 2.0]);
        let gained = plain.clone().with_gain(vec![1.0, 16.0, 4.0]);
        let v = [0.3, 0.05, -1.0, 2.0, 1.0, 9.0];
        let (mut u0, mut u1) = ([0.0; 6], [0.0; 6]);
        plain.denormalize(&v, &mut u0);
        gained.denormalize(&v, &mut u1);
        assert_eq!(u0[0].to_bits(), u1[0].to_bits());
        assert!((u1[1] - 16.0 * u0[1]).abs() < 1e-12, "{u1:?}");
        assert!((u1[2] - 4.0 * u0[2]).abs() < 1e-12, "{u1:?}");
        // The box in u is the same: projecting then mapping never leaves it.
        for j in 0..3 {
            for &x in &[-100.0, -0.07, 0.0, 0.07, 100.0] {
                let mut u = [0.0; 3];
                let mut w = [0.0; 3];
                w[j] = gained.project(j, x);
                gained.denormalize(&w, &mut u);
                assert!(u[j] >= plain.low[j] - 1e-12 && u[j] <= plain.high[j] + 1e-12);
            }
        }
        assert_eq!(gained.project(1, 1.0), 1.0 / 16.0);
        assert_eq!(gained.project(2, 1.0), 0.5);
        let (c, h) = gained.affine(1);
        assert!(((0.2 - c) / h * 16.0 * 0.5 - 0.2).abs() < 1e-12);
        assert_eq!(plain.gain(1), 1.0);
        assert_eq!(gained.gain(1), 16.0);
        assert_eq!(plain.clone().with_gain(vec![1.0; 3]), plain);
        // Without clipping the map is the same and the box is no longer enforced.
        let free = gained.clone().without_clipping();
        assert_eq!(free.affine(1), gained.affine(1));
        assert_eq!(free.project(1, 1.0), 1.0);
        assert_eq!(free.project(0, -7.5), -7.5);
        assert!(gained.clips() && !free.clips());
    }

    #[test]
    fn knots_expand_and_reduce_are_adjoint() {
        let k = Knots {
            steps: 40,
            per_actuator: 20,
            m: 4,
        };
        assert_eq!(k.len(), 80);
        assert_eq!(
            (k.knot_of(0), k.knot_of(1), k.knot_of(2), k.knot_of(39)),
            (0, 0, 1, 19)
        );
        let knots: Vec<f64> = (0..80).map(|i| i as f64).collect();
        let ub: Vec<f64> = (0..160).map(|i| (i as f64).sin()).collect();
        let mut u = vec![0.0; 160];
        k.expand(&knots, &mut u);
        let mut kb = vec![0.0; 80];
        k.reduce(&ub, &mut kb);
        assert!((dot(&u, &ub) - dot(&knots, &kb)).abs() < 1e-9);
    }
}
