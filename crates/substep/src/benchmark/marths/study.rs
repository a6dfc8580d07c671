//! Uncertain plants and trials: the toolset's `fcn_build_uncert_plant.m` with a seeded generator,
//! the nominal run and `N` uncertain trials in parallel, and the average the toolset reports.

use super::data::PlantParameters;
use super::run::{Criteria, MarthsInput, MarthsResult, Reference, Transfer, reference, run};
use crate::error::{Error, Result};
use nalgebra::Complex;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

/// Most uncertain trials one study runs.
pub const MAX_TRIALS: usize = 1000;

/// Relative σ of the perturbed zeros and poles (`fcn_build_uncert_plant.m`): H11/H21 zeros,
/// H11/H21 real poles, H12 and H22 zeros, H12/H22 real poles, the frame pair.
pub const SIGMA_H1_ZEROS: f64 = 0.055;
pub const SIGMA_H1_POLES: f64 = 0.06;
pub const SIGMA_H2: f64 = 0.03;
pub const SIGMA_FRAME: f64 = 0.05;

/// The plant of uncertain trial `index` (0-based) under `seed`: every zero and pole `v` becomes
/// `v (1 + σ n)`, `n` standard normal from ChaCha8 (seed `seed`, stream `index`) in the
/// toolset's draw order (h1z₁, h1z₂, h1p₁, h1p₂, frame pole, h12z, h2p₁, h2p₂, h22z; the frame
/// pair scaled by one real draw, its conjugate mirrored); each channel's gain rescaled so that
/// its static gain stays nominal (the toolset matches the magnitude at the lowest frequency of a
/// Bode grid, 0.01 Hz for H11).
pub fn uncertain_plant(seed: u64, index: u64) -> Result<PlantParameters> {
    let nominal = PlantParameters::nominal();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index);
    let mut draw = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut p = nominal;
    p.h1_zeros[0] *= 1.0 + SIGMA_H1_ZEROS * draw();
    p.h1_zeros[1] *= 1.0 + SIGMA_H1_ZEROS * draw();
    p.h1_poles[0] *= 1.0 + SIGMA_H1_POLES * draw();
    p.h1_poles[1] *= 1.0 + SIGMA_H1_POLES * draw();
    p.frame_pole *= Complex::new(1.0 + SIGMA_FRAME * draw(), 0.0);
    p.h12_zero *= 1.0 + SIGMA_H2 * draw();
    p.h2_poles[0] *= 1.0 + SIGMA_H2 * draw();
    p.h2_poles[1] *= 1.0 + SIGMA_H2 * draw();
    p.h22_zero *= 1.0 + SIGMA_H2 * draw();
    let dc_nominal = nominal.transfer_matrix()?.dc_gain();
    let dc = p.transfer_matrix()?.dc_gain();
    for i in 0..2 {
        for j in 0..2 {
            p.gains[2 * i + j] *= dc_nominal[(i, j)] / dc[(i, j)];
        }
    }
    Ok(p)
}

/// A nominal run and `trials` uncertain ones.
#[derive(Debug, Clone)]
pub struct Study {
    pub nominal: MarthsResult,
    pub trials: Vec<(PlantParameters, MarthsResult)>,
}

impl Study {
    /// What the toolset reports: the nominal values with no trials, else the mean over the
    /// trials (nominal excluded); `None` if a run it needs diverged.
    pub fn reported(&self) -> Option<Criteria> {
        if self.trials.is_empty() {
            return self.nominal.criteria;
        }
        let all: Option<Vec<Criteria>> = self.trials.iter().map(|(_, r)| r.criteria).collect();
        Criteria::mean(&all?)
    }
    /// Runs (nominal and trials) that diverged.
    pub fn diverged_runs(&self) -> usize {
        usize::from(self.nominal.diverged) + self.trials.iter().filter(|(_, r)| r.diverged).count()
    }
    /// The first run that diverged (nominal first).
    pub fn first_diverged(&self) -> Option<&MarthsResult> {
        std::iter::once(&self.nominal)
            .chain(self.trials.iter().map(|(_, r)| r))
            .find(|r| r.diverged)
    }
    /// The error a front end ends with when a run diverged (exit 1 in the CLI, `RunError` in
    /// Python): how many, and the first one's time and reason.
    pub fn divergence(&self) -> Option<Error> {
        let first = self.first_diverged()?;
        let at = first.stopped_at.unwrap_or(0);
        Some(Error::Diverged {
            step: at,
            time: at as f64 * super::run::SAMPLE_TIME,
            reason: format!(
                "benchmark marths: {} run(s) diverged, no score; the first: {}",
                self.diverged_runs(),
                first.stop_reason.clone().unwrap_or_default()
            ),
        })
    }
    /// Every run stable.
    pub fn stable(&self) -> bool {
        !self.nominal.diverged && self.trials.iter().all(|(_, r)| !r.diverged)
    }
    /// The toolset's realisability over the runs it reports (both actuators over 3.8 V in a run
    /// makes the test not realisable; the toolset looks at its last trial only).
    pub fn realizable(&self) -> bool {
        if self.trials.is_empty() {
            self.nominal.realizable
        } else {
            self.trials.iter().all(|(_, r)| r.realizable)
        }
    }
}

