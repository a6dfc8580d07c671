//! Kinematic transformations between the coupling DOFs of a node and the strokes of the
//! actuators that move it through a rigid coupler (several actuators on one specimen).
//!
//! The planar coupler: a rigid body attached to a node with the DOFs `q = (x, θ)` (horizontal
//! translation \[m\], rotation \[rad\], counter-clockwise). Actuator `i` is horizontal and pinned to
//! the coupler at the point `r_i (cos α_i, sin α_i)` from the node; its stroke is the horizontal
//! displacement of that point (an actuator long against its stroke, whose end's vertical motion
//! does not change its length):
//!
//! ```text
//! s_i(q) = x + r_i (cos(θ + α_i) − cos α_i)                      forward, exact
//! J(q)   = ∂s/∂q,  J_i = [1, −r_i sin(θ + α_i)]
//! f_q    = J(q)ᵀ f_s                                           actuator forces → DOF forces
//! ```
//!
//! (virtual work: `f_sᵀ δs = f_sᵀ J δq`). The inverse `q(s)` for two actuators: Newton on
//! `s(q) = s` from `q = (s̄, 0)`; for the symmetric coupler of the multi-axial benchmark
//! (`r₁ = r₂ = d_v`, `α₁ = −α₂`) in closed form, `sin θ = (s₁ − s₂)/(2 d_v sin α₂)`,
//! `x = s₁ − d_v (cos(θ + α₁) − cos α₁)`. A stroke pair that no rotation produces
//! (`|sin θ| > 1`, or Newton without convergence) is refused as unreachable.
//!
//! The benchmark's toolset (`fcn_coupler_geometry.m`) puts `r = sin θ` instead of `θ` into the
//! cosine of the last line; [`Coupler::toolset_inverse`] reproduces that for sample-by-sample
//! comparisons (the difference in `x` is about `d_v sin(α₂) θ³/6`: 2.1e-8 m at θ = 0.01 rad).

use crate::error::{Error, Result};

/// One actuator's attachment on the coupler: distance from the node \[m\] and angle from the
/// horizontal \[rad\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attachment {
    pub radius: f64,
    pub angle: f64,
}

/// A planar rigid coupler driven by two horizontal actuators (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Coupler {
    points: [Attachment; 2],
    /// Use the toolset's inverse (`r` for `θ` in the cosine); symmetric couplers only.
    toolset: bool,
}

/// `d_v` of the multi-axial benchmark's coupler \[m\]: `√(0.2667² + 0.127²)`.
pub const MARTHS_RADIUS: f64 = 0.29539446508017037;

/// Newton iterations of the general inverse.
const MAX_NEWTON: usize = 50;

impl Coupler {
    /// A coupler with the two attachments; refused if they cannot control `(x, θ)` (the
    /// Jacobian is singular at rest: both points at the same height).
    pub fn new(points: [Attachment; 2]) -> Result<Self> {
        for (i, p) in points.iter().enumerate() {
            if !(p.radius.is_finite() && p.radius > 0.0 && p.angle.is_finite()) {
                return Err(Error::invalid(
                    format!("coupler.actuator{}", i + 1),
                    format!(
                        "needs a finite radius > 0 m and a finite angle, got radius {} m, angle {} rad",
                        p.radius, p.angle
                    ),
                ));
            }
        }
        let c = Self { points, toolset: false };
        let det = c.jacobian_det(0.0);
        if det.abs() <= 1e-9 * (points[0].radius + points[1].radius) {
            return Err(Error::invalid(
                "coupler",
                "the two attachment points are at the same height: the actuators cannot produce a rotation",
            ));
        }
        Ok(c)
    }

    /// The multi-axial benchmark's coupler (`fcn_coupler_geometry.m`): attachment points at
    /// `(0.2667, ∓0.127) m` from the node, `d_v = √(0.2667² + 0.127²) = 0.295394… m`, with the
    /// angles as the toolset writes them, `α = ∓25.4633°`.
    pub fn marths() -> Self {
        let a = 25.4633f64.to_radians();
        let d_v = MARTHS_RADIUS;
        Self {
            points: [
                Attachment { radius: d_v, angle: -a },
                Attachment { radius: d_v, angle: a },
            ],
            toolset: false,
        }
    }

