//! File and resource utilities shared by every stage: limits on untrusted inputs and resources
//! ([`limits`]).

pub mod limits;