/// The nominal run of `input` (its transfer system as given) and `trials` uncertain plants
/// (noise seeded per trial from `seed` when the nominal run has noise), in parallel.
pub fn run_study(input: &MarthsInput, trials: usize, seed: u64) -> Result<Study> {
    let reference = reference(input)?;
    run_with(input, &reference, trials, seed)
}

/// [`run_study`] against a reference computed once.
pub fn run_with(input: &MarthsInput, reference: &Reference, trials: usize, seed: u64) -> Result<Study> {
    if trials > MAX_TRIALS {
        return Err(Error::invalid("trials", format!("at most {MAX_TRIALS}, got {trials}")));
    }
    let noisy = matches!(
        input.transfer,
        Transfer::Plant {
            noise_seed: Some(_),
            ..
        }
    );
    let inputs: Vec<(PlantParameters, MarthsInput)> = (0..trials as u64)
        .map(|i| -> Result<(PlantParameters, MarthsInput)> {
            let mut one = input.clone();
            let params = uncertain_plant(seed, i)?;
            one.transfer = Transfer::Plant {
                plant: params.transfer_matrix()?.to_state_space(),
                noise_seed: noisy.then(|| seed.wrapping_add(1 + i).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
            };
            Ok((params, one))
        })
        .collect::<Result<_>>()?;
    let (nominal, trials) = rayon::join(
        || run(input, reference),
        || {
            inputs
                .par_iter()
                .map(|(params, one)| run(one, reference).map(|r| (*params, r)))
                .collect::<Result<Vec<_>>>()
        },
    );
    Ok(Study {
        nominal: nominal?,
        trials: trials?,
    })
}

/// One row of [`compare`]: a controller on a record, nominal and over uncertain plants.
#[derive(Debug, Clone)]
pub struct CompareRow {
    pub record: &'static str,
    pub controller: &'static str,
    /// The nominal plant's criteria (`None`: diverged).
    pub nominal: Option<Criteria>,
    /// The mean over the trials (`None`: a trial diverged or there were none).
    pub mean: Option<Criteria>,
    /// Worst (largest) J2 and J7 per component over the trials.
    pub worst_j2: [f64; 2],
    pub worst_j7: [f64; 2],
    pub stable_trials: usize,
    pub trials: usize,
    /// Runs (nominal and trials) in which a compensator backed off.
    pub backed_off: usize,
    pub realizable: bool,
}

/// Every controller on every shipped record: the nominal plant and `trials` uncertain ones
/// (seeded by `seed`, sensor noise when `noise`), in parallel.
pub fn compare(
    records: &[super::data::Record],
    controllers: &[super::run::ControllerKind],
    trials: usize,
    seed: u64,
    noise: bool,
) -> Result<Vec<CompareRow>> {
    let mut rows = Vec::new();
    for &record in records {
        let mut input = MarthsInput::new(std::sync::Arc::new(record.load()));
        if let Transfer::Plant { noise_seed, .. } = &mut input.transfer {
            *noise_seed = noise.then_some(seed);
        }
        let reference = reference(&input)?;
        for controller in controllers {
            input.controller = controller.clone();
            let study = run_with(&input, &reference, trials, seed)?;
            let worst = |f: &dyn Fn(&Criteria) -> [f64; 2]| -> [f64; 2] {
                let mut w = [0.0f64; 2];
                for (_, r) in &study.trials {
                    let v = r.criteria.as_ref().map_or([f64::INFINITY; 2], f);
                    w = [w[0].max(v[0]), w[1].max(v[1])];
                }
                w
            };
            rows.push(CompareRow {
                record: record.name(),
                controller: controller.name(),
                nominal: study.nominal.criteria,
                mean: if study.trials.is_empty() {
                    None
                } else {
                    study.reported()
                },
                worst_j2: worst(&|c| c.j2),
                worst_j7: worst(&|c| c.j7),
                stable_trials: study.trials.iter().filter(|(_, r)| !r.diverged).count(),
                trials: study.trials.len(),
                backed_off: usize::from(study.nominal.backed_off)
                    + study.trials.iter().filter(|(_, r)| r.backed_off).count(),
                realizable: study.realizable(),
            });
        }
    }
    Ok(rows)
}

/// The rows of [`compare`] as a Markdown table (J2, J7 nominal and mean over the trials).
pub fn compare_markdown(rows: &[CompareRow]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "| record | controller | J2 act. 1 / 2 [%] nominal | mean | worst | J7 x / θ [%] nominal | mean | worst | stable | backed off | realizable |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let pair = |v: Option<[f64; 2]>| v.map_or("diverged".to_string(), |v| format!("{:.2} / {:.2}", v[0], v[1]));
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {}/{} | {} | {} |",
            r.record,
            r.controller,
            pair(r.nominal.map(|c| c.j2)),
            pair(r.mean.map(|c| c.j2)),
            pair((r.trials > 0).then_some(r.worst_j2)),
            pair(r.nominal.map(|c| c.j7)),
            pair(r.mean.map(|c| c.j7)),
            pair((r.trials > 0).then_some(r.worst_j7)),
            r.stable_trials,
            r.trials,
            r.backed_off,
            if r.realizable { "yes" } else { "no" }
        );
    }
    s
}