    /// With the toolset's inverse (see the module docs); only for a symmetric coupler.
    pub fn toolset_inverse(mut self) -> Result<Self> {
        if !self.is_symmetric() {
            return Err(Error::invalid(
                "coupler.inverse",
                "the toolset's closed-form inverse needs a symmetric coupler (equal radii, opposite angles)",
            ));
        }
        self.toolset = true;
        Ok(self)
    }

    pub fn attachments(&self) -> &[Attachment; 2] {
        &self.points
    }

    fn is_symmetric(&self) -> bool {
        let [a, b] = self.points;
        (a.radius - b.radius).abs() <= 1e-12 * a.radius && (a.angle + b.angle).abs() <= 1e-12
    }

    fn jacobian_det(&self, theta: f64) -> f64 {
        let [a, b] = self.points;
        // det [[1, −r₁ sin(θ+α₁)], [1, −r₂ sin(θ+α₂)]]
        -b.radius * (theta + b.angle).sin() + a.radius * (theta + a.angle).sin()
    }

    /// Strokes `s` \[m\] of the DOFs `q = [x, θ]`.
    pub fn strokes(&self, q: [f64; 2]) -> [f64; 2] {
        let [x, theta] = q;
        self.points
            .map(|p| x + p.radius * ((theta + p.angle).cos() - p.angle.cos()))
    }

    /// `J(q)` row by row.
    pub fn jacobian(&self, q: [f64; 2]) -> [[f64; 2]; 2] {
        self.points.map(|p| [1.0, -p.radius * (q[1] + p.angle).sin()])
    }

    /// DOF forces `f_q = Jᵀ f_s` \[N, N·m\] of actuator forces `f_s` \[N\] at `q`.
    pub fn dof_forces(&self, q: [f64; 2], f_s: [f64; 2]) -> [f64; 2] {
        let j = self.jacobian(q);
        [j[0][0] * f_s[0] + j[1][0] * f_s[1], j[0][1] * f_s[0] + j[1][1] * f_s[1]]
    }

    /// The DOFs `q = [x, θ]` that give the strokes `s` \[m\]; an error names the strokes if no
    /// rotation gives them.
    pub fn dofs(&self, s: [f64; 2]) -> Result<[f64; 2]> {
        if !(s[0].is_finite() && s[1].is_finite()) {
            return Err(unreachable(s, "a stroke is not finite"));
        }
        if self.is_symmetric() {
            let [a, b] = self.points;
            let r = (s[0] - s[1]) / (2.0 * b.radius * b.angle.sin());
            if r.abs() > 1.0 {
                return Err(unreachable(s, &format!("sin θ would be {r}")));
            }
            let theta = r.asin();
            let in_cosine = if self.toolset { r } else { theta };
            let x = s[0] - a.radius * ((a.angle + in_cosine).cos() - a.angle.cos());
            return Ok([x, theta]);
        }
        let mut q = [0.5 * (s[0] + s[1]), 0.0];
        let scale = self.points[0].radius + self.points[1].radius;
        for _ in 0..MAX_NEWTON {
            let f = self.strokes(q);
            let r = [f[0] - s[0], f[1] - s[1]];
            if r[0].abs().max(r[1].abs()) <= 1e-14 * scale {
                return Ok(q);
            }
            let j = self.jacobian(q);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if det.abs() <= 1e-12 * scale {
                return Err(unreachable(s, "the coupler reaches a singular position"));
            }
            q[0] -= (j[1][1] * r[0] - j[0][1] * r[1]) / det;
            q[1] -= (-j[1][0] * r[0] + j[0][0] * r[1]) / det;
            if !(q[0].is_finite() && q[1].is_finite()) || q[1].abs() > std::f64::consts::PI {
                break;
            }
        }
        Err(unreachable(s, "no position of the coupler gives them"))
    }
}

