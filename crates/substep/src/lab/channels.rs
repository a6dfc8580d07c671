//! Which target signal is which: the command channels (one per coupling DOF, engineering
//! units → target units) and the measured channels (target units → displacement \[m\] or force
//! \[N\] of a coupling DOF), each with a linear calibration `target = gain · engineering + offset`
//! (commands) or `engineering = gain · target + offset` (measurements), and the command's
//! saturation in engineering units. Allocation-free per sub-step.

use crate::error::{Error, Result};

/// What a measured channel measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// The coupling DOF's displacement \[m\] (the actuator's LVDT / the specimen's transducer).
    Displacement,
    /// The force at the coupling DOF \[N\], as the load cell reads it: the specimen's resisting
    /// force, positive along the DOF (the numerical substructure gets its negative).
    Force,
}

/// One command channel: the command of coupling DOF `dof` (0-based), saturated to
/// `[min, max]` \[m\], sent as `gain · x + offset` (target units, e.g. V).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandChannel {
    pub dof: usize,
    pub gain: f64,
    pub offset: f64,
    pub min: f64,
    pub max: f64,
}

/// One measured channel: word `signal` (0-based) of the measured signals, `gain · v + offset`
/// in m or N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredChannel {
    pub signal: usize,
    pub quantity: Quantity,
    pub dof: usize,
    pub gain: f64,
    pub offset: f64,
}

/// The wiring of a lab target: command channels in the order the target reads them, measured
/// channels, and how many measured signals the target sends.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelMap {
    pub commands: Vec<CommandChannel>,
    pub measured: Vec<MeasuredChannel>,
    pub n_signals: usize,
}

impl ChannelMap {
    /// The default for `n_c` coupling DOFs: command `i` = DOF `i`; measured signals `0 … n_c − 1`
    /// = the displacements, `n_c … 2 n_c − 1` = the forces; unit gains, no offsets, no saturation.
    pub fn default_for(n_c: usize) -> Self {
        let unit = |dof| CommandChannel {
            dof,
            gain: 1.0,
            offset: 0.0,
            min: f64::NEG_INFINITY,
            max: f64::INFINITY,
        };
        let meas = |signal, quantity, dof| MeasuredChannel {
            signal,
            quantity,
            dof,
            gain: 1.0,
            offset: 0.0,
        };
        Self {
            commands: (0..n_c).map(unit).collect(),
            measured: (0..n_c)
                .map(|d| meas(d, Quantity::Displacement, d))
                .chain((0..n_c).map(|d| meas(n_c + d, Quantity::Force, d)))
                .collect(),
            n_signals: 2 * n_c,
        }
    }

