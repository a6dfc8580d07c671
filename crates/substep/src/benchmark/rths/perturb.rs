//! Perturbed plants for robustness runs: `k_e`, `β₁`, `β₂`, `a₃` drawn from normal
//! distributions around the nominal values with the benchmark's σ (5e4 N/m, 3.3, 3.3e3, 1.3).
//! Run `i` of seed `S` draws from ChaCha8 with seed `S` and stream `i`, so every run is the same
//! whatever the number of threads or runs. The specimen damping `c_e` is kept nominal.

use super::run::{RthsInput, RthsResult, Transfer, run};
use crate::error::Result;
use crate::transfer::servo::ServoParams;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

/// σ of `k_e`, `β₁`, `β₂`, `a₃`.
pub const PERTURBATION_SIGMA: [f64; 4] = [5e4, 3.3, 3.3e3, 1.3];

/// The plant of perturbed run `index` (0-based) under `seed`.
pub fn perturbed_plant(nominal: &ServoParams, seed: u64, index: u64) -> ServoParams {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index);
    let mut draw = |mean: f64, sigma: f64| Normal::new(mean, sigma).expect("σ > 0").sample(&mut rng);
    ServoParams {
        k_e: draw(nominal.k_e, PERTURBATION_SIGMA[0]),
        beta1: draw(nominal.beta1, PERTURBATION_SIGMA[1]),
        beta2: draw(nominal.beta2, PERTURBATION_SIGMA[2]),
        a3: draw(nominal.a3, PERTURBATION_SIGMA[3]),
        ..*nominal
    }
}

/// `runs` perturbed copies of `input` (its plant is the nominal one), in parallel (rayon), in
/// run order.
pub fn run_perturbed(input: &RthsInput, runs: usize, seed: u64) -> Result<Vec<(ServoParams, RthsResult)>> {
    let (nominal, derivative) = match input.transfer {
        Transfer::Plant { params, derivative } => (params, derivative),
        Transfer::Ideal => (ServoParams::benchmark(), Default::default()),
    };
    (0..runs as u64)
        .into_par_iter()
        .map(|i| {
            let params = perturbed_plant(&nominal, seed, i);
            let mut one = input.clone();
            one.transfer = Transfer::Plant { params, derivative };
            run(&one).map(|r| (params, r))
        })
        .collect()
}
