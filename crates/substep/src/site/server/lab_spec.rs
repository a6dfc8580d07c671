//! [`VirtualLabSpec`]: the virtual lab a site hosts, built per connection from the handshake.

use super::*;

/// A virtual lab to host: specimens attached to model DOFs, and the actuator and sensors used
/// for every coupling DOF. Built per connection from the client's handshake: the actuator
/// order follows the client's coupling DOFs and the sub-step length is the client's `Δτ`.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualLabSpec {
    pub specimens: Vec<SpecimenSpec>,
    pub actuator: ActuatorSpec,
    /// Base sensor specs; each channel gets its own seed (see [`channel_sensors`]).
    pub force_sensor: SensorSpec,
    pub displacement_sensor: SensorSpec,
    /// Inner intervals per sub-step (≥ 1).
    pub inner_steps: usize,
}

impl VirtualLabSpec {
    /// Specimens behind ideal actuators and sensors.
    pub fn ideal(specimens: Vec<SpecimenSpec>) -> Self {
        Self {
            specimens,
            actuator: ActuatorSpec::ideal(),
            force_sensor: SensorSpec::ideal(),
            displacement_sensor: SensorSpec::ideal(),
            inner_steps: 1,
        }
    }

    /// The lab for a client. Every coupling DOF of the client must carry a specimen and every
    /// specimen must sit on a coupling DOF of the client.
    pub fn build(&self, hello: &Hello) -> Result<VirtualLab> {
        let mut at: Vec<usize> = self.specimens.iter().flat_map(|s| s.dofs()).collect();
        at.sort_unstable();
        at.dedup();
        if let Some(d) = hello.coupling_dofs.iter().find(|d| !at.contains(d)) {
            let list: Vec<String> = at.iter().map(|d| (d + 1).to_string()).collect();
            return Err(Error::invalid(
                "site",
                format!(
                    "the client couples at model DOF {} where this site has no specimen (specimens at DOFs {})",
                    d + 1,
                    list.join(", ")
                ),
            ));
        }
        let n = hello.n_coupling;
        // per-channel seeds as in a local run's config (`[substructure.sensors] seed`)
        let (force, displacement) = channel_sensors(&self.force_sensor, &self.displacement_sensor, n);
        VirtualLab::from_specs(
            &hello.coupling_dofs,
            &self.specimens,
            &vec![self.actuator.clone(); n],
            &force,
            &displacement,
            hello.dtau,
            self.inner_steps,
        )
    }

    /// What hosting this lab for `hello` costs: the actuators' delay histories (sized from
    /// the delay and the inner-step length `Δτ / inner_steps`) and the work of one sub-step
    /// (every inner step searches each delay history). Computed in floating point, so absurd
    /// handshakes give huge numbers instead of overflowing.
    pub fn cost(&self, hello: &Hello) -> SessionCost {
        let n = hello.n_coupling as f64;
        let inner = self.inner_steps.max(1) as f64;
        let history = if self.actuator.delay > 0.0 {
            // as `DelayLine::new`: 2 (⌈delay / dt_inner⌉ + 2) samples of (time, value)
            2.0 * ((self.actuator.delay * inner / hello.dtau).ceil() + 2.0)
        } else {
            0.0
        };
        let dofs: usize = self.specimens.iter().map(|s| s.dofs().len()).sum();
        let specimen_work = (dofs * dofs) as f64 + 16.0;
        let to_u = |x: f64| if x.is_finite() && x < 1e18 { x as u64 } else { u64::MAX };
        SessionCost {
            bytes: to_u(n * history * 16.0 + n * 1024.0).min(usize::MAX as u64) as usize,
            work_per_substep: to_u(inner * (n * (history + 8.0) + specimen_work)),
        }
    }

    /// A factory for [`SiteServer::serve`] with the default [`SiteLimits`].
    pub fn factory(self) -> impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
        self.factory_with(SiteLimits::default())
    }

    /// A factory that refuses a handshake whose [`VirtualLabSpec::cost`] exceeds `limits`
    /// before building anything.
    pub fn factory_with(
        self,
        limits: SiteLimits,
    ) -> impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
        move |hello: &Hello| {
            limits
                .check_cost(hello, self.cost(hello))
                .map_err(|reason| Error::invalid("site limits", reason))?;
            Ok(Box::new(self.build(hello)?) as Box<dyn ExperimentalSubstructure>)
        }
    }
}
