//! The articulated tree's description ([`Tree3d`], [`Body3d`], [`Joint3d`]), its state
//! layout, its validation and what `motionlab describe` prints; the dynamics are in
//! [`super::dynamics`], the equations in the [module docs](super).

use super::spatial;
use crate::physics::{Model, Parameter};
use nalgebra::{Matrix3, Matrix6, Vector3};
use serde::{Deserialize, Serialize};

/// Most bodies a tree may have.
pub const MAX_BODIES: usize = 16;
/// Most velocity coordinates (degrees of freedom) a tree may have.
pub const MAX_DOF: usize = 32;

/// The joint between a body and its parent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Joint3d {
    /// Six degrees of freedom to the world (the root only): position p of the body's origin
    /// in the world (m) and unit quaternion q (w, x, y, z) taking body to world coordinates;
    /// velocities ṗ in world coordinates (m/s) and the angular velocity ω in body coordinates
    /// (rad/s), MuJoCo's free joint.
    Free,
    /// Three rotational degrees of freedom: the unit quaternion (w, x, y, z) of the body's
    /// rotation relative to its joint frame; velocity the relative angular velocity in the
    /// body's coordinates (rad/s), MuJoCo's ball joint.
    Ball,
    /// One rotational degree of freedom about `axis`, a unit vector in the joint frame (which
    /// it shares with the body): the angle (rad) and its rate (rad/s), MuJoCo's hinge.
    Revolute {
        /// Unit rotation axis in the joint frame (normalized when used).
        axis: [f64; 3],
    },
}

impl Joint3d {
    /// Number of position coordinates.
    pub fn nq(&self) -> usize {
        match self {
            Joint3d::Free => 7,
            Joint3d::Ball => 4,
            Joint3d::Revolute { .. } => 1,
        }
    }

    /// Number of velocity coordinates (degrees of freedom).
    pub fn nv(&self) -> usize {
        match self {
            Joint3d::Free => 6,
            Joint3d::Ball => 3,
            Joint3d::Revolute { .. } => 1,
        }
    }

    pub(super) fn code(&self) -> f64 {
        match self {
            Joint3d::Free => 0.0,
            Joint3d::Ball => 1.0,
            Joint3d::Revolute { .. } => 2.0,
        }
    }
}

/// One rigid body and the joint to its parent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Body3d {
    /// Name (used in state and control names).
    pub name: String,
    /// Parent body index (`None` for the root, body 0, whose joint is [`Joint3d::Free`]).
    pub parent: Option<usize>,
    /// Joint to the parent.
    pub joint: Joint3d,
    /// Position of the joint (the body's origin) in the parent's coordinates (m); unused by
    /// the root.
    pub offset: [f64; 3],
    /// Quaternion (w, x, y, z) of the joint frame relative to the parent's frame, the body's
    /// orientation at zero joint angle (normalized when used); unused by the root.
    pub orientation: [f64; 4],
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the body's coordinates (m).
    pub com: [f64; 3],
    /// Inertia tensor about the centre of mass in the body's axes, `[ixx, iyy, izz, ixy,
    /// ixz, iyz]` (kg·m²), entries of I = ∫ (|r|² 1 − r rᵀ) dm (so ixy = −∫ x y dm), MuJoCo's
    /// `fullinertia` order.
    pub inertia: [f64; 6],
    /// Viscous friction at the joint, per degree of freedom (N·m·s/rad; unused by the root).
    pub damping: f64,
    /// Whether the joint has motors: one torque per degree of freedom (N·m), about the
    /// revolute axis or about the body's x, y, z axes for a ball.
    pub actuated: bool,
}

impl Body3d {
    /// The inertia tensor as a matrix (kg·m²).
    pub fn inertia_matrix(&self) -> Matrix3<f64> {
        let [xx, yy, zz, xy, xz, yz] = self.inertia;
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }

    pub(super) fn spatial_inertia(&self) -> Matrix6<f64> {
        spatial::inertia(self.mass, &Vector3::from(self.com), &self.inertia_matrix())
    }
}

/// A point fixed on a body of a tree, where an external force acts (a contact point).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyPoint {
    /// Index of the body in [`Tree3d::bodies`].
    pub body: usize,
    /// Position in the body's coordinates (m).
    pub offset: [f64; 3],
}

/// A 3-D articulated tree with a floating base.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tree3d {
    /// Registry name.
    pub name: String,
    /// Bodies; body 0 is the root and parents come before children.
    pub bodies: Vec<Body3d>,
    /// Gravitational acceleration along the world −z axis (m/s²).
    pub gravity: f64,
    /// Natural time step (s).
    pub dt: f64,
}

