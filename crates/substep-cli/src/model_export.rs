//! `substep model export CONFIG --mtx DIR`: the numerical substructure of a test definition as
//! MatrixMarket files, so that another tool can be run on exactly our matrices: `M.mtx`,
//! `C.mtx`, `K.mtx` (symmetric coordinate), `influence.mtx` (`n × 1` array) and `coupling.txt`
//! (the coupling DOFs, 1-based, one per line; empty for a monolithic test).

use substep::output::files::replace_atomic;
use anyhow::{Context, Result};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use substep::io::{TestDefinition, write_matrix_market_symmetric, write_matrix_market_vector};
use substep::model::{Model, SparseModel};

#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    #[command(subcommand)]
    pub command: ModelCommand,
}

#[derive(Debug, Clone, clap::Subcommand)]
pub enum ModelCommand {
    /// Write M, C, K, the influence vector and the coupling DOFs of CONFIG as MatrixMarket files
    Export {
        /// Test definition (TOML)
        config: PathBuf,
        /// Output directory (created if missing)
        #[arg(long, value_name = "DIR")]
        mtx: PathBuf,
    },
}

pub fn model(args: &ModelArgs) -> Result<()> {
    match &args.command {
        ModelCommand::Export { config, mtx } => {
            let def = TestDefinition::from_file(config)?;
            let coupling = def.substructure.as_ref().map_or(&[][..], |s| &s.coupling_dofs[..]);
            let sparse = match &def.model {
                Model::Sparse(m) => m.clone(),
                Model::Dense(m) => SparseModel::from_dense(m),
            };
            let what = format!("exported by substep from {}", config.display());
            export(&sparse, coupling, mtx, &what)?;
            println!(
                "wrote M.mtx, C.mtx, K.mtx, influence.mtx, coupling.txt ({} DOFs, {} coupling) to {}",
                sparse.n_dofs(),
                coupling.len(),
                mtx.display()
            );
            Ok(())
        }
    }
}

/// Write `model` and its coupling DOFs (0-based) into `dir` (each file atomically).
pub fn export(model: &SparseModel, coupling: &[usize], dir: &Path, what: &str) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| substep::Error::file(dir.display().to_string(), format!("cannot create the directory: {e}")))?;
    let write = |name: &str, f: &dyn Fn(&mut BufWriter<std::fs::File>) -> std::io::Result<()>| -> Result<()> {
        let path = dir.join(name);
        replace_atomic(&path, |tmp| {
            let mut w = BufWriter::new(std::fs::File::create(tmp)?);
            f(&mut w)?;
            w.flush()
        })
        .with_context(|| format!("cannot write {}", path.display()))
    };
    for (name, m, label) in [
        ("M.mtx", &model.mass, "mass M [kg]"),
        ("C.mtx", &model.damping, "damping C [N s/m]"),
        ("K.mtx", &model.stiffness, "stiffness K [N/m]"),
    ] {
        write(name, &|w| {
            write_matrix_market_symmetric(w, m, &format!("{label}, {what}"))
        })?;
    }
    write("influence.mtx", &|w| {
        write_matrix_market_vector(w, model.influence.as_slice(), &format!("influence vector, {what}"))
    })?;
    write("coupling.txt", &|w| {
        coupling.iter().try_for_each(|d| writeln!(w, "{}", d + 1))
    })?;
    Ok(())
}
