//! `substep model export CONFIG --mtx DIR`: the numerical substructure of a test definition as
//! MatrixMarket files, so that another tool can be run on exactly our matrices: `M.mtx`,
//! `C.mtx`, `K.mtx` (symmetric coordinate), `influence.mtx` (`n × 1` array) and `coupling.txt`
//! (the coupling DOFs, 1-based, one per line; empty for a monolithic test).

use anyhow::Result;
use std::path::PathBuf;
use substep::io::TestDefinition;
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
            substep::io::export_model(&sparse, coupling, mtx, &what)?;
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
