//! Community benchmarks reproduced as built-ins: [`rths`], the virtual real-time hybrid
//! simulation benchmark control problem of Silva et al. (2020).

pub mod marths;
pub mod rths;
