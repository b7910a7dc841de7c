//! Integration tests: the CLI on tiny specs in temporary folders, and the papers' claims at
//! small scale. One test binary (polars makes each binary large).

mod cli;
mod diff;
mod digits;
mod folders;
mod inputs;
mod ms;
mod na;
mod shard;
mod spec_errors;
mod util;
mod verbs;