    /// Every coupling DOF has exactly one command channel, one displacement and one force
    /// channel; gains are finite and not 0; offsets finite; `min < max`; signals in range and
    /// used once. Errors name `what.command[k]` / `what.measured[k]` (1-based).
    pub fn validate(&self, n_c: usize, what: &str) -> Result<()> {
        if self.n_signals == 0 || self.n_signals > 4096 {
            return Err(Error::invalid(
                format!("{what}.signals"),
                format!("must be 1 to 4096 measured signals, got {}", self.n_signals),
            ));
        }
        let mut seen_cmd = vec![false; n_c];
        for (k, c) in self.commands.iter().enumerate() {
            let key = format!("{what}.command[{}]", k + 1);
            if c.dof >= n_c {
                return Err(Error::invalid(
                    format!("{key}.dof"),
                    format!("coupling DOF {} is out of range (the test has {n_c})", c.dof + 1),
                ));
            }
            if std::mem::replace(&mut seen_cmd[c.dof], true) {
                return Err(Error::invalid(
                    format!("{key}.dof"),
                    format!("coupling DOF {} has a command channel already", c.dof + 1),
                ));
            }
            check_gain(&key, c.gain, c.offset)?;
            if c.min.is_nan() || c.max.is_nan() || c.min >= c.max {
                return Err(Error::invalid(
                    format!("{key}.saturation"),
                    format!("needs min < max, got [{}, {}]", c.min, c.max),
                ));
            }
        }
        if let Some(d) = seen_cmd.iter().position(|s| !s) {
            return Err(Error::invalid(
                format!("{what}.command"),
                format!("coupling DOF {} has no command channel", d + 1),
            ));
        }
        let mut used = vec![false; self.n_signals];
        let mut seen = vec![[false; 2]; n_c];
        for (k, m) in self.measured.iter().enumerate() {
            let key = format!("{what}.measured[{}]", k + 1);
            if m.signal >= self.n_signals {
                return Err(Error::invalid(
                    format!("{key}.signal"),
                    format!(
                        "signal {} is out of range (the target sends {} measured signals)",
                        m.signal + 1,
                        self.n_signals
                    ),
                ));
            }
            if std::mem::replace(&mut used[m.signal], true) {
                return Err(Error::invalid(
                    format!("{key}.signal"),
                    format!("signal {} is mapped twice", m.signal + 1),
                ));
            }
            if m.dof >= n_c {
                return Err(Error::invalid(
                    format!("{key}.dof"),
                    format!("coupling DOF {} is out of range (the test has {n_c})", m.dof + 1),
                ));
            }
            let q = m.quantity as usize;
            if std::mem::replace(&mut seen[m.dof][q], true) {
                return Err(Error::invalid(
                    format!("{key}.dof"),
                    format!(
                        "coupling DOF {} has a {} channel already",
                        m.dof + 1,
                        quantity_name(m.quantity)
                    ),
                ));
            }
            check_gain(&key, m.gain, m.offset)?;
        }
        for (d, s) in seen.iter().enumerate() {
            for (q, name) in [(0, "displacement"), (1, "force")] {
                if !s[q] {
                    return Err(Error::invalid(
                        format!("{what}.measured"),
                        format!("coupling DOF {} has no {name} channel", d + 1),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Host side: the commands \[m\] per coupling DOF → the command signals (target units).
    pub fn encode_commands(&self, command: &[f64], out: &mut [f64]) {
        for (o, c) in out.iter_mut().zip(&self.commands) {
            *o = c.gain * command[c.dof].clamp(c.min, c.max) + c.offset;
        }
    }

    /// Host side: the measured signals → displacement \[m\] and force on the numerical
    /// substructure \[N\] (the negative of the load cell's) per coupling DOF.
    pub fn decode_measured(&self, signals: &[f64], displacement: &mut [f64], force: &mut [f64]) {
        for m in &self.measured {
            let v = m.gain * signals[m.signal] + m.offset;
            match m.quantity {
                Quantity::Displacement => displacement[m.dof] = v,
                Quantity::Force => force[m.dof] = -v,
            }
        }
    }

    /// Target side (the emulator): command signals → commands \[m\].
    pub fn decode_commands(&self, signals: &[f64], command: &mut [f64]) {
        for (c, v) in self.commands.iter().zip(signals) {
            command[c.dof] = (v - c.offset) / c.gain;
        }
    }

    /// Target side: displacement and force on the numerical substructure → measured signals.
    pub fn encode_measured(&self, displacement: &[f64], force: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for m in &self.measured {
            let x = match m.quantity {
                Quantity::Displacement => displacement[m.dof],
                Quantity::Force => -force[m.dof],
            };
            out[m.signal] = (x - m.offset) / m.gain;
        }
    }
}

pub fn quantity_name(q: Quantity) -> &'static str {
    match q {
        Quantity::Displacement => "displacement",
        Quantity::Force => "force",
    }
}

fn check_gain(key: &str, gain: f64, offset: f64) -> Result<()> {
    if !(gain.is_finite() && gain != 0.0) {
        return Err(Error::invalid(
            format!("{key}.gain"),
            format!("must be a finite number other than 0, got {gain}"),
        ));
    }
    if !offset.is_finite() {
        return Err(Error::invalid(
            format!("{key}.offset"),
            format!("must be finite, got {offset}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_round_trips_and_saturates() {
        let mut map = ChannelMap::default_for(2);
        map.commands[1] = CommandChannel {
            dof: 1,
            gain: 100.0,
            offset: 0.5,
            min: -0.05,
            max: 0.05,
        };
        map.measured[3].gain = 1e4;
        map.validate(2, "lab").unwrap();
        let mut s = [0.0; 2];
        map.encode_commands(&[0.01, 0.2], &mut s);
        assert_eq!(s, [0.01, 100.0 * 0.05 + 0.5]);
        let mut back = [0.0; 2];
        map.decode_commands(&s, &mut back);
        assert_eq!(back, [0.01, 0.05]);
        let mut m = [0.0; 4];
        map.encode_measured(&[0.1, 0.2], &[-30.0, -40.0], &mut m);
        assert_eq!(m, [0.1, 0.2, 30.0, 40.0 / 1e4]);
        let (mut d, mut f) = ([0.0; 2], [0.0; 2]);
        map.decode_measured(&m, &mut d, &mut f);
        assert_eq!((d, f), ([0.1, 0.2], [-30.0, -40.0]));
        map.measured[2].gain = 0.0;
        assert!(
            map.validate(2, "lab")
                .unwrap_err()
                .to_string()
                .starts_with("lab.measured[3].gain:")
        );
        let mut map = ChannelMap::default_for(1);
        map.measured[0].signal = 5;
        assert!(
            map.validate(1, "lab")
                .unwrap_err()
                .to_string()
                .contains("signal 6 is out of range")
        );
    }
}
