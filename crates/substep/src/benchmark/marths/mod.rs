//! The multi-axial RTHS benchmark (maRTHS; Condori Uribe et al. 2023) as its public toolset
//! (FermandoisLab/maRTHS-bmk-RoDeAC, MIT) defines it: a 29-DOF 3-storey steel frame whose
//! first-storey node is driven in `x` and `θ` by two actuators through a rigid coupler, a 2×2
//! identified control plant, a virtual 5-DOF physical frame giving the feedback force, sensor
//! noise, the RoDeAC controller, and the criteria J1–J10 (docs/benchmark.md, "maRTHS").
//!
//! ## The loop (one sample `k`, `h = 1/1024 s`, in the order of the toolset's Simulink model)
//!
//! 1. `a_g(t_k)` = intensity × the record, linearly interpolated;
//! 2. the plant's output `y_k = C x_k` (its state after `k` RK4 steps; no direct feedthrough),
//!    plus sensor noise (one normal draw for both actuators, as the toolset seeds both blocks
//!    alike) → measured strokes \[mm\];
//! 3. the coupler's inverse ([`crate::transfer::kinematics`], the toolset's form) → measured
//!    `(x̂, θ̂)`; the virtual frame's force from it ([`structure::FrameForce`]);
//! 4. the numerical substructure's Newmark step with that force and `a_g(t_k)`
//!    ([`structure::NewmarkFrame`]) → target `(U₂₇, −U₂₁)` → the coupler → target strokes;
//! 5. the controller per actuator → commands; the plant's RK4 step with them held;
//! 6. the reference frame's step (computed once per record and intensity, [`reference()`]).
//!
//! The ideal transfer system ([`Transfer::Ideal`]) measures the target of the same sample: the
//! numerical step and the virtual frame are then solved together ([`structure::solve_ideal`]),
//! so J1–J6 vanish and J7–J10 show the benchmark's floor (the virtual frame is not the partition
//! it replaces; the partition's mass and its ground-inertia force are lost).

mod config;
pub mod data;
mod mimo_arx;
mod options;
pub mod report;
mod rodeac;
mod run;
pub mod structure;
mod study;

pub use config::MarthsConfig;
pub use data::{InitialParameters, PlantParameters, Record};
pub use mimo_arx::{MimoArx, MimoArxSpec};
pub use options::{MarthsOptions, RecordChoice, criteria_json, names_a_record_file, shipped_record};
pub use rodeac::{BUTTER_A, BUTTER_B, Butterworth, RlsAc, rodeac};
pub use run::{
    Algorithm, COMMAND_LIMIT_V, ControllerKind, Criteria, DIVERGENCE_LIMIT, History, MAX_LAG, MarthsInput,
    MarthsResult, NOISE_STD_MM, Reference, SAMPLE_TIME, SubstepSpec, Transfer, arx_default, evaluate, find_delay,
    numerical_matrices, reference, round1, run, volts,
};
pub use study::{CompareRow, MAX_TRIALS, Study, compare, compare_markdown, run_study, run_with, uncertain_plant};