/// A tree that [`Tree3d::validate`] refuses, naming the body and the bad value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TreeError {
    /// No bodies.
    #[error("a tree needs at least one body")]
    Empty,
    /// Too many bodies or degrees of freedom.
    #[error("{what} = {value}, at most {max}")]
    TooLarge {
        /// `bodies` or `dof`.
        what: &'static str,
        /// The count.
        value: usize,
        /// The limit.
        max: usize,
    },
    /// The root is not body 0 with a free joint, or a later body is free or has no earlier
    /// parent.
    #[error("body {body}: {why}")]
    Structure {
        /// Body index.
        body: usize,
        /// What is wrong.
        why: &'static str,
    },
    /// A mass, inertia, axis or orientation out of range.
    #[error("body {body}: {what} = {value:?} {why}")]
    Value {
        /// Body index.
        body: usize,
        /// Field name.
        what: &'static str,
        /// The values.
        value: Vec<f64>,
        /// What it must be.
        why: &'static str,
    },
}

impl Tree3d {
    /// Number of position coordinates (the quaternions count four each).
    pub fn nq(&self) -> usize {
        self.bodies.iter().map(|b| b.joint.nq()).sum()
    }

    /// Number of velocity coordinates (degrees of freedom).
    pub fn nv(&self) -> usize {
        self.bodies.iter().map(|b| b.joint.nv()).sum()
    }

    /// Index of body `i`'s first position coordinate in the state.
    pub fn q_index(&self, i: usize) -> usize {
        self.bodies[..i].iter().map(|b| b.joint.nq()).sum()
    }

    /// Index of body `i`'s first velocity coordinate within the velocity block.
    pub fn v_index(&self, i: usize) -> usize {
        self.bodies[..i].iter().map(|b| b.joint.nv()).sum()
    }

    /// Checks the structure and the values.
    pub fn validate(&self) -> Result<(), TreeError> {
        let n = self.bodies.len();
        if n == 0 {
            return Err(TreeError::Empty);
        }
        if n > MAX_BODIES {
            return Err(TreeError::TooLarge {
                what: "bodies",
                value: n,
                max: MAX_BODIES,
            });
        }
        if self.nv() > MAX_DOF {
            return Err(TreeError::TooLarge {
                what: "dof",
                value: self.nv(),
                max: MAX_DOF,
            });
        }
        for (i, b) in self.bodies.iter().enumerate() {
            let bad = |why| Err(TreeError::Structure { body: i, why });
            match (i, b.parent, b.joint) {
                (0, None, Joint3d::Free) if !b.actuated => {}
                (0, ..) => return bad("the root must be free, unactuated and have no parent"),
                (_, _, Joint3d::Free) => return bad("only the root may be free"),
                (_, Some(p), _) if p < i => {}
                _ => return bad("its parent must come before it"),
            }
            let value = |what, value: &[f64], why| {
                Err(TreeError::Value {
                    body: i,
                    what,
                    value: value.to_vec(),
                    why,
                })
            };
            if !(b.mass > 0.0 && b.mass.is_finite()) {
                return value("mass", &[b.mass], "must be positive");
            }
            let eig = b.inertia_matrix().symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            if !(lo > 0.0 && 2.0 * hi <= eig.sum() * (1.0 + 1e-12)) {
                return value(
                    "inertia",
                    &b.inertia,
                    "must be positive definite with principal moments obeying the triangle inequality",
                );
            }
            if let Joint3d::Revolute { axis } = b.joint {
                if !(Vector3::from(axis).norm() > 0.0) {
                    return value("axis", &axis, "must be a non-zero vector");
                }
            }
            let o = b.orientation;
            if !(o.iter().map(|c| c * c).sum::<f64>() > 0.0) {
                return value("orientation", &o, "must be a non-zero quaternion");
            }
            if !(b.damping >= 0.0) {
                return value("damping", &[b.damping], "must be >= 0");
            }
        }
        Ok(())
    }

    /// Rescales every quaternion of `x` (the root's and each ball's) to unit norm; a zero
    /// quaternion is left alone.
    pub fn normalize_state(&self, x: &mut [f64]) {
        let mut iq = 0;
        for b in &self.bodies {
            let at = match b.joint {
                Joint3d::Free => Some(iq + 3),
                Joint3d::Ball => Some(iq),
                Joint3d::Revolute { .. } => None,
            };
            if let Some(a) = at {
                let q = &mut x[a..a + 4];
                let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
                if n > 0.0 {
                    q.iter_mut().for_each(|c| *c /= n);
                }
            }
            iq += b.joint.nq();
        }
    }

    /// Bodies with motors, in control order.
    pub fn actuated(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.bodies.len()).filter(|&i| self.bodies[i].actuated)
    }
}

