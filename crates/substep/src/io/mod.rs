//! Input and output around the numerical core: MatrixMarket matrices, TOML test definitions
//! (documented in `docs/config.md`), result containers and site definitions. The stepping of a
//! defined test is [`crate::run`].
//!
//! Conventions: SI units; DOF numbers are 1-based in files and messages, 0-based in the
//! library types; every error is one line naming the file and line or the config key.

pub mod config;
pub use crate::limits;
pub mod matrix_market;
pub mod results;
pub mod site_config;

pub use config::{
    GroundMotion, IntegratorDefinition, MonitorSettings, OutputSettings, SubstructureDefinition, TestDefinition,
    check_token,
};
pub use limits::Limits;
pub use matrix_market::{
    export_model, parse_matrix_market, parse_matrix_market_sparse, read_matrix_market, read_matrix_market_sparse,
    read_matrix_market_sparse_with, read_matrix_market_with, write_matrix_market_symmetric, write_matrix_market_vector,
};
