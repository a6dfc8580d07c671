//! The virtual real-time hybrid simulation (RTHS) benchmark control problem of Silva, Gomez,
//! Maghareh, Dyke and Spencer (2020), reproduced: a 3-storey frame (4 cases), its first-storey
//! column as the experimental substructure behind a servo-hydraulic actuator with
//! control–structure interaction, sensor noise, A/D–D/A converters, and the evaluation criteria
//! J1–J9 against the exact reference of the full model.
//!
//! ## The benchmark's loop ([`Algorithm::Benchmark`])
//!
//! One rate `h = 1/4096 s`. Per sample `k` (order matters):
//!
//! 1. outputs at `t_k`: `q(t_k)`, the plant displacement `x_k`, the load-cell force
//!    `f_k = k_e x_k + c_e D1_k + m_e D2_k` from backward differences, and the measured
//!    `x_m = x + σ_x n_k`, `f_m = f + σ_f n_k` (one normal `n_k` of the benchmark generator for
//!    both, [`crate::transfer::noise`]);
//! 2. the controller: `u_k = C(y_n(t_k) = q₁(t_k), x_m(t_k))` (module `controller`);
//! 3. the one-sample delay stores `f_m(t_k)`;
//! 4. RK4 over `[t_k, t_{k+1}]` of the plant ([`crate::transfer::servo`], `u_k` held) and of the
//!    numerical substructure `M_N q̈ + C_N q̇ + K_N q = −M ι a_g − e₁ f_m(t_{k−1})`, `a_g`
//!    linearly interpolated from the record at the stage times.
//!
//! The reference is the exact first-order-hold discretisation of the full 3-DOF model at `h`
//! ([`reference()`](fn@reference)). J1 is the lag of the first maximum of the correlation of `x_m` with `y_n`,
//! J2/J3 NRMS/peak of `x_m − y_n`, J4/J5 of `x_m − x_r1`, J6–J9 of floors 2 and 3 against the
//! reference ([`crate::analysis::metrics`]). A run diverges (and stops: `stable = false`) when a
//! displacement leaves ±[`DIVERGENCE_LIMIT`] or is not finite; a run that completes with
//! J2 > [`UNSTABLE_TRACKING_PERCENT`] is not stable either; `max |F| ≥ 8900 N` flags
//! `capacity_exceeded`.
//!
//! ## With the sub-step algorithm ([`Algorithm::Substep`])
//!
//! The same plant, sensors and controller at 4096 Hz; the numerical substructure is integrated
//! by [`crate::substructure::SubstepController`] (Newmark at `Δt = n h`, `k_sub` sub-steps of
//! `Δτ = Δt/k_sub`, error-force compensation), with the ground load `−M ι a_g(t_i)` of the full
//! mass. The mapping onto the controller samples:
//!
//! * the command signal is linear between the sub-step commands (the project's convention):
//!   `d^(s)` is reached at the end of sub-step `s`, `(s+1)Δτ`, starting from `d^(s−1)` at `sΔτ`;
//!   the controller samples it at `t_k` as its desired displacement `y_n(t_k)`;
//! * the force fed back at the end of sub-step `s` is the latest measured sample at or before
//!   that time, `f_m(⌊(s+1)Δτ/h⌋ h)` (negated: the controller takes the force *on* the
//!   numerical substructure);
//! * a sub-step is computed when the controller first needs its command, which is causal: the
//!   command of sub-step `s` needs the force at `sΔτ < t_k`, already measured.
//!
//! With `Δτ = h` this is the benchmark's one-sample force delay; `Δτ < h` (e.g. `k_sub = 8` at
//! `Δt = 1/1024 s`) feeds the same sample to consecutive sub-steps. J6–J9 are evaluated on the
//! step grid `t_i` (the floors exist only there); J1–J5 at every sample.
//!
//! Nothing in the per-sample loop allocates (the histories are sized before it).

mod case;
mod compare;
mod config;
mod controller;
mod options;
mod perturb;
pub mod report;
mod run;
mod study;

pub use case::{Case, ELCENTRO_CSV, GroundRecord, MAX_DURATION, Specimen, numerical_matrices};
pub use compare::{COMPARED, ComparisonRow, compare};
pub use config::{BenchmarkConfig, CONFIG_KEYS};
pub use controller::{
    Controller, ControllerKind, ControllerSpec, INVERSE_FIR_REFUSED, SAMPLE_TIME, arx_default, ats_default,
    sample_feedback, sample_feedforward,
};
pub use options::{StudyOptions, StudySetup};
pub use perturb::{PERTURBATION_SIGMA, perturbed_plant, run_perturbed};
pub use run::{
    Algorithm, Criteria, DIVERGENCE_LIMIT, FORCE_CAPACITY, MAX_LAG, NOISE_POWER_F, NOISE_POWER_X, RthsInput,
    RthsResult, RunHistory, SubstepSpec, Transfer, UNSTABLE_TRACKING_PERCENT, reference, run,
};
pub use study::{MAX_PERTURBED, PerturbedStats, RthsRow, perturbed_stats, run_study};

/// Published results (Silva et al. 2020, table 3): the sample controller, El Centro at 0.4,
/// nominal plant; rows cases 1–4, columns J1 \[ms\], J2…J9 [%].
pub const PUBLISHED_SAMPLE: [[f64; 9]; 4] = [
    [4.6, 10.4, 11.5, 36.1, 19.0, 32.3, 32.4, 14.8, 14.8],
    [4.6, 9.8, 11.1, 33.1, 17.1, 30.5, 30.5, 15.3, 15.2],
    [4.6, 9.1, 10.2, 49.9, 36.7, 49.8, 49.8, 35.5, 35.6],
    [4.6, 10.5, 11.3, 72.6, 35.2, 68.5, 68.7, 33.4, 33.3],
];
