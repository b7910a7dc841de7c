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

/// Box bounds on each actuator.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds (may be −∞).
    pub low: Vec<f64>,
    /// Upper bounds (may be +∞).
    pub high: Vec<f64>,
}

impl Bounds {
    /// No bounds on `m` actuators.
    pub fn unbounded(m: usize) -> Self {
        Self {
            low: vec![f64::NEG_INFINITY; m],
            high: vec![f64::INFINITY; m],
        }
    }
    /// Centre and half-width of actuator j's box ((0, 1) when it is unbounded on a side).
    pub fn affine(&self, j: usize) -> (f64, f64) {
        let (lo, hi) = (self.low[j], self.high[j]);
        if lo.is_finite() && hi.is_finite() {
            (0.5 * (lo + hi), 0.5 * (hi - lo))
        } else {
            (0.0, 1.0)
        }
    }
    /// Control values from normalized values `v` of consecutive actuators (value i belongs to
    /// actuator i mod m): u_i = c_j + h_j v_i with [`Bounds::affine`] of j.
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
        let (lo, hi) = (self.low[j], self.high[j]);
        if lo.is_finite() && hi.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            v.clamp(lo, hi)
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
        let bounds = Bounds {
            low: vec![-2.0, f64::NEG_INFINITY, 0.3],
            high: vec![5.0, 1.0, 0.7],
        };
        let v: Vec<f64> = (0..17).map(|i| (i as f64 * 0.37).sin() * 1.3).collect();
        let mut u = vec![f64::NAN; v.len()];
        bounds.denormalize(&v, &mut u);
        for (i, (u, v)) in u.iter().zip(&v).enumerate() {
            let (c, h) = bounds.affine(i % 3);
            assert_eq!(u.to_bits(), (c + h * v).to_bits(), "value {i}");
        }
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
