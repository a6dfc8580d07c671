//! `substep lab emulate TARGET.toml`: a lab target speaking the protocol of a test's
//! `[substructure.lab]`, with the test's virtual lab (actuator, specimens, sensors) behind it and
//! the faults of the target file injected — to rehearse a test against exactly the packets the
//! real target will see (docs/lab.md).

use anyhow::Result;
use clap::{Args, Subcommand};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use substep::lab::Emulator;

#[derive(Debug, Args)]
pub struct LabArgs {
    #[command(subcommand)]
    pub command: LabCommand,
}

#[derive(Debug, Subcommand)]
pub enum LabCommand {
    /// Serve one test session as the lab target of TARGET.toml (docs/lab.md, "Rehearsing without hardware")
    Emulate(EmulateArgs),
}

#[derive(Debug, Args)]
pub struct EmulateArgs {
    /// Target file: `test = "TEST.toml"` (with its [substructure.lab]), optional `bind`, `idle`, [faults]
    pub target: PathBuf,
    /// Override the address to serve (e.g. 127.0.0.1:0 for a free port; the first line shows it)
    #[arg(long, value_name = "ADDR")]
    pub bind: Option<String>,
}

pub fn lab(args: &LabArgs) -> Result<()> {
    let LabCommand::Emulate(a) = &args.command;
    let (mut spec, virtual_lab) = substep::io::config::emulator_from_file(&a.target)?;
    if let Some(b) = &a.bind {
        spec.bind = b
            .parse()
            .map_err(|e| substep::Error::invalid("--bind", format!("'{b}' is not an address ip:port ({e})")))?;
    }
    let (protocol, transport, faults) = (spec.protocol, spec.transport, spec.faults);
    let emulator = Emulator::bind(spec, virtual_lab)?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "lab emulator: {} over {} on {} (faults: loss {}, duplicate {}, reorder {}, stall {:?}, die_at {:?})",
            protocol.name(),
            transport.name(),
            emulator.local_addr(),
            faults.loss,
            faults.duplicate,
            faults.reorder,
            faults.stall,
            faults.die_at
        )?;
        out.flush()?;
    }
    let stop = AtomicBool::new(false);
    let r = emulator.serve(&stop)?;
    println!(
        "session ended: {}; {} sub-steps, {} frames in, {} replies, {} dropped, {} duplicated, {} reordered, {} stall(s)",
        r.ended, r.substeps, r.frames_in, r.replies, r.dropped, r.duplicated, r.reordered, r.stalls
    );
    Ok(())
}
