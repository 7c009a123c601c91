//! One module per subcommand: its arguments and its `run`, which returns the process's exit code
//! (`main` only routes and prints an error).

pub mod bag;
pub mod device_check;
pub mod experiment;
pub mod msg;
pub mod nn;
pub mod policy;
pub mod record;
pub mod rotest;
pub mod security;
pub mod sim;
pub mod topic;
pub mod train;

use std::process::ExitCode;

use anyhow::Context as _;

/// The multi-threaded tokio runtime every node runs on.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread().enable_all().build().context("starting the tokio runtime")
}

/// The exit code of a tool that reports one (0 success; the grids' codes are documented with them).
pub fn exit_code(code: i32) -> ExitCode {
    match u8::try_from(code) {
        Ok(c) => ExitCode::from(c),
        Err(_) => ExitCode::FAILURE,
    }
}