impl Model for Tree3d {
    fn name(&self) -> &str {
        &self.name
    }
    fn state_names(&self) -> Vec<String> {
        let (mut q, mut v) = (Vec::new(), Vec::new());
        for b in &self.bodies {
            let n = &b.name;
            match b.joint {
                Joint3d::Free => {
                    q.extend(["x", "y", "z", "qw", "qx", "qy", "qz"].map(|s| format!("{n}_{s}")));
                    v.extend(["vx", "vy", "vz", "wx", "wy", "wz"].map(|s| format!("{n}_{s}")));
                }
                Joint3d::Ball => {
                    q.extend(["qw", "qx", "qy", "qz"].map(|s| format!("{n}_{s}")));
                    v.extend(["wx", "wy", "wz"].map(|s| format!("{n}_{s}")));
                }
                Joint3d::Revolute { .. } => {
                    q.push(format!("{n}_angle"));
                    v.push(format!("{n}_rate"));
                }
            }
        }
        q.into_iter().chain(v).collect()
    }
    fn control_names(&self) -> Vec<String> {
        let mut c = Vec::new();
        for i in self.actuated() {
            let b = &self.bodies[i];
            match b.joint {
                Joint3d::Ball => {
                    c.extend(["tx", "ty", "tz"].map(|s| format!("{}_{s}", b.name)));
                }
                _ => c.push(format!("{}_torque", b.name)),
            }
        }
        c
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = Vec::new();
        for b in &self.bodies {
            let n = &b.name;
            let parent = b.parent.map_or(-1.0, |j| j as f64);
            p.push(Parameter::new(
                format!("{n}.parent"),
                parent,
                "1",
                "parent body index (-1: the world)",
            ));
            p.push(Parameter::new(
                format!("{n}.joint"),
                b.joint.code(),
                "1",
                "joint type: 0 free, 1 ball, 2 revolute",
            ));
            if b.parent.is_some() {
                for (k, c) in ["x", "y", "z"].iter().enumerate() {
                    p.push(Parameter::new(
                        format!("{n}.offset.{c}"),
                        b.offset[k],
                        "m",
                        "joint position (body origin) in the parent's coordinates",
                    ));
                }
                for (k, c) in ["w", "x", "y", "z"].iter().enumerate() {
                    p.push(Parameter::new(
                        format!("{n}.orientation.{c}"),
                        b.orientation[k],
                        "1",
                        "quaternion of the joint frame relative to the parent's frame",
                    ));
                }
            }
            if let Joint3d::Revolute { axis } = b.joint {
                for (k, c) in ["x", "y", "z"].iter().enumerate() {
                    p.push(Parameter::new(
                        format!("{n}.axis.{c}"),
                        axis[k],
                        "1",
                        "revolute axis in the joint frame (normalized when used)",
                    ));
                }
            }
            p.push(Parameter::new(
                format!("{n}.mass"),
                b.mass,
                "kg",
                "body mass",
            ));
            for (k, c) in ["x", "y", "z"].iter().enumerate() {
                p.push(Parameter::new(
                    format!("{n}.com.{c}"),
                    b.com[k],
                    "m",
                    "centre of mass in the body's coordinates",
                ));
            }
            for (k, c) in ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"]
                .iter()
                .enumerate()
            {
                p.push(Parameter::new(
                    format!("{n}.inertia.{c}"),
                    b.inertia[k],
                    "kg*m^2",
                    "inertia tensor entry about the centre of mass, body axes",
                ));
            }
            if b.parent.is_some() {
                p.push(Parameter::new(
                    format!("{n}.damping"),
                    b.damping,
                    "N*m*s/rad",
                    "viscous friction at the joint, per degree of freedom",
                ));
                p.push(Parameter::new(
                    format!("{n}.actuated"),
                    if b.actuated { 1.0 } else { 0.0 },
                    "1",
                    "1 when the joint has a torque control per degree of freedom",
                ));
            }
        }
        p.push(Parameter::gravity(
            self.gravity,
            "gravitational acceleration (along the world -z axis)",
        ));
        p
    }
    fn default_dt(&self) -> f64 {
        self.dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::body3d::chain3d;

    #[test]
    fn validate_names_what_is_wrong() {
        assert!(chain3d().validate().is_ok());
        let mut t = chain3d();
        t.bodies[2].inertia = [0.01, 0.01, 0.05, 0.0, 0.0, 0.0];
        assert!(matches!(
            t.validate(),
            Err(TreeError::Value {
                body: 2,
                what: "inertia",
                ..
            })
        ));
        let mut t = chain3d();
        t.bodies[3].parent = Some(3);
        assert!(matches!(
            t.validate(),
            Err(TreeError::Structure { body: 3, .. })
        ));
        let mut t = chain3d();
        t.bodies[1].joint = Joint3d::Free;
        assert!(matches!(
            t.validate(),
            Err(TreeError::Structure { body: 1, .. })
        ));
        let mut t = chain3d();
        t.bodies[2].joint = Joint3d::Revolute { axis: [0.0; 3] };
        assert!(matches!(
            t.validate(),
            Err(TreeError::Value { what: "axis", .. })
        ));
    }
}