fn unreachable(s: [f64; 2], why: &str) -> Error {
    Error::invalid(
        "coupler",
        format!("cannot reach the actuator strokes [{:e}, {:e}] m: {why}", s[0], s[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An asymmetric coupler (inverted by Newton).
    fn general() -> Coupler {
        Coupler::new([
            Attachment {
                radius: 0.3,
                angle: -0.4,
            },
            Attachment {
                radius: 0.5,
                angle: 0.7,
            },
        ])
        .unwrap()
    }

    #[test]
    fn forward_and_inverse_agree_and_forces_follow_virtual_work() {
        let symmetric = Coupler::marths();
        let general = general();
        for c in [&symmetric, &general] {
            for q in [[0.0, 0.0], [0.01, 0.002], [-0.03, -0.05], [0.1, 0.3]] {
                let s = c.strokes(q);
                let back = c.dofs(s).unwrap();
                assert!(
                    (back[0] - q[0]).abs() < 1e-13 && (back[1] - q[1]).abs() < 1e-13,
                    "{q:?} {back:?}"
                );
                // J against central differences, and Jᵀ by virtual work.
                let j = c.jacobian(q);
                let e = 1e-6;
                for k in 0..2 {
                    let mut qp = q;
                    let mut qm = q;
                    qp[k] += e;
                    qm[k] -= e;
                    let (sp, sm) = (c.strokes(qp), c.strokes(qm));
                    for i in 0..2 {
                        assert!(((sp[i] - sm[i]) / (2.0 * e) - j[i][k]).abs() < 1e-9);
                    }
                }
                let f = c.dof_forces(q, [1000.0, -250.0]);
                let work = |dq: [f64; 2]| {
                    1000.0 * (j[0][0] * dq[0] + j[0][1] * dq[1]) - 250.0 * (j[1][0] * dq[0] + j[1][1] * dq[1])
                };
                assert!((f[0] - work([1.0, 0.0])).abs() < 1e-9 && (f[1] - work([0.0, 1.0])).abs() < 1e-9);
            }
        }
        // The symmetric coupler: a pure translation moves both actuators alike; a rotation
        // pushes one and pulls the other by 2 d_v sin α sin θ in all.
        let s = symmetric.strokes([0.0, 0.01]);
        let d_v = MARTHS_RADIUS;
        assert_eq!(d_v, (0.2667f64.powi(2) + 0.127f64.powi(2)).sqrt());
        let a = 25.4633f64.to_radians();
        assert!((s[0] - s[1] - 2.0 * d_v * a.sin() * 0.01f64.sin()).abs() < 1e-15);
        assert_eq!(symmetric.strokes([0.02, 0.0]), [0.02, 0.02]);
    }

    #[test]
    fn the_toolset_inverse_differs_by_the_cube_of_the_rotation() {
        let exact = Coupler::marths();
        let toolset = Coupler::marths().toolset_inverse().unwrap();
        let q = [0.004, 0.01];
        let s = exact.strokes(q);
        let (a, b) = (exact.dofs(s).unwrap(), toolset.dofs(s).unwrap());
        assert_eq!(a[1], b[1]);
        let d = (a[0] - b[0]).abs();
        let expected = MARTHS_RADIUS * 25.4633f64.to_radians().sin() * 0.01f64.powi(3) / 6.0;
        assert!((d / expected - 1.0).abs() < 0.05, "{d:e} {expected:e}");
    }

    #[test]
    fn unreachable_strokes_and_degenerate_couplers_are_refused() {
        let c = Coupler::marths();
        let e = c.dofs([0.2, -0.2]).unwrap_err().to_string();
        assert!(e.contains("cannot reach") && e.contains("sin θ"), "{e}");
        let e = Coupler::new([
            Attachment {
                radius: 0.3,
                angle: 0.0,
            },
            Attachment {
                radius: 0.3,
                angle: std::f64::consts::PI,
            },
        ])
        .unwrap_err()
        .to_string();
        assert!(e.contains("same height"), "{e}");
        let general = general();
        assert!(general.dofs([5.0, -5.0]).is_err());
    }
}
